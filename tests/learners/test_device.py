"""Where the learner runs: ``--device cpu|cuda|auto``, the device-clean step, batched acting, data on the device.

These run on any CPU.  The tests marked ``cuda`` need an NVIDIA GPU and skip without one; the GPU's figures come
from ``scripts/gpu/check.sh`` (docs/benchmarks.md).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from learner_factories import TINY_CEM, TINY_NET, random_transitions, tiny_train

from nsl import keys
from nsl.errors import ConfigError
from nsl.learners import ArraySampler, CEMPolicy, Learner, QNetwork, TrainConfig, bellman_target, train
from nsl.learners.cuda_graph import DeviceData, GraphedStep
from nsl.learners.device import CUDA_ENV, resolve_device
from nsl.learners.qtopt import METRICS, QTOpt, batch_to_torch, refresh_lagged, step_metrics, update

_NO_GPU = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs an NVIDIA GPU that torch can see")


def cuda(test):
    """Marked ``cuda`` (``pytest -m cuda`` selects them on a GPU machine) and skipped without a GPU."""
    return pytest.mark.cuda(_NO_GPU(test))


@pytest.fixture
def no_gpu(monkeypatch):
    """This machine as one without a GPU, whatever it has."""
    monkeypatch.setenv(CUDA_ENV, "0")


def test_device_names_resolve_and_cuda_without_a_gpu_fails_in_one_line_that_names_the_fix(no_gpu):
    assert resolve_device("auto") == "cpu"
    assert resolve_device("cpu") == "cpu"
    with pytest.raises(ConfigError) as e:
        resolve_device("cuda")
    assert "\n" not in str(e.value) and "--device cpu" in str(e.value)
    with pytest.raises(ConfigError, match="unknown; use one of cpu, cuda, auto"):
        resolve_device("gpu")
    with pytest.raises(ConfigError, match="device 'tpu' is unknown"):
        TrainConfig(device="tpu")


def test_training_on_cuda_without_a_gpu_stops_before_any_step(no_gpu, tmp_path, random_sampler):
    with pytest.raises(ConfigError, match="--device cpu"):
        train(tiny_train(device="cuda"), random_sampler, tmp_path, net=TINY_NET, progress=False)
    assert not (tmp_path / "run.json").exists()


def test_the_cpu_is_absent_from_a_config_so_existing_checkpoint_ids_hold(tmp_path, random_sampler):
    assert "device" not in TrainConfig().to_dict()
    assert TrainConfig(device="cuda").to_dict()["device"] == "cuda"
    # auto resolves to the device that trained, which a CPU run leaves out of its checkpoint
    runs = {}
    for device in ("cpu", "auto"):
        cfg = tiny_train(steps=4, checkpoint_every=4, device=device)
        result = train(cfg, random_sampler, tmp_path / device, net=TINY_NET, progress=False)
        runs[device] = (result.checkpoint / "model.safetensors").read_bytes()
        config = json.loads((result.checkpoint / "config.json").read_text())
        assert "device" not in config["training"]
    assert runs["cpu"] == runs["auto"]


def _batch(n=32, seed=0):
    return batch_to_torch(random_transitions(n, seed=seed, done_rate=0.4))


def test_masked_terminal_targets_equal_the_indexed_ones():
    """A GPU step searches every next state and masks the terminal ones; the CPU's indexes them out.  Both give
    the same targets (to rounding: the batch shapes differ) and zero values where the episode ended."""
    b = _batch()
    torch.manual_seed(0)
    polyak, lagged = QNetwork(TINY_NET).eval(), QNetwork(TINY_NET).eval()
    x = b[keys.NEXT_OBS_IMAGE].permute(0, 3, 1, 2).float() / 255
    gen = torch.Generator().manual_seed(3)
    noise = torch.randn(len(x), TINY_CEM.iterations, TINY_CEM.samples, len(TINY_NET.action_dims), generator=gen)
    args = (polyak, lagged, x, b[keys.NEXT_OBS_STATE], b[keys.REWARD], b[keys.DONE], 0.9, TINY_CEM, noise)
    with torch.no_grad():
        indexed, v_indexed = bellman_target(*args, masked=False)
        masked, v_masked = bellman_target(*args, masked=True)
    done = b[keys.DONE] > 0.5
    assert done.any() and (~done).any()
    assert torch.equal(v_masked[done], torch.zeros(int(done.sum())))
    assert torch.allclose(masked, indexed, atol=1e-6) and torch.allclose(v_masked, v_indexed, atol=1e-6)


def test_the_learner_interface_returns_metrics_unread_with_the_values_update_reads():
    b = _batch()
    cfg = tiny_train(conservative=0.1).replace(lr=1e-3)
    learners = []
    for _ in range(2):
        torch.manual_seed(0)
        learners.append(Learner.create(QNetwork(TINY_NET), 1e-3, cfg))
    lazy = QTOpt().update(learners[0], b, cfg, 0, None)
    read = update(learners[1], b, cfg, 0)
    assert list(lazy) == list(METRICS) == list(read)
    assert all(isinstance(v, torch.Tensor) and v.dim() == 0 for v in lazy.values())
    assert {k: float(v) for k, v in lazy.items()} == read


def _sampler_of_frames(n=40, seed=0):
    """Transitions whose frames carry their own index in pixel (0, 0) and in the state, to check what was drawn."""
    t = random_transitions(n, seed=seed)
    t[keys.OBS_IMAGE][:, 0, 0, 0] = np.arange(n)
    t[keys.NEXT_OBS_IMAGE][:, 0, 0, 0] = np.arange(n) + 100
    t[keys.OBS_STATE][:, 0] = np.arange(n)
    t[keys.NEXT_OBS_STATE][:, 0] = np.arange(n) + 100
    return ArraySampler.from_transitions(t), t


def test_device_data_draws_whole_transitions_by_source_weight():
    a, ta = _sampler_of_frames(40, seed=0)
    b, tb = _sampler_of_frames(30, seed=1)
    data = DeviceData(a.tables() + [(b.tables()[0][0], 3.0)], "cpu")
    gen = torch.Generator().manual_seed(0)
    batch = data.sample(4000, gen)
    i = batch[keys.OBS_IMAGE][:, 0, 0, 0].long().numpy()
    assert np.array_equal(batch[keys.NEXT_OBS_IMAGE][:, 0, 0, 0].long().numpy(), i + 100)  # its own next frame
    assert np.array_equal(batch[keys.OBS_STATE][:, 0].numpy(), i.astype(np.float32))
    from_b = np.isin(batch[keys.ACTION].numpy()[:, 0], tb[keys.ACTION][:, 0])  # which source: by its actions
    assert 0.72 < from_b.mean() < 0.78  # weights 1 : 3
    rows = np.where(from_b, 0, 1)
    for t, mask in ((tb, from_b), (ta, rows == 1)):
        assert np.array_equal(batch[keys.ACTION].numpy()[mask], t[keys.ACTION][i[mask]])
        assert np.array_equal(batch[keys.REWARD].numpy()[mask], t[keys.REWARD][i[mask]])
        assert np.array_equal(batch[keys.DONE].numpy()[mask], t[keys.DONE][i[mask]])
    again = data.sample(4000, torch.Generator().manual_seed(0))
    assert all(torch.equal(batch[k], again[k]) for k in batch)  # the same generator, the same batch


def test_the_graphed_step_is_the_sampled_step_and_refreshes_the_lagged_network_on_schedule():
    """On the CPU the graphed step runs its body eagerly: a batch drawn on the device, then qtopt's step, with the
    lagged copy refreshed every lag_period steps, as the replayed graph does on a GPU."""
    sampler, _ = _sampler_of_frames(64)
    cfg = tiny_train(lag_period=3, conservative=0.1).replace(lr=1e-3)
    torch.manual_seed(0)
    ours = Learner.create(QNetwork(TINY_NET), 1e-3, cfg)
    torch.manual_seed(0)
    ref = Learner.create(QNetwork(TINY_NET), 1e-3, cfg)
    data = DeviceData(sampler.tables(), "cpu")
    graphed = GraphedStep(ours, data, cfg)
    for step in range(7):
        got = graphed(step)
        expected = step_metrics(ref, data.sample(cfg.batch_size, ref.generator), cfg, step, refresh_lag=False)
        if (step + 1) % cfg.lag_period == 0:
            refresh_lagged(ref)
        assert torch.equal(got, expected)
    for a, b in zip(ours.lagged.state_dict().values(), ref.lagged.state_dict().values()):
        assert torch.equal(a, b)
    assert not torch.equal(ours.lagged.columns[0].out.weight, ours.online.columns[0].out.weight)  # refreshed at 6


def test_a_graphed_step_refuses_a_decaying_rate():
    cfg = tiny_train(lr_decay=100).replace(lr=1e-3)
    learner = Learner.create(QNetwork(TINY_NET), 1e-3, cfg)
    with pytest.raises(ConfigError, match="lr_decay 0"):
        GraphedStep(learner, DeviceData(_sampler_of_frames()[0].tables(), "cpu"), cfg)


def _obs(n, seed=0):
    rng = np.random.default_rng(seed)
    return {
        "image": rng.integers(0, 256, (n, 16, 16, 3), dtype=np.uint8),
        "state": rng.random((n, 6), dtype=np.float32),
    }


def test_batched_acting_is_reproducible_for_a_batch_and_close_to_acting_one_state_at_a_time():
    torch.manual_seed(0)
    net = QNetwork(TINY_NET)
    obs = _obs(8)
    per_state, batched = CEMPolicy(net, TINY_CEM), CEMPolicy(net, TINY_CEM, batched=True)
    assert not per_state.batched and "device" not in per_state.describe() and "batched" not in per_state.describe()
    assert batched.describe()["batched"] is True

    def rngs():
        return [np.random.default_rng([5, i]) for i in range(8)]

    a1, l1 = batched.greedy(obs, rngs())
    a2, l2 = batched.greedy(obs, rngs())
    assert np.array_equal(a1, a2) and np.array_equal(l1, l2)
    a0, l0 = per_state.greedy(obs, rngs())
    assert np.allclose(l1, l0, atol=1e-5)  # the same search: the best logits agree to rounding


def test_a_checkpoint_trained_on_a_device_loads_and_acts_on_the_cpu(tmp_path, random_sampler):
    """A GPU run records its device; its weights and trainer state are saved from the device and load on the CPU.
    Without a GPU the record is written as a GPU run writes it, and read back here."""
    from nsl.learners import load_checkpoint, load_policy
    from nsl.learners.checkpoint import load_trainer_state

    result = train(tiny_train(steps=4, checkpoint_every=2), random_sampler, tmp_path, net=TINY_NET, progress=False)
    config_file = result.checkpoint / "config.json"
    config = json.loads(config_file.read_text())
    config["training"]["device"] = "cuda"
    config_file.write_text(json.dumps(config))
    ckpt = load_checkpoint(result.checkpoint)
    assert ckpt.training.device == "cuda" and next(ckpt.net.parameters()).device.type == "cpu"
    policy = load_policy(result.checkpoint)
    assert policy.device == "cpu" and policy(_obs(2), rngs=[np.random.default_rng(i) for i in range(2)]).shape == (2, 6)
    state = load_trainer_state(tmp_path / "checkpoints" / "step-000000004")
    assert state is not None and state["learner"]["generator"].device.type == "cpu"


def test_the_device_figures_run_here_with_torch_alone():
    from nsl.bench._device import acting_figures, learner_figures

    learner = learner_figures("cpu", steps=2, quick=True)
    assert learner["device"] == "cpu" and learner["b64_fp32_steps_per_s"] > 0
    assert learner["b64_fp32_transitions_per_s"] == round(64 * learner["b64_fp32_steps_per_s"])
    assert "b64_fp32_kernel_ms_per_step" not in learner  # kernel time is a GPU figure
    acting = acting_figures("cpu", states=4, quick=True)
    assert acting["batched_states_per_s"] > 0 and acting["per_state_states_per_s"] > 0


@cuda
def test_cuda_training_records_its_device_and_its_checkpoint_evaluates_on_the_cpu(tmp_path, random_sampler):
    from nsl.learners import load_checkpoint, load_policy

    result = train(tiny_train(steps=6, device="cuda"), random_sampler, tmp_path, net=TINY_NET, progress=False)
    assert load_checkpoint(result.checkpoint).training.device == "cuda"
    policy = load_policy(result.checkpoint)
    assert policy(_obs(2), rngs=[np.random.default_rng(i) for i in range(2)]).shape == (2, 6)
    again = train(tiny_train(steps=6, device="cuda"), random_sampler, tmp_path / "again", net=TINY_NET, progress=False)
    a = (result.checkpoint / "model.safetensors").read_bytes()
    assert a == (again.checkpoint / "model.safetensors").read_bytes()  # the same seed, the same run


@cuda
def test_cuda_graphed_steps_replay_the_eager_body():
    sampler, _ = _sampler_of_frames(64)
    cfg = tiny_train(device="cuda").replace(lr=1e-3)
    torch.manual_seed(0)
    learner = Learner.create(QNetwork(TINY_NET), 1e-3, cfg)
    graphed = GraphedStep(learner, DeviceData(sampler.tables(), "cuda"), cfg, warmup=2)
    losses = [float(graphed(step)[0]) for step in range(12)]
    assert graphed.graph is not None and all(np.isfinite(losses))


@pytest.mark.parametrize(
    "argv",
    [
        ["train", "--data", "grasp-base", "--name", "on-gpu", "--steps", "10", "--device", "cuda"],
        ["collect", "--shift", "base", "--episodes", "1", "--policy", "base", "--data", "d", "--device", "cuda"],
        ["eval", "--checkpoint", "ckpt:base", "--episodes", "1", "--device", "cuda"],
        ["bench", "learner", "--device", "cuda"],
        ["bench", "eval", "--device", "cuda"],
    ],
)
def test_the_commands_refuse_cuda_without_a_gpu_in_one_line(no_gpu, argv, capsys):
    from tests.conftest import run_cli

    assert run_cli(*argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "device cuda needs an NVIDIA GPU" in err[0] and "--device cpu" in err[0]
