"""A killed run resumes from its last checkpoint and ends with bit-identical weights."""

from __future__ import annotations

import csv

import pytest
import torch
from learner_factories import TINY_NET, tiny_train

from nsl.errors import ConfigError
from nsl.learners import load_checkpoint, train


class _Crash(Exception):
    pass


class _CrashingSampler:
    """Delegates to a sampler and raises on its ``crash_at``-th call (0-based), like a kill mid-run."""

    def __init__(self, inner, crash_at):
        self.inner, self.crash_at, self.calls = inner, crash_at, 0

    def sample(self, batch_size, rng):
        if self.calls == self.crash_at:
            raise _Crash("killed")
        self.calls += 1
        return self.inner.sample(batch_size, rng)

    def describe(self):
        return self.inner.describe()


@pytest.mark.parametrize("learner", ["qtopt", "iql"])
def test_resumed_run_equals_an_uninterrupted_one(random_sampler, tmp_path, learner):
    cfg = tiny_train(
        steps=24, checkpoint_every=8, log_every=4, lag_period=5, augment_crop=2, augment_colour=0.2, learner=learner
    )
    if learner == "iql":
        cfg = cfg.replace(learner_options={"v_warmup": 3})
    whole = train(cfg, random_sampler, tmp_path / "whole", net=TINY_NET, progress=False)
    with pytest.raises(_Crash):
        train(cfg, _CrashingSampler(random_sampler, crash_at=13), tmp_path / "killed", net=TINY_NET, progress=False)
    assert not (tmp_path / "killed" / "final").exists()
    resumed = train(cfg, random_sampler, tmp_path / "killed", net=TINY_NET, progress=False)
    a, b = load_checkpoint(whole.checkpoint).net.state_dict(), load_checkpoint(resumed.checkpoint).net.state_dict()
    assert all(torch.equal(a[k], b[k]) for k in a)
    with open(tmp_path / "killed" / "metrics.csv") as f:
        steps = [int(r["step"]) for r in csv.DictReader(f)]
    assert steps == [4, 8, 12, 16, 20, 24]  # rows after the resumed step (8) were written once
    # the target networks and optimiser were restored too: continuing both runs gives the same weights again
    longer = cfg.replace(steps=32)
    a2 = train(longer, random_sampler, tmp_path / "whole", net=TINY_NET, progress=False)
    b2 = train(longer, random_sampler, tmp_path / "killed", net=TINY_NET, progress=False)
    a, b = load_checkpoint(a2.checkpoint).net.state_dict(), load_checkpoint(b2.checkpoint).net.state_dict()
    assert a2.step == 32 and all(torch.equal(a[k], b[k]) for k in a)


def test_a_finished_run_returns_at_once_and_other_settings_are_refused(random_sampler, tmp_path):
    cfg = tiny_train(steps=4, checkpoint_every=2)
    first = train(cfg, random_sampler, tmp_path / "run", net=TINY_NET, progress=False)
    again = train(cfg, _CrashingSampler(random_sampler, crash_at=0), tmp_path / "run", net=TINY_NET, progress=False)
    assert again.step == first.step == 4
    with pytest.raises(ConfigError, match=r"different training \(\['gamma'\]\)"):
        train(cfg.replace(gamma=0.5), random_sampler, tmp_path / "run", net=TINY_NET, progress=False)


def test_eval_hook_is_called_every_k_steps_and_can_stop_the_run(random_sampler, tmp_path):
    calls = []

    def eval_fn(step, policy):
        import numpy as np

        obs = {"image": np.zeros((2, 16, 16, 3), np.uint8), "state": np.zeros((2, 6), np.float32)}
        actions = policy(obs, rngs=[np.random.default_rng(0), np.random.default_rng(1)])
        calls.append((step, actions.shape))
        return {"success": 0.5, "stop": step >= 6}

    result = train(
        tiny_train(steps=20, eval_every=3),
        random_sampler,
        tmp_path / "run",
        net=TINY_NET,
        eval_fn=eval_fn,
        progress=False,
    )
    assert [c[0] for c in calls] == [0, 3, 6] and calls[0][1] == (2, 6)
    assert result.stopped_early and result.step == 6
    assert load_checkpoint(result.checkpoint).step == 6
    assert (tmp_path / "run" / "checkpoints" / "step-000000006").is_dir()
    assert [e["step"] for e in result.evals] == [0, 3, 6]
    assert (tmp_path / "run" / "eval.jsonl").read_text().count("\n") == 3


def test_cosine_lr_decay_follows_its_schedule_and_resumes_exactly(random_sampler, tmp_path):
    cfg = tiny_train(steps=16, checkpoint_every=8, log_every=4, lr=1e-3, lr_decay=12, lr_floor=0.1)
    assert cfg.lr_at(0) == pytest.approx(1e-3) and cfg.lr_at(6) == pytest.approx(0.55e-3)
    assert cfg.lr_at(12) == cfg.lr_at(100) == pytest.approx(1e-4)
    whole = train(cfg, random_sampler, tmp_path / "whole", net=TINY_NET, progress=False)
    with open(tmp_path / "whole" / "metrics.csv") as f:
        logged = [float(r["charts/lr"]) for r in csv.DictReader(f)]
    assert logged == pytest.approx([cfg.lr_at(s) for s in (3, 7, 11, 15)], rel=1e-4)  # the rate of each row's last step
    with pytest.raises(_Crash):
        train(cfg, _CrashingSampler(random_sampler, crash_at=10), tmp_path / "killed", net=TINY_NET, progress=False)
    resumed = train(cfg, random_sampler, tmp_path / "killed", net=TINY_NET, progress=False)
    a, b = load_checkpoint(whole.checkpoint).net.state_dict(), load_checkpoint(resumed.checkpoint).net.state_dict()
    assert all(torch.equal(a[k], b[k]) for k in a)
    constant = train(cfg.replace(lr_decay=0), random_sampler, tmp_path / "constant", net=TINY_NET, progress=False)
    c = load_checkpoint(constant.checkpoint).net.state_dict()
    assert not all(torch.equal(a[k], c[k]) for k in a)  # the schedule reached the optimiser
    with pytest.raises(ConfigError, match="lr_decay"):
        cfg.replace(lr_decay=-1)


def test_a_run_recorded_before_a_setting_existed_still_resumes(random_sampler, tmp_path):
    import json

    cfg = tiny_train(steps=8, checkpoint_every=4)
    with pytest.raises(_Crash):
        train(cfg, _CrashingSampler(random_sampler, crash_at=6), tmp_path / "run", net=TINY_NET, progress=False)
    run_file = tmp_path / "run" / "run.json"
    run = json.loads(run_file.read_text())
    for added in ("lr_decay", "lr_floor", "conservative"):  # settings newer than the run: they take their defaults
        del run["training"][added]  # (a run recorded without the conservative term had none: 0)
    run_file.write_text(json.dumps(run))
    assert train(cfg, random_sampler, tmp_path / "run", net=TINY_NET, progress=False).step == 8
    with pytest.raises(ConfigError, match=r"different training \(\['lr_decay'\]\)"):
        train(cfg.replace(steps=12, lr_decay=12), random_sampler, tmp_path / "run", net=TINY_NET, progress=False)
