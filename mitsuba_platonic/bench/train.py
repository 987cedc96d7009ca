"""Training speed per renderer: images per second of a few trainer steps of one small
reconstruction configuration (closed form, the marcher, the path tracer)."""

from __future__ import annotations

import time
from typing import Any, Callable, Dict, List

import torch

from ..config import load_config
from ..train.data import TrainingData
from ..train.run import training_threads
from ..train.trainer import Trainer


def _bench_train(r: int, width: int, batch: int, steps: int, warmup: int,
                 log: Callable[[str], None]) -> List[Dict[str, Any]]:
    """Training images/s per renderer (reconstruction, EA, one random view per volume)."""
    import drjit as dr               # Dr.Jit only when the bench runs (its variant is set by then)

    g = torch.Generator().manual_seed(0)
    data = TrainingData(torch.rand(64, 4, r, r, generator=g) * 0.5, torch.zeros(0, 4, r, r))
    renderers = [("closed_form", "closed form", []), ("mitsuba", "marcher default", []),
                 ("physical", "path tracer spp 1, depth 2", ["render.physical_spp=1", "render.max_depth=2"])]
    rows: List[Dict[str, Any]] = []
    base = None
    for backend, label, extra in renderers:
        row: Dict[str, Any] = {"renderer": backend, "config": label, "overrides": extra, "resolution": r,
                               "width": width, "batch": batch, "steps": steps, "warmup_steps": warmup,
                               "skipped": None}
        try:
            cfg = load_config(None, [f"model.resolution={r}", f"model.width={width}", f"train.batch_size={batch}",
                                     f"render.backend={backend}", "render.model=ea", "data.formation=ea", *extra])
            trainer = Trainer(cfg, data, torch.device("cpu"))
            with training_threads(cfg):                       # as a training run sets them (run.drjit_threads)
                row["drjit_threads"] = None if backend == "closed_form" else dr.thread_count()
                for step in range(warmup):
                    trainer.step(step)
                t0 = time.perf_counter()
                for step in range(warmup, warmup + steps):
                    trainer.step(step)
                per_step = (time.perf_counter() - t0) / steps
        except (ValueError, RuntimeError, TypeError, KeyError) as e:
            row["skipped"] = f"{type(e).__name__}: {e}"
            log(f"train {label}: skipped ({row['skipped']})")
            rows.append(row)
            continue
        rate = batch * 2 / per_step                            # the random view and the input view
        base = base or rate
        row.update({"s_per_step": per_step, "images_per_s": rate, "vs_closed_form": rate / base})
        rows.append(row)
        log(f"train {label}: {per_step:.3f} s/step, {rate:.1f} images/s")
    return rows
