"""``platonic reconstruct`` and ``platonic generate``: a trained run's volumes, exported.

Each reads a :class:`~mitsuba_platonic.model.Model` from a run and writes its volumes with
:func:`~mitsuba_platonic.export.export_reconstructions` (one per input image) or
:func:`~mitsuba_platonic.export.export_samples` (drawn from the generator); a Ctrl-C says how many
whole files are on disk.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import List

from ..errors import Interrupted
from ..files.fileio import confined
from ..files.outputs import output_lock
from .args import CLIError, add_background, non_negative_int, positive_int, seed

__all__ = ["add_reconstruct", "add_generate"]


def _interrupted_export(command: str, written: List[Path], out: Path, detail: str) -> Interrupted:
    """The one line of a Ctrl-C in reconstruct/generate: how many files are on disk, and how to go on."""
    return Interrupted(f"{len(written)} complete file(s) written to {out} ({detail}); each file is whole; "
                       f"run the command again with --overwrite (or another --out) to redo them",
                       saved=f"{len(written)} file(s) in {out}")


def _cmd_reconstruct(args: argparse.Namespace) -> int:
    from ..export import export_reconstructions
    from ..model import Model

    if not 0.0 < args.level < 1.0:                           # a density level: before the model is read
        raise CLIError(f"--level: expected the mesh's iso-level, a density between 0 and 1 (exclusive), got "
                       f"{args.level:g}")
    model = Model.from_checkpoint(args.run)
    out = Path(args.out) if args.out else Path(args.run) / "reconstructions"
    written: List[Path] = []
    done_inputs = 0
    try:
        with confined(out), output_lock(out, "reconstruct"):   # no write through a link, one command at a time
            for path, done in export_reconstructions(model, args.images, out, background=args.background,
                                                     crop=args.crop, level=args.level, overwrite=args.overwrite,
                                                     written=written):
                done_inputs += 1
                if done.no_mesh:
                    print(f"{path}: no mesh: {done.no_mesh}", file=sys.stderr)
                print(f"{path} → " + ", ".join(str(p) for p in done.paths))
    except KeyboardInterrupt:
        raise _interrupted_export("reconstruct", written, out,
                                  f"{done_inputs} of {len(args.images)} input(s) finished") from None
    return 0


def add_reconstruct(sub: "argparse._SubParsersAction") -> None:
    from ..data.photos import CROPS

    p = sub.add_parser("reconstruct", help="single-image 3D reconstruction with a trained run",
                       description="Encode each image, generate its volume, and write the volume (.npz, "
                                   ".vol), a turntable GIF and a marching-cubes mesh with vertex colours (.ply) "
                                   "into --out. Names: each input's file name without its last extension "
                                   "(shot.v1.png → shot.v1.*), characters other than letters, digits and . _ + - "
                                   "as _, a leading dot as _; a name an earlier input took gets _2, _3, … "
                                   "(a/x.png b/x.png → x.*, x_2.*). Files of those names already in --out are "
                                   "refused unless --overwrite.")
    p.add_argument("--run", required=True, help="a run folder (with checkpoints/last.pt)")
    p.add_argument("images", nargs="+", help="input images (RGBA PNG, or RGB on white with --background white)")
    p.add_argument("--out", default=None, help="output folder (default: RUN/reconstructions)")
    add_background(p)
    p.add_argument("--crop", choices=CROPS, default="image")
    p.add_argument("--level", type=float, default=0.5, help="iso-level of the mesh (default: %(default)s)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace the files of the same names an earlier call wrote into --out")
    p.set_defaults(handler=_cmd_reconstruct, interrupted="nothing was written; run the same command again")


def _cmd_generate(args: argparse.Namespace) -> int:
    from ..export import export_samples
    from ..model import Model

    if args.cell < 8:                                          # before the model is read
        raise CLIError(f"--cell: expected at least 8 pixels per tile, got {args.cell}")
    if args.interpolate == 1:
        raise CLIError("--interpolate: a walk needs at least 2 steps (its two ends), or 0 for none")

    model = Model.from_checkpoint(args.run)
    out = Path(args.out) if args.out else Path(args.run) / "generated"
    written: List[Path] = []
    try:
        with confined(out), output_lock(out, "generate"):    # no write or deletion through a link, one at a time
            export_samples(model, args.n, out, seed=args.seed, overwrite=args.overwrite, written=written,
                           progress=not args.quiet, cell=args.cell, turntables=args.turntable,
                           interpolation=args.interpolate)
    except KeyboardInterrupt:
        samples = len({p.stem for p in written if p.name.startswith("sample_")})
        raise _interrupted_export("generate", written, out, f"{samples} of {args.n} sample(s) begun, "
                                                              f"the sheets (samples.png …) not written") from None
    sheets = ["samples.png (the grid)"] + (["turntables.png"] if args.turntable else []) + \
        (["interpolation.png (sample_000 to sample_001)"] if args.interpolate and args.n >= 2 else [])
    print(f"{args.n} volumes (step {model.step}) → {out}; " + ", ".join(sheets))
    return 0


def add_generate(sub: "argparse._SubParsersAction") -> None:
    p = sub.add_parser("generate", help="sample volumes from a trained generator",
                       description="Draw z ~ N(0, I), generate volumes, write sample_000.npz/.vol/.gif, … into "
                                   "--out with three sheets: samples.png (a labelled grid, one tile per sample), "
                                   "turntables.png (a line of azimuths per sample) and interpolation.png (G along "
                                   "the spherical interpolation from sample_000's latent to sample_001's). A folder "
                                   "holding an earlier call's samples is refused unless --overwrite, which deletes "
                                   "them first.")
    p.add_argument("--run", required=True, help="a run folder")
    p.add_argument("-n", type=positive_int, default=16, help="number of samples (default: %(default)s)")
    p.add_argument("--seed", type=seed, default=0)
    p.add_argument("--out", default=None, help="output folder (default: RUN/generated)")
    p.add_argument("--cell", type=positive_int, default=128, metavar="PX",
                   help="pixels per tile of the sheets, at least (nearest upscaling; default: %(default)s)")
    p.add_argument("--turntable", type=non_negative_int, default=8, metavar="N",
                   help="azimuths per sample in turntables.png (0: no turntables; default: %(default)s)")
    p.add_argument("--interpolate", type=non_negative_int, default=8, metavar="K",
                   help="steps of the walk from sample_000 to sample_001 in interpolation.png, ends included "
                        "(0: none; needs -n 2 or more; default: %(default)s)")
    p.add_argument("--overwrite", action="store_true",
                   help="delete an earlier call's sample_* files and sheets in --out first")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(handler=_cmd_generate, interrupted="nothing was written; run the same command again")
