"""QT-Opt's step on a GPU as one CUDA graph, on training data that lives on the GPU.

Eager, a step launches some 360 small kernels, and at batch 64 the GPU waits
on Python and the launches most of the time.  Here the whole step is captured
once and replayed:

* :class:`DeviceData`: a sampler's transitions on the GPU (images as uint8,
  only the frames the transitions read).  A batch is drawn there: each row's
  source by weight, then a transition of that source, uniformly, all from the
  step's generator, so the host copies nothing.
* :class:`GraphedStep`: draw a batch, then ``qtopt.step_metrics`` (augment,
  the CEM target, the loss, backward, Adam, Polyak) captured as one
  ``torch.cuda.CUDAGraph``.  The lagged network's refresh (every
  ``lag_period`` steps) copies weights in place between replays.

The step's text is ``learners/qtopt.py``'s; only where its inputs come from
changes.  A graphed run is reproducible on the same GPU, and it is not the
eager CUDA run: their batches are drawn differently.  Adam runs fused and
capturable, at a constant learning rate (``lr_decay`` 0).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from nsl import keys
from nsl.errors import ConfigError

from .config import TrainConfig
from .qtopt import Learner, refresh_lagged, step_metrics

# The per-transition columns of a sampler's table (``Sampler.tables()``), besides "images", "obs" and "next".
COLUMNS = (keys.OBS_STATE, keys.NEXT_OBS_STATE, keys.ACTION, keys.REWARD, keys.DONE)


class DeviceData:
    """A sampler's transitions on ``device``; :meth:`sample` draws a batch there.

    ``tables`` is what ``sampler.tables()`` returns: per source, a dict with ``images`` (F, H, W, 3) uint8,
    ``obs`` and ``next`` (T,) frame indices into it, the ``COLUMNS`` (T, ...) and optionally ``DISCOUNT``, and
    the source's weight.
    """

    def __init__(self, tables: list[tuple[dict[str, np.ndarray], float]], device: str):
        if not tables:
            raise ConfigError("no data for the GPU: the sampler has no sources")
        discount = all(keys.DISCOUNT in t for t, _ in tables)
        frames, parts, sizes = [], [], []
        offset = 0
        for table, _ in tables:
            used, inverse = np.unique(np.concatenate([table["obs"], table["next"]]), return_inverse=True)
            frames.append(np.asarray(table["images"][used]))  # only the frames its transitions read
            t = len(table["obs"])
            parts.append(
                {
                    "obs": inverse[:t] + offset,
                    "next": inverse[t:] + offset,
                    **{k: table[k] for k in COLUMNS + ((keys.DISCOUNT,) if discount else ())},
                }
            )
            offset += len(used)
            sizes.append(t)
        self.device = device
        self.images = torch.from_numpy(np.concatenate(frames)).to(device)
        self.columns = {
            k: torch.from_numpy(np.concatenate([np.asarray(p[k]) for p in parts])).to(device) for k in parts[0]
        }
        self.columns[keys.REWARD] = self.columns[keys.REWARD].float()
        self.columns[keys.DONE] = self.columns[keys.DONE].float()
        w = torch.tensor([float(w) for _, w in tables], dtype=torch.float64)
        self.weights = (w / w.sum()).float().to(device)
        self.sizes = torch.tensor(sizes, dtype=torch.float32, device=device)
        self.starts = torch.tensor(np.r_[0, np.cumsum(sizes)[:-1]], dtype=torch.int64, device=device)

    @property
    def nbytes(self) -> int:
        return self.images.nbytes + sum(v.nbytes for v in self.columns.values())

    def sample(self, batch_size: int, generator: torch.Generator) -> dict[str, torch.Tensor]:
        """A batch of ``batch_size`` transitions (``nsl.keys``), drawn on the device with ``generator``."""
        source = torch.multinomial(self.weights, batch_size, replacement=True, generator=generator)
        u = torch.rand(batch_size, generator=generator, device=self.device)
        row = self.starts[source] + (u * self.sizes[source]).long().clamp_max_(self.sizes[source].long() - 1)
        obs, nxt = self.columns["obs"][row], self.columns["next"][row]
        batch = {k: v[row] for k, v in self.columns.items() if k not in ("obs", "next")}
        batch[keys.OBS_IMAGE] = self.images[obs]
        batch[keys.NEXT_OBS_IMAGE] = self.images[nxt]
        return batch


class GraphedStep:
    """``step(n)``: QT-Opt's gradient step ``n`` on a batch from ``data``, replayed from one CUDA graph.

    The first ``warmup`` steps run eagerly on a side stream (CUDA graphs need the allocator and cuDNN warmed);
    the next is captured and every later one replays it.  Returns the step's metrics (``qtopt.METRICS``), a
    tensor the next step overwrites: read or accumulate it before then.  On the CPU every step runs the same
    body eagerly (what the tests without a GPU check).
    """

    def __init__(self, learner: Learner, data: DeviceData, cfg: TrainConfig, warmup: int = 3):
        if cfg.lr_decay:
            raise ConfigError("a graphed step keeps the learning rate constant; use lr_decay 0")
        self.graphed = learner.generator.device.type == "cuda"
        if self.graphed and not all(g.get("capturable") for g in learner.optimizer.param_groups):
            raise ConfigError("a graphed step needs a capturable Adam (Learner.create makes one on cuda)")
        self.learner, self.data, self.cfg, self.warmup = learner, data, cfg, warmup
        self.graph: Any = None
        self.metrics: torch.Tensor | None = None
        self.stream = torch.cuda.Stream() if self.graphed else None
        self.calls = 0  # eager warm-up steps taken

    def _body(self) -> torch.Tensor:
        batch = self.data.sample(self.cfg.batch_size, self.learner.generator)
        return step_metrics(self.learner, batch, self.cfg, 0, refresh_lag=False)

    def __call__(self, step: int) -> torch.Tensor:
        if not self.graphed:
            out = self._body()
        else:
            out = self._replay()
        if (step + 1) % self.cfg.lag_period == 0:
            refresh_lagged(self.learner)
        return out

    def _replay(self) -> torch.Tensor:
        if self.graph is None:
            stream = self.stream
            assert stream is not None
            stream.wait_stream(torch.cuda.current_stream())
            if self.calls < self.warmup:
                self.calls += 1
                with torch.cuda.stream(stream):
                    out = self._body()
                torch.cuda.current_stream().wait_stream(stream)
                return out
            torch.cuda.synchronize()
            self.learner.optimizer.zero_grad(set_to_none=True)
            graph = torch.cuda.CUDAGraph()
            graph.register_generator_state(self.learner.generator)
            with torch.cuda.graph(graph, stream=stream):
                self.metrics = self._body()
            self.graph = graph
        self.graph.replay()
        assert self.metrics is not None
        return self.metrics
