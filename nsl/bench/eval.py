"""``nsl bench eval``: episodes/s of CEM-policy evaluation with 1 and with 2 workers.

The policy is a freshly initialised Q-network (the speed does not depend on
its weights) acting through CEM (64 samples, 6 elites, 2 iterations), batched
over 8 environments per worker, on the base task's test objects.
"""

from __future__ import annotations

import functools
import tempfile
import time
from pathlib import Path

HELP = "episodes/s of CEM-policy evaluation with 1 and 2 worker processes"


def add_arguments(p) -> None:
    p.add_argument("--episodes", type=int, default=None, help="episodes per measurement (default 320, quick 48)")
    p.add_argument(
        "--device",
        default="cpu",
        choices=("cpu", "cuda", "auto"),
        help="cpu: evaluation episodes/s (above); cuda (or auto with a GPU): the CEM policy's acting on the GPU, "
        "states/s searched one a call against --states a call (no simulator needed)",
    )
    p.add_argument("--states", type=int, default=64, help="with --device cuda: states per batched call")


def _make_checkpoint(folder: Path) -> Path:
    import torch

    from nsl.learners import NetConfig, QNetwork, TrainConfig, checkpoint_config, save_checkpoint

    torch.manual_seed(0)
    net = QNetwork(NetConfig())
    config = checkpoint_config(net, training=TrainConfig(lr=3e-4), method="scratch", data={}, parent=None, step=0)
    return save_checkpoint(folder / "bench-policy", net, config)


def _rate(make_policy, episodes: int, workers: int) -> tuple[float, float]:
    """Episodes/s over the whole run, and after the first batch arrived (worker start-up excluded)."""
    from nsl.collectors import EnvConfig, collect_episodes

    t0 = time.perf_counter()
    first, n = 0.0, 0
    for _ in collect_episodes(EnvConfig(split="test"), make_policy, range(episodes), seed=7, workers=workers, batch=8):
        n += 1
        if n == 8:
            first = time.perf_counter()
    end = time.perf_counter()
    return n / (end - t0), (n - 8) / max(end - first, 1e-9)


def run(args) -> dict:
    from nsl.learners.device import resolve_device

    device = resolve_device(getattr(args, "device", "cpu"))
    if device != "cpu":
        from ._device import acting_figures

        return acting_figures(device, states=args.states, quick=args.quick)
    from nsl.learners import load_policy

    episodes = args.episodes or (48 if args.quick else 320)
    with tempfile.TemporaryDirectory() as tmp:
        path = _make_checkpoint(Path(tmp))
        make_policy = functools.partial(load_policy, str(path))
        one, one_steady = _rate(make_policy, episodes, 1)
        two, two_steady = _rate(make_policy, episodes, 2)
    return {
        "episodes": episodes,
        "eval_episodes_per_s_1_worker": round(one, 2),
        "eval_episodes_per_s_2_workers": round(two, 2),
        "speedup_2_workers": round(two / one, 2),
        "eval_episodes_per_s_1_worker_after_startup": round(one_steady, 2),
        "eval_episodes_per_s_2_workers_after_startup": round(two_steady, 2),
        "cem": "64/6/2",
        "batch_per_worker": 8,
        "note": "one worker runs in-process with torch's default 2 threads; each of 2 workers uses 1 thread",
        **_precision_rates(episodes),
    }


def _precision_rates(episodes: int) -> dict:
    """The shipped base acting in fp32 and in bf16, 2 workers each, one after the other in this run."""
    from nsl import workspace
    from nsl.learners import load_policy
    from nsl.learners.precision import bf16_supported

    if not bf16_supported():
        return {"bf16_supported": False}
    base = str(workspace.shipped_base_dir())
    fp32, fp32_steady = _rate(functools.partial(load_policy, base, precision="fp32"), episodes, 2)
    bf16, bf16_steady = _rate(functools.partial(load_policy, base, precision="bf16"), episodes, 2)
    return {
        "bf16_supported": True,
        "base_fp32_episodes_per_s_2_workers": round(fp32, 2),
        "base_bf16_episodes_per_s_2_workers": round(bf16, 2),
        "bf16_speedup": round(bf16 / fp32, 2),
        "bf16_speedup_after_startup": round(bf16_steady / max(fp32_steady, 1e-9), 2),
    }
