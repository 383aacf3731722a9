"""The study's fine-tuning methods: what each one starts from and what it may change."""

from __future__ import annotations

import shutil

import pytest
import torch
from learner_factories import TINY_NET, random_transitions, tiny_train

from nsl.errors import ConfigError
from nsl.learners import ArraySampler, NetConfig, QNetwork, checkpoint_id, load_checkpoint, train
from nsl.learners.networks import is_head_parameter

TARGET = ArraySampler.from_transitions(random_transitions(64, seed=9), name="target")


def _inputs(n=5):
    g = torch.Generator().manual_seed(4)
    return torch.rand(n, 3, 16, 16, generator=g), torch.rand(n, 6, generator=g), torch.rand(n, 4, generator=g) * 2 - 1


def _weights(path):
    return load_checkpoint(path).net.state_dict()


def test_fine_tuning_starts_from_exactly_the_parent_at_a_quarter_of_its_lr(parent_checkpoint, tmp_path):
    result = train(tiny_train(steps=0), TARGET, tmp_path / "ft", init_checkpoint=parent_checkpoint, progress=False)
    parent, child = _weights(parent_checkpoint), _weights(result.checkpoint)
    assert parent.keys() == child.keys() and all(torch.equal(parent[k], child[k]) for k in parent)
    cfg = load_checkpoint(result.checkpoint).config
    assert cfg["method"] == "ft" and cfg["training"]["lr"] == pytest.approx(0.25e-3)
    assert cfg["parent"]["id"] == checkpoint_id(parent_checkpoint) and "path" not in cfg["parent"]
    assert cfg["data"]["sources"][0]["name"] == "target"


def test_a_fine_tune_has_the_recipes_conservative_term_unless_told_and_pre_training_has_none(
    parent_checkpoint, tmp_path
):
    """The conservative term's weight resolves like the rate: FINE_TUNE_CONSERVATIVE with a parent, 0 without,
    an explicit value always; the checkpoint records the value the run used, and it reaches the loss."""
    from nsl.learners import FINE_TUNE_CONSERVATIVE

    def run(name, cfg, **kw):
        result = train(cfg, TARGET, tmp_path / name, progress=False, **kw)
        return load_checkpoint(result.checkpoint).config["training"]["conservative"], result

    assert FINE_TUNE_CONSERVATIVE == 0.1
    assert run("ft", tiny_train(steps=2), init_checkpoint=parent_checkpoint)[0] == FINE_TUNE_CONSERVATIVE
    assert run("scratch", tiny_train(steps=2), net=TINY_NET)[0] == 0.0
    assert run("plain", tiny_train(steps=2, conservative=0.0), init_checkpoint=parent_checkpoint)[0] == 0.0
    used, result = run("strong", tiny_train(steps=5, log_every=5, conservative=0.3), init_checkpoint=parent_checkpoint)
    assert used == 0.3 and result.metrics["losses/conservative"] > 0
    _, plain = run("plain5", tiny_train(steps=5, log_every=5, conservative=0.0), init_checkpoint=parent_checkpoint)
    assert plain.metrics["losses/conservative"] == 0


def test_a_fine_tune_has_the_same_id_wherever_its_parent_and_output_are(parent_checkpoint, tmp_path):
    """The id hashes the config, so the config names the parent by content, never by folder."""
    moved = shutil.copytree(parent_checkpoint, tmp_path / "elsewhere" / parent_checkpoint.name)
    a = train(tiny_train(steps=2), TARGET, tmp_path / "a", init_checkpoint=parent_checkpoint, progress=False)
    b = train(tiny_train(steps=2), TARGET, tmp_path / "b" / "deeper", init_checkpoint=moved, progress=False)
    assert checkpoint_id(a.checkpoint) == checkpoint_id(b.checkpoint)


def test_fine_tuning_changes_every_column_weight(parent_checkpoint, tmp_path):
    result = train(tiny_train(steps=3), TARGET, tmp_path / "ft", init_checkpoint=parent_checkpoint, progress=False)
    parent, child = _weights(parent_checkpoint), _weights(result.checkpoint)
    assert all(not torch.equal(parent[k], child[k]) for k in parent)


def test_new_head_reinitialises_only_the_head(parent_checkpoint, tmp_path):
    result = train(
        tiny_train(steps=0),
        TARGET,
        tmp_path / "nh",
        init_checkpoint=parent_checkpoint,
        method="new_head",
        progress=False,
    )
    parent, child = _weights(parent_checkpoint), _weights(result.checkpoint)
    head = [k for k in parent if is_head_parameter(k)]
    trunk = [k for k in parent if not is_head_parameter(k)]
    assert {k.split(".")[2] for k in head} == {"state_fc", "action_fc", "hidden_fcs", "out"}
    assert trunk and all(k.split(".")[2] == "convs" for k in trunk)
    assert all(torch.equal(parent[k], child[k]) for k in trunk)
    assert all(not torch.equal(parent[k], child[k]) for k in head)


@pytest.mark.parametrize("method", ["pnn", "ft_pnn"])
def test_progressive_network_leaves_the_base_column_unchanged(parent_checkpoint, tmp_path, method):
    result = train(
        tiny_train(steps=5, lr=1e-2),
        TARGET,
        tmp_path / method,
        init_checkpoint=parent_checkpoint,
        method=method,
        progress=False,
    )
    parent = load_checkpoint(parent_checkpoint).net
    child = load_checkpoint(result.checkpoint).net
    assert child.cfg.columns == 2 and child.columns[0].n_lateral == 0 and child.columns[1].n_lateral == 1
    image, state, action = _inputs()
    with torch.no_grad():
        base_before = parent.columns[0].encode(parent.input(image), state, [])
        base_after = child.columns[0].encode(child.input(image), state, [])
        assert torch.equal(base_before["ctx"], base_after["ctx"])
        assert all(torch.equal(a, b) for a, b in zip(base_before["convs"], base_after["convs"]))
        column0 = child.columns[0].score(base_after, action.unsqueeze(1), [])[0]
        assert torch.equal(column0, parent(image, state, action).unsqueeze(1))
        assert not torch.allclose(child(image, state, action), parent(image, state, action))
    for k, v in parent.state_dict().items():
        assert torch.equal(child.state_dict()[k], v)  # column 0 is the parent, bit for bit


def test_ft_pnn_starts_as_the_parent_function_and_pnn_does_not(parent_checkpoint, tmp_path):
    parent = load_checkpoint(parent_checkpoint).net
    image, state, action = _inputs()
    outs = {}
    for method in ("ft_pnn", "pnn"):
        result = train(
            tiny_train(steps=0),
            TARGET,
            tmp_path / method,
            init_checkpoint=parent_checkpoint,
            method=method,
            progress=False,
        )
        with torch.no_grad():
            outs[method] = load_checkpoint(result.checkpoint).net(image, state, action)
    with torch.no_grad():
        expected = parent(image, state, action)
    assert torch.allclose(outs["ft_pnn"], expected, atol=1e-6)
    assert not torch.allclose(outs["pnn"], expected, atol=1e-3)


def test_scratch_ignores_the_parent_weights_and_keeps_its_lr(parent_checkpoint, tmp_path):
    result = train(
        tiny_train(steps=0), TARGET, tmp_path / "s", init_checkpoint=parent_checkpoint, method="scratch", progress=False
    )
    parent, child = _weights(parent_checkpoint), _weights(result.checkpoint)
    assert parent.keys() == child.keys() and not any(torch.equal(parent[k], child[k]) for k in parent)
    assert load_checkpoint(result.checkpoint).config["training"]["lr"] == pytest.approx(1e-3)


def test_bad_method_arguments_are_refused(parent_checkpoint, tmp_path):
    with pytest.raises(ConfigError, match="method 'finetune' is unknown"):
        train(tiny_train(), TARGET, tmp_path / "x", init_checkpoint=parent_checkpoint, method="finetune")
    with pytest.raises(ConfigError, match="pass init_checkpoint"):
        train(tiny_train(), TARGET, tmp_path / "x", method="ft")
    with pytest.raises(ConfigError, match="architecture comes from init_checkpoint"):
        train(tiny_train(), TARGET, tmp_path / "x", init_checkpoint=parent_checkpoint, net=TINY_NET)


def test_new_head_of_a_spatial_network_reinitialises_its_spatial_layers_only(random_sampler, tmp_path):
    net = NetConfig.from_dict({**TINY_NET.to_dict(), "pool": "spatial"})
    parent = train(tiny_train(steps=2), random_sampler, tmp_path / "p", net=net, progress=False).checkpoint
    result = train(
        tiny_train(steps=0), TARGET, tmp_path / "nh", init_checkpoint=parent, method="new_head", progress=False
    )
    before, after = _weights(parent), _weights(result.checkpoint)
    head = {k.split(".")[2] for k in before if is_head_parameter(k)}
    assert head == {"state_fc", "state_proj", "spatial_fc", "action_fc", "hidden_fcs", "out"}
    for k in before:
        assert torch.equal(before[k], after[k]) != is_head_parameter(k), k


def test_spatial_network_scores_candidates_as_its_forward_pass_does():
    net = QNetwork(NetConfig.from_dict({**TINY_NET.to_dict(), "pool": "spatial"}))
    image, state, _ = _inputs(3)
    candidates = torch.rand(3, 7, 4) * 2 - 1
    with torch.no_grad():
        batched = net.score(net.encode(image, state), candidates)
        one_by_one = torch.stack([net(image, state, candidates[:, j]) for j in range(7)], 1)
    assert torch.allclose(batched, one_by_one, atol=1e-5)
    with pytest.raises(ConfigError, match="spatial"):
        NetConfig(pool="spatial", columns=2)


def test_reinit_head_redraws_exactly_the_head_parameters_of_the_last_column():
    from nsl.learners.networks import grow_column, reinit_head

    net = grow_column(QNetwork(TINY_NET), copy_last=True)  # two columns, with laterals into the head
    before = {k: v.clone() for k, v in net.state_dict().items()}
    reinit_head(net)
    changed = {k for k, v in net.state_dict().items() if not torch.equal(before[k], v)}
    last = f"columns.{net.cfg.columns - 1}."
    expected = {k for k in before if k.startswith(last) and is_head_parameter(k)}
    assert changed == expected and any(".lateral." in k for k in changed)
    assert not any(k.startswith("columns.0.") for k in changed)


def test_shrink_perturb_starts_from_alpha_parent_plus_sigma_fresh_init(parent_checkpoint, tmp_path):
    cfg = tiny_train(steps=0, shrink_perturb=(0.8, 0.01))
    result = train(cfg, TARGET, tmp_path / "sp", init_checkpoint=parent_checkpoint, progress=False)
    parent, child = _weights(parent_checkpoint), _weights(result.checkpoint)
    arch = load_checkpoint(parent_checkpoint).net.cfg  # loading draws an initialisation too: before the seed
    torch.manual_seed(cfg.seed + 1)
    fresh = QNetwork(arch).state_dict()
    for k in parent:
        assert torch.allclose(child[k], 0.8 * parent[k] + 0.01 * fresh[k], atol=1e-7), k
    assert load_checkpoint(result.checkpoint).config["training"]["shrink_perturb"] == [0.8, 0.01]
    # alpha 1, sigma 0 is the parent itself
    same = train(
        tiny_train(steps=0, shrink_perturb=(1.0, 0.0)),
        TARGET,
        tmp_path / "same",
        init_checkpoint=parent_checkpoint,
        progress=False,
    )
    assert all(torch.equal(parent[k], v) for k, v in _weights(same.checkpoint).items())


def test_shrink_perturb_is_refused_without_a_parent_or_with_bad_values(tmp_path):
    with pytest.raises(ConfigError, match="init_checkpoint"):
        train(tiny_train(steps=0, shrink_perturb=(0.8, 0.01)), TARGET, tmp_path / "x", net=TINY_NET, progress=False)
    for bad in ((0.0, 0.01), (1.5, 0.0), (0.8, -1.0), (0.8,)):
        with pytest.raises(ConfigError, match="shrink_perturb"):
            tiny_train(shrink_perturb=bad)
