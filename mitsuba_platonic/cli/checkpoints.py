"""``platonic convert-checkpoint``: :func:`mitsuba_platonic.checkpoint.convert_checkpoint`, for a
trusted checkpoint the safe loader refuses (the only command that unpickles with
``weights_only=False``)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import List, Sequence

from .args import CLIError

__all__ = ["add_convert_checkpoint"]


def _cmd_convert_checkpoint(args: argparse.Namespace) -> int:
    from ..checkpoint import convert_checkpoint

    files = _checkpoints_to_convert([Path(p) for p in args.paths])
    if args.out is not None and len(files) != 1:
        raise CLIError(f"--out takes one checkpoint file; {len(files)} were given (or found in a run folder)")
    for path in files:
        target = Path(args.out) if args.out is not None else path
        refused = convert_checkpoint(path, target)
        if refused is None:
            print(f"{path}: loads safely already; left as it is")
        else:
            print(f"{path}: converted (it held {refused}) → {target}, which loads safely")
    return 0


def _checkpoints_to_convert(paths: Sequence[Path]) -> List[Path]:
    """Checkpoint files as given, a run folder's ``checkpoints/*.pt`` in its place; :class:`CLIError`
    for a path that is neither."""
    from ..checkpoint import checkpoint_files

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
                                   "holds: use it only on files whose origin you trust. Files that already load "
                                   "safely are left as they are (never unpickled that way).")
    p.add_argument("paths", nargs="+", metavar="PATH", help="checkpoint files, or run folders (all their checkpoints)")
    p.add_argument("--out", default=None, metavar="FILE",
                   help="write the converted checkpoint here instead of over PATH (one file only)")
    p.set_defaults(handler=_cmd_convert_checkpoint)
