"""Training runs: a run folder, checkpoints, exact resume, logs, samples, Ctrl-C, data parallel.

A run folder (``run.out_dir/run.name``) holds::

    run.json                 written first: marks the folder as a run (:mod:`.folder`; train writes
                             only into a new or empty folder or a run folder, never its --config file)
    config.yaml              the resolved config (every key, defaults included)
    checkpoints/last.pt      the newest checkpoint (atomically replaced)
    checkpoints/step_NNNNNNN.pt   the last ``keep_checkpoints`` periodic checkpoints
    scalars.csv, tb/         scalar logs (CSV and TensorBoard)
    samples/step_NNNNNNN.png renders of fixed held-out inputs from fixed views
    samples/turntable_NNNNNNN.gif
    run.lock                 held while a run writes to the folder (the pid of its process)

Checkpoints are written to a temporary file and renamed over the old one, so a kill at any
moment leaves the previous checkpoint loadable (the next run in the folder deletes the
temporaries a killed one left; ``scalars.csv`` is written before each checkpoint, so a resume
loses no row); a full disk ends the run with one line naming the file, the good checkpoints
as they were. ``resume=True`` continues from ``last.pt``;
because every random draw of a step derives from (seed, step), the continued run matches an
uninterrupted one step for step (on CPU). Ctrl-C (SIGINT) finishes the current step, saves a
checkpoint and raises :class:`~mitsuba_platonic.errors.Interrupted` saying which step it holds
(the command line: one line on stderr, exit code 130), so that ``train && evaluate`` stops.

What is saved: a checkpoint is written only on a clean stop (a periodic checkpoint, the last
step, Ctrl-C, ``stop_at``) and only if every tensor of the state is finite. An exception during
training saves nothing (the good checkpoints stay as they are; its message says which step
``last.pt`` holds), and a state with NaN or Inf ends the run with :class:`RunError`. If
``last.pt`` cannot be loaded (truncated, corrupt), ``--resume``, ``reconstruct`` and ``generate``
use the newest loadable ``step_*.pt`` and warn on stderr. Checkpoints are unpickled safely
(``weights_only=True``, :mod:`mitsuba_platonic.checkpoint`): one that would run code is an error
naming it, never a fallback; ``--resume`` refuses a checkpoint saved with other data, model,
render or train settings, naming the first key.

One run per folder: ``run.lock`` is an exclusive lock (``flock``) that the kernel releases when
its process ends, so a lock file left by a killed run is simply taken over, while a second
run in the folder of a live one is refused.

Data parallel: launch with ``torchrun --nproc-per-node N -m mitsuba_platonic.cli train ...``
(CUDA + NCCL, or CPU + gloo). Each process renders its share of the batch with the configured
renderer; rank 0 writes checkpoints, logs and samples.
"""

from __future__ import annotations

import csv
import os
import signal
import time
import warnings
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Dict, Iterator, List, Optional, Tuple

import torch
import torch.distributed as dist
import yaml

from ..checkpoint import (CHECKPOINT_VERSION, RunError, checkpoint_files, load_checkpoint, load_latest_checkpoint,
                          load_weights, read_checkpoint, save_checkpoint)
from ..config import Config, ConfigError, config_from_dict
from ..errors import Interrupted, UserError
from ..fileio import atomic_write, remove_temporaries
from ..frames import display_frames, save_gif, turntable_frames
from ..images import composite, linear_to_srgb, save_grid, to_hwc
from ..loading import checkpoint_config, config_difference, model_from_checkpoint, saved_config
from ..model import Model
from ..progress import progress_bar
from ..render.variant import ensure_variant
from ..views import front_view, turntable
from .data import load_training_data
from .fits import check_model_fits
from .folder import RUN_MARKER, claim_run_folder
from .run_settings import DEVICES  # noqa: F401  (the choice list, also named here)
from .trainer import Trainer

__all__ = ["train", "load_run", "RunError", "save_checkpoint", "load_checkpoint", "load_latest_checkpoint",
           "run_lock", "SAMPLE_VIEWS", "read_run_config", "DEVICES", "write_samples", "RUN_MARKER"]


def _device(cfg: Config, local_rank: int) -> torch.device:
    if cfg.run.device == "cuda" or (cfg.run.device == "auto" and torch.cuda.is_available()):
        if not torch.cuda.is_available():
            raise RunError("run.device: 'cuda' requested but CUDA is not available")
        return torch.device("cuda", local_rank)
    return torch.device("cpu")


def _non_finite(state: Any, name: str = "") -> Optional[str]:
    """The name of the first floating tensor of ``state`` holding NaN or Inf, else None."""
    if isinstance(state, torch.Tensor):
        return name if state.is_floating_point() and not bool(torch.isfinite(state).all()) else None
    if isinstance(state, dict):
        items = state.items()
    elif isinstance(state, (list, tuple)):
        items = enumerate(state)
    else:
        return None
    for k, v in items:
        bad = _non_finite(v, f"{name}.{k}" if name else str(k))
        if bad is not None:
            return bad
    return None


def _lock_holder(fd: int) -> str:
    try:
        text = os.pread(fd, 64, 0).decode(errors="replace").strip()
    except OSError:
        return "?"
    return text if text.isdigit() else "?"


@contextmanager
def run_lock(run_dir: Path) -> Iterator[Path]:
    """Hold ``run_dir/run.lock`` (an exclusive ``flock`` holding this process's pid) while inside.

    A lock file whose process is gone is free (the kernel dropped its lock) and is taken over; a
    live holder makes this raise :class:`RunError`. The file is removed on exit.
    """
    import fcntl  # lazy: POSIX only, where a run folder is locked

    run_dir.mkdir(parents=True, exist_ok=True)
    path = run_dir / "run.lock"
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            holder = _lock_holder(fd)
            os.close(fd)
            raise RunError(f"{run_dir} is in use by another training run (pid {holder}, lock {path}); "
                           f"wait for it to end or choose another run.name") from None
        try:
            same = os.path.samestat(os.fstat(fd), os.stat(path))
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)                                 # its holder removed it as we opened it: again
    try:
        try:
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        except OSError as e:                         # a full disk: say where
            raise OSError(e.errno, e.strerror, str(path)) from None
        yield path
    finally:
        try:
            os.unlink(path)                          # while still holding it: no one can hold a stale copy
        finally:
            os.close(fd)


#: Fixed views of the periodic samples: the input view and three turntable views.
SAMPLE_VIEWS = torch.cat([front_view(1), turntable(3, elevation=25.0, start=60.0)])


def write_samples(model: Model, inputs: torch.Tensor, folder: Path, step: int, seed: int) -> Tuple[Path, Path]:
    """PNG grid (input | reconstruction from the sample views; for generation, samples of a
    generator seeded with ``seed``) and a turntable GIF of the first volume."""
    if model.task == "reconstruction":
        vols = model.reconstruct(inputs).cpu()
        first = [[linear_to_srgb(composite(to_hwc(x), background=1.0))] for x in inputs]
    else:
        vols = model.generate(len(inputs), seed).cpu()
        first = [[] for _ in vols]
    rows = [first[i] + display_frames(vol, model.formation, SAMPLE_VIEWS, filter=model.render.filter)
            for i, vol in enumerate(vols)]
    scale = max(1, 256 // model.resolution)
    png = save_grid(folder / f"step_{step:07d}.png", rows, scale=scale)
    gif = save_gif(turntable_frames(vols[0], model.formation, frames=24), folder / f"turntable_{step:07d}.gif",
                   scale=scale, duration_ms=80)
    return png, gif


class _ScalarLog:
    """scalars.csv (rows after a resumed step are dropped) and TensorBoard."""

    def __init__(self, folder: Path, start_step: int):
        self.path = folder / "scalars.csv"
        self.rows: List[Dict[str, Any]] = []
        if self.path.exists():
            with open(self.path) as f:
                self.rows = [r for r in csv.DictReader(f) if int(r["step"]) <= start_step]
        try:
            from torch.utils.tensorboard import SummaryWriter  # lazy: TensorBoard is slow to import, and may be broken
            self.tb = SummaryWriter(str(folder / "tb"), purge_step=start_step + 1)
        except ImportError:  # tensorboard is a dependency; keep training if it is broken
            self.tb = None

    def add(self, step: int, scalars: Dict[str, float]) -> None:
        self.rows.append({"step": step, **{k: f"{v:.6g}" for k, v in scalars.items()}})
        if self.tb is not None:
            for k, v in scalars.items():
                self.tb.add_scalar(k, v, step)

    def flush(self) -> None:
        keys: List[str] = []
        for r in self.rows:
            keys += [k for k in r if k not in keys]

        def write(tmp: Path) -> None:
            with open(tmp, "w", newline="") as f:
                w = csv.DictWriter(f, fieldnames=keys)
                w.writeheader()
                w.writerows(self.rows)

        atomic_write(self.path, write)
        if self.tb is not None:
            self.tb.flush()

    def close(self) -> None:
        self.flush()
        if self.tb is not None:
            self.tb.close()


def _distributed() -> Tuple[int, int, int]:
    """(rank, world size, local rank), initialising torch.distributed under torchrun."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world <= 1:
        return 0, 1, 0
    if not dist.is_initialized():
        dist.init_process_group("nccl" if torch.cuda.is_available() else "gloo")
    return dist.get_rank(), dist.get_world_size(), int(os.environ.get("LOCAL_RANK", "0"))


def train(cfg: Config, resume: bool = False, progress: bool = True,
          stop_at: Optional[int] = None, config_file: Optional[Path] = None) -> Path:
    """Run (or continue) training; return the run folder.

    The run folder (``run.out_dir/run.name``) must be new, empty or a run folder
    (:func:`~mitsuba_platonic.train.folder.claim_run_folder`); any other folder is refused with
    nothing in it changed. ``config_file``: the file ``cfg`` was read from (``--config``), which is
    never written, also where it is the run's own ``config.yaml``. ``stop_at`` ends the loop after
    that step as if finished (a checkpoint is saved): used to test exact resume. Ctrl-C finishes
    the current step, saves a checkpoint and raises :class:`~mitsuba_platonic.errors.Interrupted`.
    """
    rank, world, local_rank = _distributed()
    check_model_fits(cfg, _device(cfg, local_rank))         # before any data or run folder is written
    run_dir = Path(cfg.run.out_dir) / cfg.run.name
    with training_threads(cfg):
        if rank != 0:
            return _train(cfg, run_dir, resume, progress, stop_at, rank, world, local_rank, config_file)
        claim_run_folder(run_dir)                            # before the lock: a user's folder stays untouched
        with run_lock(run_dir):                              # one run at a time in a run folder
            return _train(cfg, run_dir, resume, progress, stop_at, rank, world, local_rank, config_file)


#: 'auto' runs the marcher's launches on the training thread up to this resolution (docs/training.md, "Threads").
SERIAL_MARCHER_MAX_RESOLUTION = 32


def drjit_threads(cfg: Config) -> Optional[int]:
    """Dr.Jit's worker threads for a training run, or None to leave them as they are.

    ``run.drjit_threads`` if it is a count. 'auto': 1 (each launch runs on the training thread)
    when the marcher trains at N ≤ :data:`SERIAL_MARCHER_MAX_RESOLUTION` on the LLVM backend,
    because Dr.Jit's idle workers keep spinning for 20 ms after every launch and take the cores
    from torch's convolutions, while a 32³ launch only takes a few ms (measured in
    docs/training.md, "Threads"; at 64³ the workers pay for themselves); otherwise
    ``run.threads`` (all cores when 0). The closed form uses no Dr.Jit.
    """
    if cfg.render.backend == "closed_form":
        return None
    if cfg.run.drjit_threads != "auto":
        return int(cfg.run.drjit_threads)
    if (cfg.render.backend == "mitsuba" and ensure_variant().variant().startswith("llvm")
            and cfg.model.resolution <= SERIAL_MARCHER_MAX_RESOLUTION):
        return 1
    return cfg.run.threads or None


@contextmanager
def training_threads(cfg: Config) -> Iterator[None]:
    """torch's threads (``run.threads``) and Dr.Jit's (:func:`drjit_threads`) while a run trains,
    restored afterwards (a quickstart evaluates in the same process, with every core)."""
    torch_before = torch.get_num_threads()
    if cfg.run.threads:
        torch.set_num_threads(cfg.run.threads)
    n, dr, before = drjit_threads(cfg), None, None
    if n is not None:
        import drjit as dr  # lazy: Dr.Jit only where a run renders with Mitsuba
        before = dr.thread_count()
        if n != before:
            dr.set_thread_count(n)
    try:
        yield
    finally:
        torch.set_num_threads(torch_before)
        if dr is not None and dr.thread_count() != before:
            dr.set_thread_count(before)


#: The render settings only the Mitsuba marcher reads.
_MARCHER_SETTINGS = ("step", "spp", "jitter", "termination")


def _warn_ignored_settings(cfg: Config) -> None:
    """Warn (naming the keys) where the config sets what the run ignores: marcher settings with
    ``render.backend`` 'closed_form', an elevation with view distribution 'sphere'."""
    for section in ("data", "train"):
        part = getattr(cfg, section)
        if part.view_distribution == "sphere" and part.elevation is not None:
            warnings.warn(f"{section}.elevation: {section}.view_distribution 'sphere' covers every elevation and "
                          f"ignores it; set it to null, or use 'band' or 'ring'", stacklevel=2)
    if cfg.render.backend != "closed_form":
        return
    defaults = type(cfg.render)()
    ignored = [f"render.{k}" for k in _MARCHER_SETTINGS if getattr(cfg.render, k) != getattr(defaults, k)]
    if ignored:
        warnings.warn(f"{', '.join(ignored)}: only the Mitsuba marcher (render.backend: mitsuba) reads "
                      f"{'these' if len(ignored) > 1 else 'this'}; render.backend 'closed_form' ignores "
                      f"{'them' if len(ignored) > 1 else 'it'}", stacklevel=2)


def _same_file(a: Optional[Path], b: Path) -> bool:
    try:
        return a is not None and os.path.samefile(a, b)
    except OSError:
        return False


def _train(cfg: Config, run_dir: Path, resume: bool, progress: bool, stop_at: Optional[int],
           rank: int, world: int, local_rank: int, config_file: Optional[Path] = None) -> Path:

    device = _device(cfg, local_rank)
    last = run_dir / "checkpoints" / "last.pt"
    if rank == 0:
        _warn_ignored_settings(cfg)
        existing = checkpoint_files(last.parent)
        if resume and not existing:
            raise RunError(f"--resume: {run_dir} has no checkpoint to continue from")
        if not resume and existing:
            raise RunError(f"{run_dir} already holds a run; pass --resume to continue it, or choose "
                           f"another run.name")
        run_dir.mkdir(parents=True, exist_ok=True)
        for folder in (run_dir, last.parent):                # what a killed run was writing (we hold the lock)
            remove_temporaries(folder)
        if resume:
            try:
                saved = read_run_config(run_dir / "config.yaml")
            except RunError as e:
                raise RunError(f"--resume: {e}") from None
            diff = config_difference(saved, cfg, there="there")
            if diff is not None:
                raise RunError(f"--resume: the {diff.split('.')[0]} settings differ from {run_dir}/config.yaml "
                               f"({diff}); an exact continuation needs the same config (only run.* may change)")
        if not _same_file(config_file, run_dir / "config.yaml"):   # --config is the user's: never written
            text = yaml.safe_dump(cfg.to_dict(), sort_keys=False)
            atomic_write(run_dir / "config.yaml", lambda p: p.write_text(text))   # never torn: --resume reads it
    if world > 1:
        dist.barrier()                                       # rank 0 checked the folder first
    if rank == 0:
        try:
            data = load_training_data(cfg, progress=progress)
        except KeyboardInterrupt as e:                       # Ctrl-C before the first step: say what is kept
            what = getattr(e, "saved", None) or "nothing of it is cached"
            done = f"{last.parent} is as it was" if resume else "no checkpoint was written"
            raise Interrupted(f"while preparing the training data: {what}; no training step ran and {done}; "
                              f"run the same command again to continue") from e
    if world > 1:
        dist.barrier()                                       # the procedural cache is complete
    if rank != 0:
        data = load_training_data(cfg, progress=False)
    trainer = Trainer(cfg, data, device, rank, world)
    start = 0
    saved: Dict[str, Any] = {"path": None, "step": None}     # the newest good checkpoint on disk
    if resume:
        try:
            state, path = load_latest_checkpoint(last.parent, device, warn=rank == 0)
            _same_settings(state, path, cfg)
            load_weights(trainer, state["trainer"], path, "this run's networks and optimisers")
        except RunError as e:
            raise RunError(f"--resume: {e}") from None
        start = int(state["step"])
        saved.update(path=path, step=start)
    pool = data.held_out if len(data.held_out) else data.images
    sample_inputs = pool[torch.linspace(0, len(pool) - 1, min(4, len(pool))).long()]   # spread: different shapes
    samples_seed = cfg.run.seed + 12345                      # generation runs: the same z at every sample

    def kept() -> str:
        if saved["path"] is None:
            return "nothing was saved (no checkpoint had been written yet)"
        return f"nothing was saved: {saved['path']} still holds step {saved['step']}"

    def checkpoint(step: int) -> None:
        if rank != 0:
            return
        state = trainer.state_dict()
        bad = _non_finite(state)
        if bad is not None:                                  # never over (or rotating out) a good one
            raise RunError(f"step {step}: the training state is not finite (NaN or Inf in {bad}); {kept()}")
        payload = {"version": CHECKPOINT_VERSION, "step": step, "config": cfg.to_dict(), "trainer": state}
        numbered = run_dir / "checkpoints" / f"step_{step:07d}.pt"
        try:
            save_checkpoint(last, payload)
            saved.update(path=last, step=step)
            save_checkpoint(numbered, payload)
        except OSError as e:                                 # a full disk: the old files are whole (atomic)
            held = f"{saved['path']} holds step {step}" if saved["step"] == step else kept()
            raise RunError(f"step {step}: the checkpoint could not be written ({e}); {held}") from None
        for old in sorted((run_dir / "checkpoints").glob("step_*.pt"))[:-cfg.run.keep_checkpoints]:
            old.unlink()

    stop = {"now": False}
    previous = None
    if rank == 0 and hasattr(signal, "SIGINT"):
        previous = signal.signal(signal.SIGINT, lambda *_: stop.update(now=True))
    log = _ScalarLog(run_dir, start) if rank == 0 else None
    end = cfg.run.steps if stop_at is None else min(stop_at, cfg.run.steps)
    bar = progress_bar(cfg.run.steps, initial=start, disable=not progress or rank != 0, unit="step", desc="train")
    images_per_step = cfg.train.batch_size * (cfg.train.random_views + (cfg.train.task == "reconstruction"))
    step, t_last, n_last = start, time.perf_counter(), start
    clean, interrupted, where = False, False, f"in step {start + 1}"
    try:
        while step < end:
            where = f"in step {step + 1}"
            scalars = trainer.step(step)
            step += 1
            where = f"after step {step}"
            if rank == 0 and (step % cfg.run.log_every == 0 or step == end):
                rate = (step - n_last) * images_per_step / max(time.perf_counter() - t_last, 1e-9)
                t_last, n_last = time.perf_counter(), step
                log.add(step, {**scalars, "images_per_s": rate})
                bar.set_postfix({k: f"{v:.3g}" for k, v in scalars.items()
                                 if not k.endswith(("_updated", "_hard"))}
                                | {"img/s": f"{rate:.1f}"})
            bar.update(1)
            if rank == 0 and step % cfg.run.sample_every == 0:
                write_samples(trainer.inference_model, sample_inputs, run_dir / "samples", step, samples_seed)
            if step % cfg.run.checkpoint_every == 0:
                if log:                                      # first: the rows after a checkpoint are dropped on
                    log.flush()                              # resume, rows missing before it would stay lost
                checkpoint(step)
            flag = torch.tensor(float(stop["now"]))
            if world > 1:
                dist.all_reduce(flag)                       # stop together
            if flag.item() > 0:
                interrupted = True
                break
        clean = True
    except BaseException as e:                               # a failing step: save nothing, say so
        if rank == 0 and not isinstance(e, RunError):
            if isinstance(e, (UserError, OSError)):          # the user's input, a full disk: one line
                raise RunError(f"training failed {where}: {e}; {kept()}") from e
            bad = _non_finite(trainer.state_dict()) if isinstance(e, ValueError) else None
            if bad is not None:                              # a diverged run (NaN or Inf in the weights), not a bug
                raise RunError(f"training failed {where}: {e} (the training state is not finite: NaN or Inf in "
                               f"{bad}; lower the learning rates); {kept()}") from e
            e.add_note(f"training failed {where}; {kept()}")   # a bug: it keeps its traceback
        raise
    finally:
        bar.close()
        if rank == 0:
            try:
                if clean:                                    # finished, stop_at or Ctrl-C between steps
                    log.flush()
                    checkpoint(step)
                    if step == cfg.run.steps:
                        write_samples(trainer.inference_model, sample_inputs, run_dir / "samples", step, samples_seed)
            except OSError as e:                             # the final samples on a full disk
                clean = False
                raise RunError(f"after step {step}: {e}; {saved['path']} holds step {saved['step']}") from None
            except BaseException:
                clean = False
                raise
            finally:
                try:
                    log.close()
                except OSError:
                    if clean:                                # else the error on its way says more
                        raise
                if previous is not None:
                    signal.signal(signal.SIGINT, previous)
        if world > 1:
            if clean:
                dist.barrier()                               # rank 0 has written the last checkpoint
            dist.destroy_process_group()
    if interrupted and step < cfg.run.steps:                 # saved: now say so, and that it did not finish
        held = f"{saved['path']} holds step {saved['step']}" if rank == 0 else "rank 0 saved the checkpoint"
        raise Interrupted(f"after step {step} of {cfg.run.steps}: {held}; continue with the same command and "
                          f"--resume", saved=held)
    return run_dir


def _same_settings(state: Dict[str, Any], path: Path, cfg: Config) -> None:
    """:class:`RunError` naming the checkpoint and the first key unless the config saved in it has
    the same data, model, render and train settings as ``cfg`` (config.yaml may have been edited,
    or the checkpoint come from another run: its weights would not fit, or not continue exactly)."""
    diff = config_difference(saved_config(state, path, run_name=cfg.run.name), cfg, there=f"in {path.name}")
    if diff is not None:
        raise RunError(f"{path} was saved with other settings ({diff}); an exact continuation needs the "
                       f"config it was trained with (only run.* may change)")


def read_run_config(path: Path) -> Config:
    """The resolved config a run wrote (``RUN/config.yaml``), validated; :class:`RunError` naming
    ``path`` if it is missing, not valid YAML, not a mapping, or has a bad key or value."""
    expected = "expected the run's resolved config as `platonic train` wrote it"
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise RunError(f"{path} is missing; {expected}") from None
    except OSError as e:
        raise RunError(f"{path} cannot be read: {e}") from None
    except UnicodeDecodeError:
        raise RunError(f"{path} is not a text file (not UTF-8); {expected}") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        problem = getattr(e, "problem", None) or type(e).__name__
        raise RunError(f"{path} is not valid YAML ({problem}{where}); {expected}") from None
    if not isinstance(data, dict):
        got = "an empty file" if data is None else f"a {type(data).__name__}"
        raise RunError(f"{path}: expected a mapping of sections (run, data, model, render, train), got {got}; "
                       f"{expected}")
    try:
        return config_from_dict(data)
    except ConfigError as e:
        raise RunError(f"{path}: {e}; {expected}") from None


def load_run(run_dir: Path, device: str = "cpu") -> Tuple[Config, Model, int]:
    """A trained run's config, :class:`~mitsuba_platonic.model.Model` and step (no training data
    is loaded): :func:`~mitsuba_platonic.checkpoint.read_checkpoint` of the run folder."""
    ckpt = read_checkpoint(Path(run_dir), device)
    cfg = checkpoint_config(ckpt)
    return cfg, model_from_checkpoint(Model, ckpt, cfg), ckpt.step
