"""Checkpoints: the file format, atomic saves, and reading the newest loadable one.

A checkpoint (``RUN/checkpoints/last.pt``, ``RUN/checkpoints/step_NNNNNNN.pt``) is a
``torch.save``d dict::

    version   CHECKPOINT_VERSION (a file of another version is refused with one line)
    step      training steps done
    config    the run's resolved config (``Config.to_dict()``: a plain mapping of sections)
    trainer   the trainer's state: ``nets`` (E, G, D and D3 in one state dict, keys ``E.*``,
              ``G.*``, ...) and the optimisers' states

Training writes checkpoints (:mod:`mitsuba_platonic.train.run`); inference reads them
(:meth:`mitsuba_platonic.model.Model.from_checkpoint`) without the training code. This module is
the file format alone: it stores and returns plain data and imports no config; the config saved
in a checkpoint becomes a :class:`~mitsuba_platonic.config.Config`, and its weights a model, in
:mod:`mitsuba_platonic.config.loading`, in the config's package.

Loading runs no code: every reader goes through :func:`load_checkpoint`, ``torch.load(...,
weights_only=True)``, whose unpickler builds tensors and plain data (dicts, lists, tuples,
strings, numbers) and refuses any other Python object. Everything a checkpoint holds is such
data (:func:`save_checkpoint` checks it before writing). A file that names another object (a
crafted ``__reduce__``, or a numpy scalar from hand-made tooling) is refused with
:class:`UnsafeCheckpoint`, one line naming the file and the object; it is never skipped in favour
of an older checkpoint, so such a file cannot go unnoticed. A user who trusts the file converts
it once, knowingly, with ``platonic convert-checkpoint PATH`` (:func:`convert_checkpoint`: the
only place that unpickles with ``weights_only=False``). Checkpoints written before loading was
made safe hold the same plain data and load as they are.
"""

from __future__ import annotations

import pickle
import re
import warnings
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path, PurePath
from typing import Any, Dict, List, Optional, Tuple, Union

import numpy as np
import torch

from ..errors import UserError
from .fileio import MAX_CHECKPOINT_BYTES, InputFileRefused, atomic_write, check_input_file
from .pickle_scan import foreign_objects

__all__ = ["RunError", "UnsafeCheckpoint", "DamagedCheckpoint", "NotACheckpoint", "OversizedCheckpoint", "CHECKPOINT_VERSION", "Checkpoint", "save_checkpoint",
           "load_checkpoint", "checkpoint_files", "load_latest_checkpoint", "read_checkpoint", "objects_to_convert", "convert_checkpoint",
           "load_weights", "saved_config_dict"]

CHECKPOINT_VERSION = 1

_NUMBERED = re.compile(r"step_(\d+)\.pt")
#: The first bytes of torch's zip format (a legacy or plain pickle starts with 0x80, its protocol).
_ZIP_MAGIC = b"PK\x03\x04"


class RunError(UserError):
    """A run folder or checkpoint that cannot be used as asked (exists, missing, incompatible)."""


class DamagedCheckpoint(RunError):
    """A checkpoint file that is truncated or damaged: cut short by a copy or a save (torch's own
    errors for it read ``[Errno 22] Invalid argument`` or name miniz)."""


class NotACheckpoint(RunError):
    """A file that is no checkpoint at all (a config, an image) where one was expected."""


class OversizedCheckpoint(RunError):
    """A checkpoint file larger than :data:`~mitsuba_platonic.files.fileio.MAX_CHECKPOINT_BYTES`
    (``size`` bytes), refused before a byte of it is read."""

    def __init__(self, message: str, size: int):
        super().__init__(message)
        self.size = size


class UnsafeCheckpoint(RunError):
    """A checkpoint the safe loader refused: it names a Python object (``refused``, e.g.
    ``'posix.system'``) that unpickling would build or call, which could run any code. Never a
    reason to fall back to an older checkpoint."""

    def __init__(self, message: str, refused: str):
        super().__init__(message)
        self.refused = refused


#: What a checkpoint may hold: the types ``torch.load(weights_only=True)`` builds without a global.
_PLAIN = (str, int, float, bool, type(None))


def save_checkpoint(path: Path, payload: Dict[str, Any]) -> None:
    """``torch.save`` to a temporary sibling, fsync, then rename over ``path`` (atomic).

    A failed write (a full disk) is the ``OSError`` the file raised, naming ``path``: ``torch.save``
    itself reports it as a ``RuntimeError`` about stream positions.
    """
    bad = _not_plain(payload)
    if bad is not None:                  # a bug in the writer: the safe loader would refuse the file
        raise TypeError(f"checkpoint {path}: {bad} is not plain data (tensors, dicts, lists, tuples, str, "
                        f"int, float, bool, None); load_checkpoint could not read it back")

    def write(tmp: Path) -> None:
        with open(tmp, "wb") as f:
            out = _Recorded(f)
            try:
                torch.save(payload, out)
            except RuntimeError:
                if out.error is not None:
                    raise out.error from None
                raise

    atomic_write(path, write, durable=True)


class _Recorded:
    """A binary file for ``torch.save`` that remembers the ``OSError`` a write raised."""

    def __init__(self, f):
        self.f, self.error = f, None

    def write(self, data) -> int:
        try:
            return self.f.write(data)
        except OSError as e:
            self.error = e
            raise

    def flush(self) -> None:
        self.f.flush()


def _not_plain(value: Any, name: str = "the payload") -> Optional[str]:
    """The name and type of the first part of ``value`` that is not plain data, else None."""
    if type(value) in (torch.Tensor, torch.nn.Parameter) or type(value) in _PLAIN:
        return None
    if type(value) in (dict, OrderedDict):
        items = value.items()
        bad_key = next((k for k in value if type(k) not in (str, int)), None)
        if bad_key is not None:
            return f"{name} key {bad_key!r} ({type(bad_key).__name__})"
    elif type(value) in (list, tuple):
        items = enumerate(value)
    else:
        return f"{name} ({type(value).__module__}.{type(value).__qualname__})"
    for k, v in items:
        bad = _not_plain(v, f"{name}[{k!r}]")
        if bad is not None:
            return bad
    return None


#: How torch's weights-only unpickler names an object it refused (torch 2.1 to 2.13).
_REFUSED = (re.compile(r"GLOBAL (\S+)"), re.compile(r"reduce for unrecognized function ([^\n]+?)(?: which|$)", re.M),
            re.compile(r"Can only (?:create new object|build)[^\n]*? but got ([^\n]+)"))


def _refused_object(message: str) -> Optional[str]:
    """The object a weights-only ``UnpicklingError`` refused (e.g. ``'posix.system'``), or None when
    the error is about a torn or corrupt file instead (an unknown opcode, an end of file)."""
    for pattern in _REFUSED:
        match = pattern.search(message)
        if match:
            return match.group(1).rstrip(".,;")
    return None


def load_checkpoint(path: Path, device: torch.device = torch.device("cpu")) -> Dict[str, Any]:
    """The raw contents of one checkpoint file, unpickled safely (``weights_only=True``: tensors and
    plain data, no code runs); not checked otherwise (see :func:`load_latest_checkpoint`).

    Raises :class:`RunError` if there is no file, or it is no regular file (a folder, a FIFO) or
    larger than :data:`~mitsuba_platonic.files.fileio.MAX_CHECKPOINT_BYTES` (checked before a byte
    is read), :class:`UnsafeCheckpoint` (one line naming the file, the object and how to convert a
    trusted file) if it names any other Python object, and torch's own errors for a torn or corrupt file.
    """
    try:
        check_input_file(path, "checkpoint", MAX_CHECKPOINT_BYTES)   # a regular file of a bounded size
    except FileNotFoundError:
        raise RunError(f"no checkpoint at {path}") from None
    except InputFileRefused as e:
        if e.reason == "not_a_file":
            raise NotACheckpoint(f"no checkpoint at {path}: {e}") from None
        raise OversizedCheckpoint(f"{e}: expected a checkpoint platonic train wrote (tens to hundreds of MB)",
                                  path.stat().st_size) from None
    with open(path, "rb") as f:
        head = f.read(4)
    if head and not head.startswith((_ZIP_MAGIC, b"\x80")):
        raise NotACheckpoint(f"{path} is not a checkpoint file (neither torch's zip format nor a pickle)")
    try:
        with warnings.catch_warnings():  # torch's note on a plain pickle's protocol: the scan below says more
            warnings.filterwarnings("ignore", message="Detected pickle protocol")
            return torch.load(path, map_location=device, weights_only=True)
    except pickle.UnpicklingError as e:
        what = _refused_object(str(e))
        if what is None:                 # a pickle torch cannot read (protocol 4's FRAME) may still name objects
            foreign = foreign_objects(path)
            if not foreign:
                raise DamagedCheckpoint(_damaged(path, e)) from None
            what = foreign[0]
        raise _unsafe(path, what) from None
    except Exception as e:               # RuntimeError (a zip cut short), EOFError, OSError (a seek past the end)
        foreign = foreign_objects(path) if head.startswith(b"\x80") else []
        if foreign:
            raise _unsafe(path, foreign[0]) from None
        raise DamagedCheckpoint(_damaged(path, e)) from None


def _unsafe(path: Path, what: str) -> UnsafeCheckpoint:
    """The one line of a file that names an object the safe loader does not build."""
    shown = what if len(what) <= 80 else what[:79] + "…"
    return UnsafeCheckpoint(
        f"{path} was refused: it holds a Python object ({shown}) whose loading could run any code (a "
        f"checkpoint holds only tensors and plain data); if you trust where the file came from, convert it "
        f"once with `platonic convert-checkpoint {path}`",
        what)


def _damaged(path: Path, e: BaseException) -> str:
    """Why a checkpoint file that is no unsafe one could not be read, in words (torch's own text,
    ``[Errno 22] Invalid argument`` or a miniz error, says nothing a user can act on)."""
    size = path.stat().st_size
    if size == 0:
        return f"{path} is empty (0 bytes): a copy or a save cut short"
    return (f"{path} is truncated or damaged ({size:,} bytes, not a whole checkpoint: a copy or a save cut "
            f"short); copy it again, or use another checkpoint of the run (checkpoints/step_*.pt)")


def objects_to_convert(path: Union[str, Path]) -> Optional[List[str]]:
    """What converting ``path`` would import and could call, read without unpickling it: the objects
    (``posix.system``, ``numpy.ndarray``) its pickles name that the safe loader does not build, or
    None if it loads safely already (nothing to convert). :class:`RunError` naming the file if it is
    missing, truncated or no checkpoint."""
    path = Path(path)
    try:
        load_checkpoint(path)
        return None
    except UnsafeCheckpoint as e:
        return foreign_objects(path) or [e.refused]


def convert_checkpoint(path: Union[str, Path], out: Union[str, Path, None] = None) -> Optional[str]:
    """Rewrite a checkpoint that the safe loader refuses as one it reads, for a user who trusts it.

    **This unpickles ``path`` with ``weights_only=False``, which runs any code the file holds**: the
    one place in the package that does, reached only by ``platonic convert-checkpoint`` (the user
    asked for it, named the file and was told what it does). A file that already loads safely is
    never unpickled that way and is left as it is. Numpy arrays become tensors, numpy scalars
    numbers, paths strings; the result is written atomically to ``out`` (default: over ``path``)
    and read back with the safe loader. Returns the object the safe loader had refused, or None
    if the file already loaded safely (nothing written). :class:`RunError` naming the file if it
    is missing, torn, holds something with no plain equivalent, or is no training checkpoint.
    """
    path = Path(path)
    target = Path(out) if out is not None else path
    try:
        load_checkpoint(path)
        return None
    except UnsafeCheckpoint as e:
        refused = e.refused
    except RunError:
        raise
    except Exception as e:                                   # torn or corrupt: nothing to convert
        raise RunError(f"{path} cannot be loaded: {_one_line(e)}") from None
    state = _unpickle_trusted(path)
    save_checkpoint(target, _to_plain(state, path, "the checkpoint"))
    try:
        _checked(target, torch.device("cpu"))
    except ValueError as e:
        raise RunError(f"{target}: converted to plain data, but it is not a training checkpoint this "
                       f"version reads ({_one_line(e)})") from None
    return refused


def _unpickle_trusted(path: Path) -> Any:
    """The contents of a checkpoint the user trusts, unpickled in full: torch's formats
    (``torch.save``, its zip or its legacy pickle) by ``torch.load``, a plain ``pickle.dump`` of the
    state (hand-made tooling; what the safe loader reads as a pickle too) by ``pickle.load``, whose
    tensors torch's own reducers rebuild. :class:`RunError` naming the file if neither reads it."""
    with open(path, "rb") as f:
        zipped = f.read(4).startswith(_ZIP_MAGIC)
    try:
        return torch.load(path, map_location="cpu", weights_only=False)     # the user trusts this file
    except Exception as e:
        if zipped or "magic number" not in str(e):
            raise RunError(f"{path} cannot be loaded: {_one_line(e)}") from None
    try:
        with open(path, "rb") as f:
            return pickle.load(f)                                            # the user trusts this file
    except Exception as e:
        raise RunError(f"{path} cannot be loaded, neither by torch.load nor as a plain pickle: {_one_line(e)}") from None


def _to_plain(value: Any, path: Path, name: str) -> Any:
    """``value`` with numpy arrays as tensors, numpy scalars as numbers and paths as strings;
    :class:`RunError` naming ``path`` and the part for anything else that is not plain data."""
    if isinstance(value, torch.Tensor):
        return value.detach() if isinstance(value, torch.nn.Parameter) else value
    if isinstance(value, np.ndarray) and value.dtype != object:
        return torch.from_numpy(np.ascontiguousarray(value))
    if isinstance(value, np.generic) and not isinstance(value, np.object_):
        return value.item()
    if isinstance(value, PurePath):
        return str(value)
    if type(value) in _PLAIN:
        return value
    for base in (bool, int, float, str):                    # subclasses (an IntEnum): their plain value
        if isinstance(value, base):
            return base(value)
    if isinstance(value, dict):
        out = OrderedDict() if isinstance(value, OrderedDict) else {}
        for k, v in value.items():
            key = _to_plain(k, path, f"{name} key {k!r}")
            if type(key) not in (str, int):
                raise RunError(f"{path}: cannot convert {name}: its key {k!r} is a {type(k).__name__}")
            out[key] = _to_plain(v, path, f"{name}[{k!r}]")
        return out
    if isinstance(value, (list, tuple)):
        items = [_to_plain(v, path, f"{name}[{i}]") for i, v in enumerate(value)]
        return items if isinstance(value, list) else tuple(items)
    raise RunError(f"{path}: cannot convert {name}, a {type(value).__module__}.{type(value).__qualname__}, "
                   f"to plain data (tensors, numbers, strings, lists, dicts)")


def _checked(path: Path, device: torch.device) -> Dict[str, Any]:
    """:func:`load_checkpoint`, then ``ValueError`` unless it is a training checkpoint of this version."""
    state = load_checkpoint(path, device)
    if not isinstance(state, dict) or not {"step", "trainer", "config"} <= set(state):
        raise ValueError("not a training checkpoint")
    if state.get("version") != CHECKPOINT_VERSION:
        raise ValueError(f"checkpoint format {state.get('version')!r}, this version reads {CHECKPOINT_VERSION}")
    problem = _contents_problem(state)
    if problem is not None:
        raise ValueError(problem)
    return state


#: The trainer state's parts every training checkpoint has (``opt_d3`` and ``ema`` only some).
_TRAINER_PARTS = ("nets", "opt_g", "opt_d")


def _contents_problem(state: Dict[str, Any]) -> Optional[str]:
    """What is wrong with a checkpoint's ``step`` and ``trainer`` (short, for one line), else None."""
    step = state["step"]
    if type(step) is not int or step < 0:
        return f"its step is {step!r}, expected a count of training steps"
    trainer = state["trainer"]
    if not isinstance(trainer, dict):
        return f"its trainer state is a {type(trainer).__name__}, expected a dict of network and optimiser states"
    for part in _TRAINER_PARTS + tuple(k for k in ("opt_d3", "ema") if k in trainer):
        if not isinstance(trainer.get(part), dict):
            got = "missing" if part not in trainer else f"a {type(trainer[part]).__name__}"
            return f"its trainer state's {part!r} is {got}, expected a dict"
    for part in ("nets", "ema"):
        weights = trainer.get(part, {})
        bad = next((k for k, v in weights.items() if not isinstance(v, torch.Tensor)), None)
        if bad is not None or (part == "nets" and not weights):
            return f"its trainer state's {part!r} " + (f"holds a {type(weights[bad]).__name__} at {bad!r}, "
                                                       f"expected tensors" if bad is not None else "is empty")
    return None


def load_weights(target: Any, state: Dict[str, Any], path: Path, what: str) -> None:
    """``target.load_state_dict(state)`` (a module, an optimiser, the trainer), with a state that does
    not fit (a missing key, a size mismatch, another parameter grouping) a :class:`RunError`: one
    line naming ``path``, ``what`` it was loaded into and the first mismatch."""
    try:
        target.load_state_dict(state)
    except (RuntimeError, KeyError, ValueError, TypeError) as e:
        raise RunError(f"{path}: its saved state does not fit {what}: {_mismatch(e)}") from None


def _mismatch(e: BaseException, limit: int = 240) -> str:
    """The first mismatch ``load_state_dict`` reported, on one line (``size mismatch for G.fc.weight:
    ...``), with how many more there were."""
    text = str(e) if not isinstance(e, KeyError) else f"no {e.args[0]!r}"
    lines = [line.strip() for line in text.split("\n\t") if line.strip()]
    detail = lines[1:] or lines or [type(e).__name__]         # torch: 'Error(s) in loading ...:' then one per tab
    first = " ".join(detail[0].split()).replace("copying a param with shape ", "").rstrip(".")
    first = first if len(first) <= limit else first[:limit - 1] + "…"
    return first + (f" (and {len(detail) - 1} more)" if len(detail) > 1 else "")


def saved_config_dict(state: Dict[str, Any], path: Path, run_name: Optional[str] = None) -> Dict[str, Any]:
    """The config saved in a checkpoint as the plain mapping it is stored as (``run.name`` replaced
    by ``run_name`` if given; not validated: :func:`mitsuba_platonic.config.loading.saved_config` builds the
    :class:`~mitsuba_platonic.config.Config`); :class:`RunError` naming ``path`` if it is not a
    mapping of sections."""
    if not isinstance(state["config"], dict) or not isinstance(state["config"].get("run") or {}, dict):
        raise RunError(f"{path}: the config saved in this checkpoint is not a mapping of sections")
    saved = dict(state["config"])
    if run_name is not None:
        saved["run"] = {**(saved.get("run") or {}), "name": run_name}
    return saved


def checkpoint_files(folder: Path) -> List[Path]:
    """``last.pt`` (if present), then the numbered checkpoints, newest first."""
    numbered = sorted((p for p in folder.glob("step_*.pt") if _NUMBERED.fullmatch(p.name)),
                      key=lambda p: int(_NUMBERED.fullmatch(p.name).group(1)), reverse=True)
    last = folder / "last.pt"
    return ([last] if last.exists() or last.is_symlink() else []) + numbered   # a dangling link: named, not skipped


def load_latest_checkpoint(folder: Path, device: torch.device = torch.device("cpu"),
                           warn: bool = True) -> Tuple[Dict[str, Any], Path]:
    """The newest loadable checkpoint of ``folder`` (``RUN/checkpoints``): ``last.pt``, else the
    newest ``step_*.pt`` that loads, with a warning on stderr naming the files that did not (torn,
    corrupt, another format, contents that are not a training state).

    Raises :class:`RunError` (one line, naming every file tried) if none loads, and
    :class:`UnsafeCheckpoint` at the first file the safe loader refuses: a file that would run
    code is an error naming it, not a reason to use an older one.
    """
    failed: List[Tuple[Path, str]] = []
    for path in checkpoint_files(folder):
        try:
            state = _checked(path, device)
        except UnsafeCheckpoint:         # not a torn file: falling back would hide a crafted one
            raise
        except Exception as e:  # torn, damaged, not a checkpoint, another format, contents not a training state
            failed.append((path, _reason(e)))
            continue
        if failed and warn:             # one line, `platonic <command>: warning: …` on the command line
            warnings.warn(f"could not load {_by_reason(failed, str)}; using {path} (step {int(state['step'])})",
                          stacklevel=2)
        return state, path
    if not failed:
        raise RunError(f"no checkpoint in {folder}")
    raise RunError(f"no loadable checkpoint in {folder}: {_by_reason(failed, lambda p: p.name)}")


@dataclass
class Checkpoint:
    """A read checkpoint: its saved config (the plain mapping, ``run.name`` set to the run folder's
    name; :func:`mitsuba_platonic.config.loading.checkpoint_config` validates it), its raw state, the file
    and the step."""

    config: Dict[str, Any]
    state: Dict[str, Any]
    path: Path
    step: int


def read_checkpoint(source: Union[str, Path], device: Union[str, torch.device] = "cpu") -> Checkpoint:
    """A run folder (its newest loadable checkpoint) or one checkpoint file → :class:`Checkpoint`.

    The config is the one saved in the checkpoint (``config.yaml`` is not read), as a plain
    mapping with ``run.name`` set to the run folder's name (one that is no mapping of sections is a
    :class:`RunError` naming the file; :func:`mitsuba_platonic.config.loading.checkpoint_config` validates it).
    """
    source, device = Path(source), torch.device(device)
    if source.is_file():
        try:
            state = _checked(source, device)
        except NotACheckpoint:
            raise NotACheckpoint(f"{source} is not a checkpoint: --run takes a run folder (runs/NAME) or one of its "
                                 f"checkpoint files (runs/NAME/checkpoints/last.pt)") from None
        except RunError:
            raise
        except Exception as e:
            raise RunError(f"{source} cannot be loaded: {_one_line(e)}") from None
        path, run_dir = source, source.parent.parent
    else:
        if not source.exists():
            raise RunError(f"{source} does not exist: --run takes a run folder (runs/NAME) or a checkpoint file")
        if not source.is_dir():
            raise RunError(f"{source} is neither a folder nor a file: --run takes a run folder (runs/NAME) or a "
                           f"checkpoint file")
        if not checkpoint_files(source / "checkpoints"):
            raise RunError(f"{source} has no checkpoints/last.pt: not a training run, or not started")
        state, path = load_latest_checkpoint(source / "checkpoints", device)
        run_dir = source
    cfg = saved_config_dict(state, path, run_name=run_dir.resolve().name)   # the folder is the run
    return Checkpoint(cfg, state, path, int(state["step"]))


def _by_reason(failed: List[Tuple[Path, str]], name) -> str:
    """``a.pt, b.pt (reason 1); c.pt (reason 2)``: files grouped by why they did not load."""
    groups: Dict[str, List[str]] = {}
    for path, why in failed:
        groups.setdefault(why, []).append(name(path))
    return "; ".join(f"{', '.join(names)} ({why})" for why, names in groups.items())


def _reason(e: BaseException) -> str:
    """Why a checkpoint file was passed over, short, for a list of files."""
    if isinstance(e, DamagedCheckpoint):
        return "empty" if "is empty" in str(e) else "truncated or damaged"
    if isinstance(e, NotACheckpoint):
        return "not a checkpoint file"
    if isinstance(e, OversizedCheckpoint):
        return f"{e.size:,} bytes, more than the {MAX_CHECKPOINT_BYTES:,} a checkpoint may be"
    return _one_line(e)


def _one_line(e: BaseException, limit: int = 100) -> str:
    """The first sentence of an error, on one line, at most ``limit`` characters."""
    text = " ".join(str(e).split()).split(". ")[0] or type(e).__name__
    return text if len(text) <= limit else text[:limit - 1] + "…"
