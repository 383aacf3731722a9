"""The learner interface: IQL through the same loop as QT-Opt, a plugin learner, and QT-Opt's numbers unchanged."""

from __future__ import annotations

import functools
import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from learner_factories import TINY_NET, colour_task, tiny_train

import nsl
from nsl import keys
from nsl.checkpoint_format import canonical_config
from nsl.errors import ConfigError, UnknownReferenceError
from nsl.learners import (
    Algorithm,
    ArraySampler,
    QTOpt,
    TrainConfig,
    find_learner,
    learner_names,
    load_checkpoint,
    load_policy,
    parse_learner,
    read_config,
    register_learner,
    synthetic_sampler,
    train,
)
from nsl.learners.augment import to_float
from nsl.learners.cem import active_actions
from nsl.learners.iql import expectile_loss

ASSET = Path(nsl.__file__).parent / "assets" / "base"
# Numbers recorded with the code before the learner interface existed (QT-Opt's update called directly by the loop).
# They are sums and norms compared to a relative 1e-5, not digests: oneDNN picks its float32 kernels by the CPU
# (AVX2, AVX-512, AMX), and they round the last bits differently, so a digest of the weights holds on one CPU
# family only.  These numbers agree to about 1e-8 between the AVX2 and the AMX kernels (ONEDNN_MAX_CPU_ISA=AVX2
# ATEN_CPU_CAPABILITY=avx2 against the default on an Intel Xeon), while any change to the learner's arithmetic
# (the loss, its terms, the target, the optimiser) moves them by far more.
BASE_EVAL_ACTIONS = [30.71846, 26.52850, 28.94779, 24.41150, 24.55628, 23.69957]  # sum |action| of each episode
FINE_TUNE_METRICS = {  # step -> (q_loss, conservative, q/mean, q/target_mean) of the seeded fine-tune's log
    3: (0.733902, 0.38822, 0.310758, 0.395689),
    6: (0.681216, 0.474934, 0.36435, 0.380436),
}
FINE_TUNE_DISTANCE = 0.15859392  # L2 norm of the fine-tuned weights minus the base's


def test_qtopt_numbers_do_not_move():
    """The shipped base's evaluation and a seeded fine-tune of it, against numbers recorded with the code before
    the learner interface existed.  One thread, as recorded."""
    import csv
    import tempfile

    from nsl.collectors import parse_shift
    from nsl.eval import EvalConfig
    from nsl.eval.success import run_eval_episodes

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        episodes = run_eval_episodes(
            functools.partial(load_policy, ASSET),
            parse_shift("base"),
            EvalConfig(episodes=6, seed=3000, workers=1, batch=2),
            progress=False,
        )
        assert [int(e.success) for e in episodes] == [1, 1, 0, 1, 1, 1]
        assert [e.actions.shape for e in episodes] == [(8, 6)] * 6
        assert [float(np.abs(e.actions).sum()) for e in episodes] == pytest.approx(BASE_EVAL_ACTIONS, rel=1e-5)

        cfg = TrainConfig(steps=6, seed=5, log_every=3, checkpoint_every=3)
        with tempfile.TemporaryDirectory() as d:
            run = train(cfg, synthetic_sampler(128, seed=1), d, init_checkpoint=ASSET, progress=False)
            config = read_config(run.checkpoint)
            config.pop("code_version")
            tuned = load_checkpoint(run.checkpoint).net.state_dict()
            with open(Path(d) / "metrics.csv") as f:
                rows = {int(r["step"]): r for r in csv.DictReader(f)}
        base = load_checkpoint(ASSET).net.state_dict()
        distance = sum(float(((tuned[k].double() - base[k].double()) ** 2).sum()) for k in base) ** 0.5
        assert distance == pytest.approx(FINE_TUNE_DISTANCE, rel=1e-5)
        for step, expected in FINE_TUNE_METRICS.items():
            names = ("losses/q_loss", "losses/conservative", "q/mean", "q/target_mean")
            assert [float(rows[step][n]) for n in names] == pytest.approx(expected, rel=1e-5), step
        assert "learner" not in config["training"]  # QT-Opt's configs (and so checkpoint ids) are as before
        assert (
            hashlib.sha256(canonical_config(config)).hexdigest()
            == "32ce16316a819d9a39da29a5e8c8afcb70586317ffdf473a4e634867d6330c53"
        )
    finally:
        torch.set_num_threads(threads)


def test_the_expectile_loss_is_minimised_at_the_expectile():
    """Over the values {0, 1}, the tau-expectile v solves tau (1 - v) = (1 - tau) v: v = tau."""
    u_values = torch.tensor([0.0, 1.0])
    for tau in (0.5, 0.8, 0.9):
        v = torch.zeros((), requires_grad=True)
        opt = torch.optim.SGD([v], lr=0.5)
        for _ in range(400):
            opt.zero_grad()
            expectile_loss(u_values - v, tau).backward()
            opt.step()
        assert float(v.detach()) == pytest.approx(tau, abs=1e-3)


def test_iql_finds_the_colour_tasks_answer(tmp_path):
    """One-step episodes: IQL's Q is fitted to the rewards, and CEM over it finds the only successful region."""
    cfg = tiny_train(steps=400, batch_size=32, lr=3e-3, checkpoint_every=400, log_every=100, augment_crop=0)
    cfg = cfg.replace(augment_colour=0.0, learner="iql", learner_options={"v_warmup": 0})
    result = train(
        cfg, ArraySampler.from_transitions(colour_task(2000)), tmp_path / "run", net=TINY_NET, progress=False
    )
    assert read_config(result.checkpoint)["training"]["learner"] == "iql"
    assert read_config(result.checkpoint)["training"]["learner_options"] == {"expectile": 0.8, "v_warmup": 0}
    policy = load_policy(result.checkpoint, samples=64, elites=6, iterations=3)
    test = colour_task(40, seed=1)
    actions = policy(
        {"image": test[keys.OBS_IMAGE], "state": test[keys.OBS_STATE]},
        rngs=[np.random.default_rng(i) for i in range(40)],
    )
    red = test[keys.OBS_IMAGE][:, 0, 0, 0] > 150
    hit = np.where(red, actions[:, 0] > 0.5, actions[:, 0] < -0.5)
    assert hit.mean() >= 0.9, f"only {hit.mean():.0%} of greedy actions are in the successful region"


def _two_step_task(n: int, seed: int = 0) -> dict[str, np.ndarray]:
    """Step 1 (grey image) leads, whatever the action, to step 2 (red image), where dx > 0.5 succeeds; the data's
    actions are uniform, so a quarter of the step-2 attempts succeed."""
    base = colour_task(n, seed=seed)
    red = base[keys.OBS_IMAGE].copy()
    red[..., 0], red[..., 2] = 230, 10
    grey = np.full_like(red, 120)
    half = n // 2
    rng = np.random.default_rng(seed + 1)
    actions = rng.uniform(-1, 1, (n, 6)).astype(np.float32)
    first = np.arange(n) < half
    return {
        keys.OBS_IMAGE: np.where(first[:, None, None, None], grey, red),
        keys.OBS_STATE: base[keys.OBS_STATE],
        keys.ACTION: actions,
        keys.REWARD: np.where(first, 0.0, actions[:, 0] > 0.5).astype(np.float32),
        keys.DONE: (~first).astype(np.float32),
        keys.NEXT_OBS_IMAGE: red,
        keys.NEXT_OBS_STATE: base[keys.OBS_STATE],
    }


def test_iqls_value_backs_up_the_upper_expectile_of_the_datas_actions(tmp_path):
    """At step 1 Q is gamma V(step 2).  V is the expectile of Q over the data's step-2 actions: at 0.5 their mean
    (about 0.25), at 0.95 near their best (1), so the first step's value rises with the expectile."""
    data = ArraySampler.from_transitions(_two_step_task(2000))
    values = {}
    for tau in (0.5, 0.95):
        cfg = tiny_train(steps=600, batch_size=32, lr=3e-3, checkpoint_every=600, log_every=100, augment_crop=0)
        cfg = cfg.replace(augment_colour=0.0, learner="iql", learner_options={"expectile": tau, "v_warmup": 0})
        net = load_checkpoint(train(cfg, data, tmp_path / f"tau{tau}", net=TINY_NET, progress=False).checkpoint).net
        grey = torch.full((64, 16, 16, 3), 120, dtype=torch.uint8)
        with torch.no_grad():
            q = torch.sigmoid(net(to_float(grey), torch.rand(64, 6), torch.rand(64, 4) * 2 - 1))
        values[tau] = float(q.mean())
    assert values[0.5] == pytest.approx(0.9 * 0.25, abs=0.1)
    assert values[0.95] > values[0.5] + 0.3, values


@dataclass(frozen=True)
class _BanditOptions:
    scale: float = 1.0


class _Bandit(Algorithm):
    """A plugin learner: Q fitted to the immediate reward (no bootstrapping); supports scratch and ft only."""

    name = "tests.bandit"
    methods = ("scratch", "ft")
    Options = _BanditOptions

    def create(self, net, lr, cfg, options):
        return QTOpt().create(net, lr, cfg, options)  # its networks and optimiser will do

    def update(self, state, batch, cfg, step, options):
        action = active_actions(batch[keys.ACTION], state.online.cfg)
        logits = state.online(to_float(batch[keys.OBS_IMAGE]), batch[keys.OBS_STATE], action)
        loss = F.binary_cross_entropy_with_logits(logits.float(), batch[keys.REWARD] * options.scale)
        state.optimizer.zero_grad()
        loss.backward()
        state.optimizer.step()
        return {"losses/q_loss": loss.item(), "q/mean": torch.sigmoid(logits).mean().item(), "q/target_mean": 0.0}


def test_a_registered_learner_trains_records_its_package_and_is_refused_where_unsupported(
    random_sampler, parent_checkpoint, tmp_path, monkeypatch
):
    monkeypatch.setattr("nsl.learners.registry._REGISTERED", {})  # forget it afterwards
    register_learner(_Bandit(), {"package": "nsl-tests-bandit", "version": "1.2.0"})
    assert "tests.bandit" in learner_names() and learner_names()[:2] == ["qtopt", "iql"]
    cfg = tiny_train(steps=4, learner="tests.bandit", learner_options={"scale": 0.5})
    with pytest.raises(ConfigError, match=r"learner 'tests.bandit' does not support method 'new_head'; use one of"):
        train(
            cfg, random_sampler, tmp_path / "nh", init_checkpoint=parent_checkpoint, method="new_head", progress=False
        )
    run = train(cfg, random_sampler, tmp_path / "ft", init_checkpoint=parent_checkpoint, progress=False)
    config = read_config(run.checkpoint)
    assert config["learner"] == {"name": "tests.bandit", "plugin": {"package": "nsl-tests-bandit", "version": "1.2.0"}}
    assert config["training"]["learner_options"] == {"scale": 0.5}
    # Reading it where that package is not installed fails in one line naming it.
    with pytest.raises(UnknownReferenceError, match=r"plugin package nsl-tests-bandit 1.2.0, which is not installed"):
        load_checkpoint(run.checkpoint)


def test_bad_learner_settings_fail_in_one_line(random_sampler, parent_checkpoint, tmp_path):
    with pytest.raises(UnknownReferenceError, match=r"unknown learner 'sac'"):
        find_learner("sac")
    with pytest.raises(ConfigError, match=r"learner 'iql' has no option\(s\) \['tau'\]; its options are"):
        train(tiny_train(learner="iql", learner_options={"tau": 0.9}), random_sampler, tmp_path / "a", net=TINY_NET)
    with pytest.raises(ConfigError, match=r"iql expectile 1.5 must be in \[0.5, 1\)"):
        train(
            tiny_train(learner="iql", learner_options={"expectile": 1.5}), random_sampler, tmp_path / "b", net=TINY_NET
        )
    with pytest.raises(ConfigError, match=r"learner 'iql' has no conservative term"):
        train(
            tiny_train(learner="iql", conservative=0.1),
            random_sampler,
            tmp_path / "c",
            init_checkpoint=parent_checkpoint,
            progress=False,
        )
    assert parse_learner("iql:expectile=0.9,v_warmup=100") == ("iql", {"expectile": 0.9, "v_warmup": 100})
    with pytest.raises(ConfigError, match=r"option 'expectile' is not KEY=VALUE"):
        parse_learner("iql:expectile")


def test_iql_fine_tunes_with_every_method_and_keeps_the_recipes_other_settings(
    random_sampler, parent_checkpoint, tmp_path
):
    for method in ("ft", "new_head", "pnn"):
        cfg = tiny_train(steps=4, learner="iql", learner_options={"v_warmup": 2})
        run = train(
            cfg, random_sampler, tmp_path / method, init_checkpoint=parent_checkpoint, method=method, progress=False
        )
        config = read_config(run.checkpoint)
        assert config["method"] == method and config["training"]["conservative"] == 0.0
        assert config["training"]["lr"] == pytest.approx(0.25 * 1e-3)
