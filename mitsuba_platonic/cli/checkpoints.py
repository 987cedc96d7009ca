"""``platonic convert-checkpoint``: :func:`mitsuba_platonic.files.checkpoint.convert_checkpoint`, for a
trusted checkpoint the safe loader refuses (the only command that unpickles with
``weights_only=False``)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Dict, List, Sequence

from .args import CLIError

__all__ = ["add_convert_checkpoint"]


def _cmd_convert_checkpoint(args: argparse.Namespace) -> int:
    from ..files.checkpoint import convert_checkpoint, objects_to_convert

    files = _checkpoints_to_convert([Path(p) for p in args.paths])
    if args.out is not None and len(files) != 1:
        raise CLIError(f"--out takes one checkpoint file; {len(files)} were given (or found in a run folder)")
    objects = {path: objects_to_convert(path) for path in files}     # read from the opcodes: nothing runs yet
    unsafe = {path: names for path, names in objects.items() if names is not None}
    if unsafe and not _confirmed(unsafe, args.yes):
        print("nothing was converted")
        return 1
    for path in files:
        target = Path(args.out) if args.out is not None else path
        if objects[path] is None:
            print(f"{path}: loads safely already; left as it is")
            continue
        refused = convert_checkpoint(path, target)
        print(f"{path}: converted (it held {refused}) → {target}, which loads safely")
    return 0


def _what_runs(unsafe: Dict[Path, List[str]], limit: int = 6) -> str:
    """``a.pt names posix.system; b.pt names numpy.ndarray, numpy.dtype``: what each file would call."""
    def names(found: List[str]) -> str:
        return ", ".join(found[:limit]) + (f" and {len(found) - limit} more" if len(found) > limit else "")
    return "; ".join(f"{path} names {names(found)}" for path, found in unsafe.items())


def _confirmed(unsafe: Dict[Path, List[str]], yes: bool) -> bool:
    """Whether the user agrees to unpickle the files of ``unsafe`` in full: ``--yes``, or a 'y' at the
    prompt on a terminal; without a terminal (a script, a pipe) a :class:`CLIError` that names what
    would run, before anything did."""
    what = _what_runs(unsafe)
    if yes:
        print(f"converting with --yes: {what}", flush=True)
        return True
    if not sys.stdin.isatty():
        raise CLIError(f"{what}: converting unpickles in full, which imports these and may call them (any code); "
                       f"nothing was converted; if you trust where the file(s) came from, run again with --yes")
    print(f"{what}.\nConverting unpickles in full, which imports these and may call them (any code). "
          f"Only convert files whose origin you trust.", flush=True)
    try:
        answer = input("Convert? [y/N] ")
    except EOFError:
        answer = ""
    return answer.strip().lower() in ("y", "yes")


def _checkpoints_to_convert(paths: Sequence[Path]) -> List[Path]:
    """Checkpoint files as given, a run folder's ``checkpoints/*.pt`` in its place; :class:`CLIError`
    for a path that is neither."""
    from ..files.checkpoint import checkpoint_files

    files: List[Path] = []
    for path in paths:
        if path.is_file():
            files.append(path)
        elif path.is_dir() and checkpoint_files(path / "checkpoints"):
            files += [p for p in checkpoint_files(path / "checkpoints") if p.is_file()]
        else:
            raise CLIError(f"{path} is neither a checkpoint file nor a run folder with checkpoints/*.pt")
    return files


def add_convert_checkpoint(sub: "argparse._SubParsersAction") -> None:
    p = sub.add_parser("convert-checkpoint", help="rewrite a trusted checkpoint that the safe loader refuses",
                       description="Every command loads checkpoints safely (tensors and plain data only; no "
                                   "code runs) and refuses a file that holds other Python objects. This command "
                                   "converts such a file into one that loads safely. WARNING: to do so it "
                                   "unpickles the file with Python's full pickle, which runs any code the file "
                                   "holds: use it only on files whose origin you trust. It first names the objects "
                                   "each file would import (read without unpickling) and asks (or needs --yes where "
                                   "stdin is no terminal). Files that already load safely are left as they are "
                                   "(never unpickled that way).")
    p.add_argument("paths", nargs="+", metavar="PATH", help="checkpoint files, or run folders (all their checkpoints)")
    p.add_argument("--out", default=None, metavar="FILE",
                   help="write the converted checkpoint here instead of over PATH (one file only)")
    p.add_argument("--yes", action="store_true",
                   help="convert without asking (needed where stdin is not a terminal: scripts, pipes)")
    p.set_defaults(handler=_cmd_convert_checkpoint)
