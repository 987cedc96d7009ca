"""Training speed per renderer and resolution: seconds per step of the quickstart's training
(``configs/quickstart.yaml``: reconstruction, EA, He-initialised E and G, a critic of width 32
with R1, the pose head, the moving average), and where a step's time goes.

A step's wall time t splits into three measured parts (:class:`StepClock`):

- **renderer**: every call of the trainer's rendering layer, forward (the call itself; its
  output is a torch tensor, so the Dr.Jit launches have run when it returns) and backward (from
  the moment autograd hands the render its output's gradient to the moment the render hands
  back the volume's: two identity nodes around the render mark them, and autograd's engine
  runs the nodes between them, which are the render's own, without interleaving others);
- **optimiser**: every ``Optimizer.step`` (Adam on E, G, the pose head and D);
- **networks**: the rest, t − renderer − optimiser: E, G and D forward and backward, the
  losses, the R1 penalty, the moving average.

Shares are over the timed steps' total. The data are random images (the speed of a step does
not depend on what the photos show).
"""

from __future__ import annotations

import time
from typing import Any, Callable, Dict, List, Sequence

import torch

from ..config import load_config
from ..files.resources import config_path
from ..train.data import TrainingData
from ..train.run import training_threads
from ..train.trainer import Trainer

__all__ = ["StepClock", "RENDERERS", "bench_train"]

#: The renderers a training row is measured for: (backend, label, extra overrides).
RENDERERS = [("closed_form", "closed form", []), ("mitsuba", "marcher", []),
             ("scatter_march", "single scattering, Dr.Jit (m 2)", ["render.steps_per_voxel=2"]),
             ("physical", "path tracer spp 1, depth 2", ["render.physical_spp=1", "render.max_depth=2"])]


class _Mark(torch.autograd.Function):
    """Identity whose backward writes the time it runs into ``clock[key]`` (a list)."""

    @staticmethod
    def forward(ctx, x: torch.Tensor, clock: Dict[str, List[float]], key: str) -> torch.Tensor:
        ctx.clock, ctx.key = clock, key
        return x.view_as(x)

    @staticmethod
    def backward(ctx, grad: torch.Tensor):
        ctx.clock[ctx.key].append(time.perf_counter())
        return grad, None, None


class StepClock:
    """Times a :class:`~mitsuba_platonic.train.trainer.Trainer`'s renderer (forward and backward)
    and optimiser steps while it is attached (module docstring); ``totals()`` gives the seconds
    spent in each since the last ``reset()``."""

    def __init__(self, trainer: Trainer):
        self.trainer = trainer
        self._render = trainer.render
        self._steps = {}
        self.reset()
        trainer.render = self._timed_render
        for opt in (trainer.opt_g, trainer.opt_d, trainer.opt_d3):
            if opt is not None:
                self._steps[opt] = opt.step
                opt.step = self._timed_step(opt.step)

    def reset(self) -> None:
        self.forward = 0.0
        self.optimiser = 0.0
        self._marks: Dict[str, List[float]] = {"start": [], "end": []}

    def _timed_render(self, volume: torch.Tensor, views: torch.Tensor, seed: int) -> torch.Tensor:
        if volume.requires_grad:
            volume = _Mark.apply(volume, self._marks, "end")       # its backward runs after the render's
        t0 = time.perf_counter()
        image = self._render(volume, views, seed)
        self.forward += time.perf_counter() - t0
        if image.requires_grad:
            image = _Mark.apply(image, self._marks, "start")       # its backward runs before the render's
        return image

    def _timed_step(self, step: Callable) -> Callable:
        def timed(*args, **kwargs):
            t0 = time.perf_counter()
            out = step(*args, **kwargs)
            self.optimiser += time.perf_counter() - t0
            return out
        return timed

    def totals(self) -> Dict[str, float]:
        """Seconds in the renderer's forward and backward and in the optimisers' steps. A render
        whose image got no gradient (D's update sees a detached image) has a start and no end; each
        end pairs with the latest start before it."""
        backward, starts = 0.0, sorted(self._marks["start"])
        for end in sorted(self._marks["end"]):
            before = [s for s in starts if s <= end]
            if before:
                backward += end - before[-1]
                starts.remove(before[-1])
        return {"renderer_forward": self.forward, "renderer_backward": backward, "optimiser": self.optimiser}

    def detach(self) -> None:
        """Give the trainer back its own renderer and optimiser steps."""
        self.trainer.render = self._render
        for opt, step in self._steps.items():
            opt.step = step


#: The path tracer trains at most at this resolution here (a 64³ step takes most of a minute on 2 cores).
PHYSICAL_MAX_RESOLUTION = 32


def bench_train(resolutions: Sequence[int], width: int, batch: int, steps: int, warmup: int,
                 log: Callable[[str], None], physical: bool = True) -> List[Dict[str, Any]]:
    """Per resolution and renderer (:data:`RENDERERS`; the path tracer only with ``physical`` and
    up to :data:`PHYSICAL_MAX_RESOLUTION`): seconds per quickstart training step and the shares of
    renderer, networks and optimiser (module docstring)."""
    import drjit as dr               # lazy: Dr.Jit only when the bench runs (its variant is set by then)

    rows: List[Dict[str, Any]] = []
    for r in resolutions:
        g = torch.Generator().manual_seed(0)
        data = TrainingData(torch.rand(64, 4, r, r, generator=g) * 0.5, torch.zeros(0, 4, r, r))
        base = None
        for backend, label, extra in RENDERERS:
            row: Dict[str, Any] = {"renderer": backend, "config": label, "overrides": extra, "resolution": r,
                                   "width": width, "batch": batch, "steps": steps, "warmup_steps": warmup,
                                   "skipped": None}
            if backend == "physical" and (not physical or r > PHYSICAL_MAX_RESOLUTION):
                row["skipped"] = ("no path tracer (--no-physical)" if not physical else
                                  f"the path tracer trains here up to {PHYSICAL_MAX_RESOLUTION}³")
                rows.append(row)
                continue
            try:
                cfg = load_config(config_path("quickstart"),
                                  [f"model.resolution={r}", f"model.width={width}", f"train.batch_size={batch}",
                                   f"render.backend={backend}", *extra])
                trainer = Trainer(cfg, data, torch.device("cpu"))
                with training_threads(cfg):                   # as a training run sets them (run.drjit_threads)
                    row["drjit_threads"] = None if backend == "closed_form" else dr.thread_count()
                    for step in range(warmup):
                        trainer.step(step)
                    clock = StepClock(trainer)
                    t0 = time.perf_counter()
                    for step in range(warmup, warmup + steps):
                        trainer.step(step)
                    total = time.perf_counter() - t0
                    parts = clock.totals()
                    clock.detach()
            except (ValueError, RuntimeError, TypeError, KeyError) as e:
                row["skipped"] = f"{type(e).__name__}: {e}"
                log(f"train {label} {r}³: skipped ({row['skipped']})")
                rows.append(row)
                continue
            per_step = total / steps
            rate = batch * 2 / per_step                        # the random view and the input view
            base = base or rate
            renderer = parts["renderer_forward"] + parts["renderer_backward"]
            row.update({"s_per_step": per_step, "images_per_s": rate, "vs_closed_form": rate / base,
                        "renderer_share": renderer / total, "renderer_backward_share": parts["renderer_backward"] / total,
                        "optimiser_share": parts["optimiser"] / total,
                        "networks_share": max(0.0, total - renderer - parts["optimiser"]) / total})
            rows.append(row)
            log(f"train {label} {r}³: {per_step:.3f} s/step, {rate:.1f} images/s; renderer "
                f"{row['renderer_share']:.0%}, networks {row['networks_share']:.0%}, optimiser {row['optimiser_share']:.0%}")
    return rows
