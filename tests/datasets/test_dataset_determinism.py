"""The same collection command gives the same dataset, bit for bit, in any workspace and worker layout.

Each case collects one small dataset twice through the real CLI, in two workspaces at different paths, with
different ``--workers`` and ``--num-envs`` (one worker runs in this process with its torch threads, two run
in worker processes with one thread each), and compares every episode's content hash and the version hash.
"""

from __future__ import annotations

import pytest

from nsl.datasets import api
from tests.conftest import run_cli

CASES = {
    # scripted: the oracle reads the simulator's true state
    "oracle": ("base", "oracle:0.5", "0.0", "8"),
    # learned: the shipped base checkpoint's CEM policy with exploration, as the study collects its target data
    "checkpoint": ("harsh_lighting", "ckpt:base", "0.1", "6"),
}


@pytest.mark.parametrize("case", CASES)
def test_a_collection_is_the_same_in_any_workspace_worker_count_and_batch_size(case, tmp_path, monkeypatch):
    shift, policy, epsilon, episodes = CASES[case]
    got = {}
    for home, workers, batch in (("first", "1", "1"), ("second/elsewhere", "2", "4")):
        monkeypatch.setenv("NSL_HOME", str(tmp_path / home))
        assert (
            run_cli(
                "collect",
                "--shift",
                shift,
                "--policy",
                policy,
                "--epsilon",
                epsilon,
                "--episodes",
                episodes,
                "--seed",
                "5",
                "--data",
                "same",
                "--workers",
                workers,
                "--num-envs",
                batch,
                "--episodes-per-file",
                "4",
            )
            == 0
        )
        v = api.open_version("same")
        got[home] = (v.episodes.content_hash, v.view().content_hash, v.hash)
    first, second = got.values()
    assert len(first[0]) == int(episodes)
    for i, (a, b) in enumerate(zip(first[0], second[0])):
        assert a == b, f"episode {i} differs"
    assert first[1] == second[1]  # content hash
    assert first[2] == second[2]  # version hash: metadata included, so nothing in it depends on the workspace


def test_a_dataset_whose_spec_records_a_checkpoint_path_can_still_be_appended_to(make_synth):
    """Older nsl versions recorded the checkpoint's folder in the policy description; its content id decides."""
    from nsl.datasets.collection import Collection
    from nsl.errors import ConfigError

    policy = {
        "policy": "cem",
        "name": "ckpt:00006000-6338b2320779",
        "checkpoint_id": "6338b2" + "0" * 58,
        "step": 6000,
        "epsilon": 0.1,
    }
    spec = {"env": {"shift": "harsh_lighting"}, "policy": policy, "policy_ref": "ckpt:base", "seed": 5}
    make_synth("older", [3, 4], spec={**spec, "policy": {**policy, "checkpoint": "/elsewhere/checkpoints/base"}})
    assert Collection.begin("older", 4, spec, 16).start == 2  # same content-defining settings: appends
    other = {**spec, "policy": {**policy, "checkpoint_id": "f" * 64}}
    with pytest.raises(ConfigError, match="collected with other settings"):
        Collection.begin("older", 4, other, 16, restart=True)
