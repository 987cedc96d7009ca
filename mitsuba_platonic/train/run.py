"""Training runs: :func:`train` runs (or continues) Algorithm 1 in a run folder, step by step,
with logs, samples, checkpoints, exact resume, Ctrl-C and data parallel; :func:`load_run` reads a
trained run back.

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

The loop is this module's; the rest of a run lives beside it, its public names re-exported here:
:mod:`.folder` (what a run folder is, its lock, its ``config.yaml``), :mod:`.checkpoints` (which
checkpoints are kept, resume), :mod:`.logs` (scalars and samples) and :mod:`.compute` (device,
data-parallel processes, threads).

Checkpoints are written to a temporary file and renamed over the old one, so a kill at any
moment leaves the previous checkpoint loadable (the next run in the folder deletes the
temporaries a killed one left; ``scalars.csv`` is written before each checkpoint, so a resume
loses no row); a full disk ends the run with one line naming the file, the good checkpoints
as they were. ``resume=True`` continues from ``last.pt``;
because every random draw of a step derives from (seed, step), the continued run matches an
uninterrupted one step for step (on CPU). Ctrl-C (SIGINT), SIGTERM (``kill``, ``timeout``,
Slurm, systemd) and SIGHUP (a closed terminal or SSH session; not under ``nohup``) finish the current step, save a checkpoint and raise
:class:`~mitsuba_platonic.errors.Interrupted` saying which step it holds (the command line: one
line on stderr, then the process ends by the signal: exit status 130, 143 or 129), so that
``train && evaluate``, and ``train; evaluate`` in a script, stop.

What is saved: a checkpoint is written only on a clean stop (a periodic checkpoint, the last
step, Ctrl-C, ``stop_at``) and only if every tensor of the state is finite. An exception during
training saves nothing (the good checkpoints stay as they are; its message says which step
``last.pt`` holds), and a state with NaN or Inf ends the run with :class:`RunError`. If
``last.pt`` cannot be loaded (truncated, corrupt), ``--resume``, ``reconstruct`` and ``generate``
use the newest loadable ``step_*.pt`` and warn on stderr. Checkpoints are unpickled safely
(``weights_only=True``, :mod:`mitsuba_platonic.files.checkpoint`): one that would run code is an error
naming it, never a fallback; ``--resume`` refuses a checkpoint saved with other data, model,
render or train settings, naming the first key.

Data parallel: launch with ``torchrun --nproc-per-node N -m mitsuba_platonic.cli train ...``
(CUDA + NCCL, or CPU + gloo). Each process renders its share of the batch with the configured
renderer; rank 0 writes checkpoints, logs and samples.
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path
from typing import Callable, Dict, Optional, Tuple

import torch
import torch.distributed as dist

from ..config import Config
from ..config.loading import checkpoint_config, model_from_checkpoint
from ..config.run_settings import DEVICES  # noqa: F401  (the choice list, also named here)
from ..errors import Interrupted, StopBetweenSteps, UserError
from ..files.checkpoint import RunError, load_checkpoint, load_latest_checkpoint, read_checkpoint, save_checkpoint
from ..files.fileio import confined
from ..model import Model
from ..runtime.progress import progress_bar
from .data import TrainingData, load_training_data
from .memory_fit import check_model_fits
from .folder import RUN_MARKER, RUN_PARTS, claim_run_folder, prepare_run_folder, read_run_config, run_lock
from .checkpoints import Checkpoints, non_finite
from .logs import SAMPLE_VIEWS, ScalarLog, write_samples
from .compute import SERIAL_MARCHER_MAX_RESOLUTION, distributed, drjit_threads, run_device, training_threads
from .trainer import Trainer

__all__ = ["train", "load_run", "RunError", "save_checkpoint", "load_checkpoint", "load_latest_checkpoint",
           "run_lock", "SAMPLE_VIEWS", "read_run_config", "DEVICES", "write_samples", "RUN_MARKER",
           "drjit_threads", "training_threads", "SERIAL_MARCHER_MAX_RESOLUTION"]


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
    rank, world, local_rank = distributed()
    check_model_fits(cfg, run_device(cfg, local_rank))      # before any data or run folder is written
    run_dir = Path(cfg.run.out_dir) / cfg.run.name
    with training_threads(cfg), confined(run_dir, RUN_PARTS):   # no write through a link the folder holds
        if rank != 0:
            return _train(cfg, run_dir, resume, progress, stop_at, rank, world, local_rank, config_file)
        claim_run_folder(run_dir)                            # before the lock: a user's folder stays untouched
        with run_lock(run_dir):                              # one run at a time in a run folder
            return _train(cfg, run_dir, resume, progress, stop_at, rank, world, local_rank, config_file)


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


def _warn_batch_beyond_images(cfg: Config, n_images: int) -> None:
    """Warn (naming the counts) where ``train.batch_size`` exceeds the ``n_images`` training images:
    a step draws its batch with replacement, so the batch repeats images (each with its own views)."""
    batch = cfg.train.batch_size
    if batch > n_images:
        warnings.warn(f"train.batch_size: {batch} is more than the {n_images} training image"
                      f"{'s' if n_images != 1 else ''}; a step draws its batch with replacement, so each image "
                      f"comes about {batch / n_images:.3g} times in every batch (under other random views), at the cost of "
                      f"{batch / n_images:.3g} batches of {n_images}; expected at most {n_images} (or add images)",
                      stacklevel=3)


def _train(cfg: Config, run_dir: Path, resume: bool, progress: bool, stop_at: Optional[int],
           rank: int, world: int, local_rank: int, config_file: Optional[Path] = None) -> Path:

    device = run_device(cfg, local_rank)
    if rank == 0:
        _warn_ignored_settings(cfg)
        prepare_run_folder(run_dir, cfg, resume, config_file)
    if world > 1:
        dist.barrier()                                       # rank 0 checked the folder first
    data = _training_data(cfg, run_dir, resume, progress, rank, world)
    if rank == 0:
        _warn_batch_beyond_images(cfg, len(data.images))
    trainer = Trainer(cfg, data, device, rank, world)
    checkpoints = Checkpoints(run_dir, cfg)                  # and the newest good one on disk
    start = checkpoints.resume(trainer, device, warn=rank == 0) if resume else 0
    pool = data.held_out if len(data.held_out) else data.images
    sample_inputs = pool[torch.linspace(0, len(pool) - 1, min(4, len(pool))).long()]   # spread: different shapes
    samples_seed = cfg.run.seed + 12345                      # generation runs: the same z at every sample

    def samples(at: int) -> None:
        write_samples(trainer.inference_model, sample_inputs, run_dir / "samples", at, samples_seed)

    stop = StopBetweenSteps()                                # Ctrl-C, SIGTERM, SIGHUP: stop after this step, save
    log = ScalarLog(run_dir, start) if rank == 0 else None
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
                _log_step(log, bar, step, scalars, rate)
            bar.update(1)
            if rank == 0 and step % cfg.run.sample_every == 0:
                samples(step)
            if rank == 0 and step % cfg.run.checkpoint_every == 0:
                log.flush()                                  # first: the rows after a checkpoint are dropped on
                checkpoints.save(step, trainer.state_dict())  # resume, rows missing before it would stay lost
            if _stop_together(stop, world):
                interrupted = True
                break
        clean = True
    except BaseException as e:                               # a failing step: save nothing, say so
        if rank == 0:
            _say_what_failed(e, where, trainer, checkpoints)
        raise
    finally:
        _close_loop(cfg, clean, step, rank, world, trainer, checkpoints, log, stop, bar, samples)
    if interrupted and step < cfg.run.steps:                 # saved: now say so, and that it did not finish
        held = checkpoints.held() if rank == 0 else "rank 0 saved the checkpoint"
        raise Interrupted(f"after step {step} of {cfg.run.steps}: {held}; continue with the same command and "
                          f"--resume", saved=held)
    return run_dir


def _log_step(log: ScalarLog, bar, step: int, scalars: Dict[str, float], rate: float) -> None:
    """A logged step's row (its scalars and ``images_per_s``) and the progress bar's figures."""
    log.add(step, {**scalars, "images_per_s": rate})
    bar.set_postfix({k: f"{v:.3g}" for k, v in scalars.items()
                     if not k.endswith(("_updated", "_hard"))}
                    | {"img/s": f"{rate:.1f}"})


def _stop_together(stop: StopBetweenSteps, world: int) -> bool:
    """Whether a stop signal (Ctrl-C, SIGTERM, SIGHUP) came during this step, on any process (so all stop together)."""
    flag = torch.tensor(float(stop.signal is not None))
    if world > 1:
        dist.all_reduce(flag)                               # stop together
    return flag.item() > 0


def _close_loop(cfg: Config, clean: bool, step: int, rank: int, world: int, trainer: Trainer,
                checkpoints: Checkpoints, log: Optional[ScalarLog], stop: StopBetweenSteps, bar,
                samples: Callable[[int], None]) -> None:
    """The end of the loop, however it ended: after a ``clean`` stop (finished, stop_at or Ctrl-C
    between steps) rank 0 saves the log, the checkpoint and, at the last step, the samples; the
    signal handlers are restored and the process group closed."""
    bar.close()
    if rank == 0:
        try:
            if clean:                                        # finished, stop_at or Ctrl-C between steps
                log.flush()
                checkpoints.save(step, trainer.state_dict())
                if step == cfg.run.steps:
                    samples(step)
        except OSError as e:                                 # the final samples on a full disk
            clean = False
            raise RunError(f"after step {step}: {e}; {checkpoints.held()}{checkpoints.no_room(e)}") from None
        except BaseException:
            clean = False
            raise
        finally:
            try:
                log.close()
            except OSError:
                if clean:                                    # else the error on its way says more
                    raise
            stop.restore()
    else:
        stop.restore()
    if world > 1:
        if clean:
            dist.barrier()                                   # rank 0 has written the last checkpoint
        dist.destroy_process_group()


def _training_data(cfg: Config, run_dir: Path, resume: bool, progress: bool, rank: int, world: int) -> TrainingData:
    """The run's training data: rank 0 loads it (rendering a procedural collection on first use)
    while the other processes wait, then they read what it cached. Ctrl-C meanwhile is
    :class:`~mitsuba_platonic.errors.Interrupted`, saying what of the data and the run is kept."""
    if rank == 0:
        try:
            data = load_training_data(cfg, progress=progress)
        except KeyboardInterrupt as e:                       # Ctrl-C before the first step: say what is kept
            what = getattr(e, "saved", None) or "nothing of it is cached"
            done = f"{run_dir / 'checkpoints'} is as it was" if resume else "no checkpoint was written"
            raise Interrupted(f"while preparing the training data: {what}; no training step ran and {done}; "
                              f"run the same command again to continue") from e
    if world > 1:
        dist.barrier()                                       # the procedural cache is complete
    if rank != 0:
        data = load_training_data(cfg, progress=False)
    return data


def _say_what_failed(e: BaseException, where: str, trainer: Trainer, checkpoints: Checkpoints) -> None:
    """Called while ``e`` propagates out of the loop ``where`` (``in step 5``): a :class:`RunError`
    of one line for the user's input or a full disk, and for a diverged run (NaN or Inf in the
    weights); otherwise (a bug) a note on ``e``, which keeps its traceback. Each says what is kept."""
    if isinstance(e, RunError):
        return
    if isinstance(e, (UserError, OSError)):                  # the user's input, a full disk: one line
        raise RunError(f"training failed {where}: {e}; {checkpoints.kept()}{checkpoints.no_room(e)}") from e
    bad = non_finite(trainer.state_dict()) if isinstance(e, ValueError) else None
    if bad is not None:                                      # a diverged run (NaN or Inf in the weights), not a bug
        raise RunError(f"training failed {where}: {e} (the training state is not finite: NaN or Inf in "
                       f"{bad}; lower the learning rates); {checkpoints.kept()}") from e
    e.add_note(f"training failed {where}; {checkpoints.kept()}")   # a bug: it keeps its traceback


def load_run(run_dir: Path, device: str = "cpu") -> Tuple[Config, Model, int]:
    """A trained run's config, :class:`~mitsuba_platonic.model.Model` and step (no training data
    is loaded): :func:`~mitsuba_platonic.files.checkpoint.read_checkpoint` of the run folder."""
    ckpt = read_checkpoint(Path(run_dir), device)
    cfg = checkpoint_config(ckpt)
    return cfg, model_from_checkpoint(Model, ckpt, cfg), ckpt.step
