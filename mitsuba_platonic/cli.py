"""The ``platonic`` command line.

Subcommands (one ``argparse`` subparser each; add new ones in :func:`build_parser` with a
``handler`` default taking the parsed arguments and returning an exit code). A handler checks
its flags, calls the library function that does the work and prints what it wrote:

- ``quickstart``: :func:`mitsuba_platonic.quickstart.quickstart`.
- ``train``: :func:`mitsuba_platonic.train.train`.
- ``reconstruct`` / ``generate``: a :class:`~mitsuba_platonic.model.Model` read from a run,
  :func:`~mitsuba_platonic.export.export_reconstructions` / :func:`~mitsuba_platonic.export.export_samples`.
- ``make-dataset``: :func:`mitsuba_platonic.data.collection.make_collection` per shape class.
- ``compare``: render a volume with the closed-form layers and the Mitsuba ray marcher from a
  few views and report how far apart and how fast they are (:mod:`mitsuba_platonic.compare`).
- ``bench``: the renderers' speed/accuracy trade: times, memory, image and gradient errors,
  JSON, Markdown and Pareto plots (:mod:`mitsuba_platonic.bench`).
- ``convert-checkpoint``: :func:`mitsuba_platonic.checkpoint.convert_checkpoint`, for a trusted
  checkpoint the safe loader refuses (the only command that unpickles with ``weights_only=False``).

Exit codes: 0 on success; 2 on a user error (usage errors, unreadable or invalid files, invalid
options: :class:`~mitsuba_platonic.errors.UserError`, which ``ConfigError``, ``RunError`` and
``CLIError`` are, ``BackendError``, and ``OSError`` from files and disks), printed as one line on
stderr without a traceback; 130 on Ctrl-C, one line saying what was saved. Any other exception is
a bug and keeps its traceback (exit code 1).
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from pathlib import Path
from typing import Callable, List, Optional, Sequence

from .backend import BackendError
from .errors import Interrupted, UserError

__all__ = ["main", "build_parser", "parse_models"]

PROG = "platonic"


class CLIError(UserError):
    """A user error: reported as ``platonic <command>: error: <message>``, exit code 2."""


# --------------------------------------------------------------------------- models


def parse_models(text: str) -> List[str]:
    """``"vh,ao,ea"`` → ``['vh', 'ao', 'ea']`` (validated, duplicates dropped, order kept)."""
    from .volume import MODELS

    models: List[str] = []
    for m in (s.strip().lower() for s in text.split(",")):
        if not m:
            continue
        if m not in MODELS:
            raise CLIError(f"unknown model {m!r} in --models {text!r}; expected a comma-separated "
                           f"subset of {','.join(MODELS)}")
        if m not in models:
            models.append(m)
    if not models:
        raise CLIError(f"--models {text!r} names no model; expected e.g. vh,ao,ea")
    return models


# --------------------------------------------------------------------------- argument types


def _number_type(convert: Callable[[str], float], minimum: float, what: str) -> Callable[[str], float]:
    """An argparse type: ``convert(text)``, finite and ≥ ``minimum``, else an error saying ``what``."""
    def parse(text: str):
        try:
            value = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        if not (value >= minimum and value != float("inf")):
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
        return value
    return parse


_positive_int = _number_type(int, 1, "a positive integer")
_non_negative_int = _number_type(int, 0, "a non-negative integer")
_resolution = _number_type(int, 2, "an integer resolution of at least 2")
_positive_float = _number_type(float, float.fromhex("0x1p-1074"), "a positive finite number")


# --------------------------------------------------------------------------- compare


#: compare's flags for the renderer settings they set (their errors name the flag).
_COMPARE_FLAGS = {"step": "--step", "spp": "--spp", "jitter": "--jitter", "filter": "--filter"}


def _check_compare_settings(args: argparse.Namespace) -> None:
    """The marcher's settings from compare's flags, checked by the renderer before any work."""
    from .render.settings import RenderSettings

    try:
        RenderSettings.for_call("mitsuba", "ea", filter=args.filter, step=args.step, spp=args.spp,
                                jitter=args.jitter)
    except ValueError as e:
        key, _, rest = str(e).partition(": ")
        if key in _COMPARE_FLAGS:
            raise CLIError(f"{_COMPARE_FLAGS[key]}: {rest}") from None
        raise CLIError(str(e)) from None


def _cmd_compare(args: argparse.Namespace) -> int:
    from .compare import check_memory, compare, comparison_views, format_table, write_summary
    from .volume_io import BUILTIN_PREFIX, load_volume

    _check_compare_settings(args)
    if args.volume.startswith(BUILTIN_PREFIX):              # before building it: refuse what cannot fit
        n = 32 if args.resolution is None else args.resolution
        check_memory(n, args.views, builtin=True,
                     what=f"--resolution {n}" if args.resolution is not None else f"--volume {args.volume}")
    volume = load_volume(args.volume, args.resolution)
    if not args.volume.startswith(BUILTIN_PREFIX):
        check_memory(volume.shape[-1], args.views, what=f"--volume {args.volume}")
    models = parse_models(args.models)
    if volume.shape[1] == 1 and "ea" in models:
        models.remove("ea")
        print(f"{args.volume}: density-only volume (C = 1): skipping EA, which needs "
              f"[r, g, b, density]", file=sys.stderr)
        if not models:
            raise CLIError("nothing to compare: the volume has no colour, so EA cannot be rendered; "
                           "pass --models vh,ao")
    views = comparison_views(args.views, seed=args.seed)
    options = {"step": args.step, "spp": args.spp, "jitter": args.jitter, "seed": args.seed}
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise CLIError(f"--out {str(out)!r} exists and is not a folder")
    results = compare(volume, views, models, filter=args.filter, options=options, out_dir=out,
                      repeats=args.repeats)

    n = volume.shape[-1]
    print(f"closed form vs Mitsuba: {args.volume} at {n}³, {len(views)} view(s), filter={args.filter}, "
          f"step={args.step:g}, spp={args.spp}, jitter={args.jitter}; "
          f"times: best of {args.repeats} after a warm-up, forward only")
    print(format_table(results))
    summary = write_summary(out / "compare.json", args.volume, views, results, args.repeats)
    print("wrote:")
    for r in results:
        print(f"  {r['png']}")
        for p in r["exrs"]:
            print(f"  {p}")
    print(f"  {summary}")
    return 0


def _add_compare(sub: "argparse._SubParsersAction") -> None:
    p = sub.add_parser(
        "compare", help="compare the closed-form and Mitsuba renderers on one volume",
        description="Render a volume with the closed-form layers and the Mitsuba ray marcher from "
                    "the front view plus random views; print max/mean absolute differences and "
                    "forward times, write comparison figures (PNG) and the Mitsuba renders (EXR).")
    p.add_argument("--volume", default="builtin:figure",
                   help="builtin:figure | builtin:cloud | a .npz file with an array 'volume' of shape "
                        "(C,N,N,N) or (1,C,N,N,N), C = 4 [r,g,b,density] or 1 [density], values in "
                        "[0,1] (default: %(default)s)")
    p.add_argument("--resolution", type=_resolution, default=None,
                   help="N ≥ 2 for built-in volumes (default 32); must match a file's N if given")
    p.add_argument("--models", default="vh,ao,ea", help="comma-separated models (default: %(default)s)")
    p.add_argument("--views", type=_positive_int, default=4,
                   help="number of views: the front view, then random views (default: %(default)s)")
    p.add_argument("--filter", choices=("trilinear", "nearest"), default="trilinear",
                   help="volume lookups, both backends (default: %(default)s)")
    p.add_argument("--step", type=_positive_float, default=1.0,
                   help="Mitsuba ray-marching step in voxels (default: %(default)s)")
    p.add_argument("--spp", type=_positive_int, default=1,
                   help="Mitsuba samples per pixel; a perfect square unless --jitter (default: %(default)s)")
    p.add_argument("--jitter", action="store_true",
                   help="Mitsuba: random sub-pixel positions and sample depths")
    p.add_argument("--out", default="compare", help="output folder (default: %(default)s/)")
    p.add_argument("--seed", type=_non_negative_int, default=0,
                   help="seed of the random views and of Mitsuba's sampler (default: %(default)s)")
    p.add_argument("--repeats", type=_positive_int, default=3,
                   help="timed runs per backend after one warm-up; the best counts (default: %(default)s)")
    p.set_defaults(handler=_cmd_compare)


# --------------------------------------------------------------------------- bench


def _cmd_bench(args: argparse.Namespace) -> int:
    from .bench import DOC_BEGIN, DOC_END, BenchSettings, run_bench, write_doc, write_outputs

    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise CLIError(f"--out {str(out)!r} exists and is not a folder")
    if args.doc is not None and not Path(args.doc).is_file():
        raise CLIError(f"--doc {args.doc!r} is not a file")
    if args.doc is not None:                                 # before the run, not after it
        text = Path(args.doc).read_text()
        if DOC_BEGIN not in text or DOC_END not in text:
            raise CLIError(f"--doc {args.doc!r} has no generated section: it needs the lines "
                           f"{DOC_BEGIN!r} and {DOC_END!r}")
    settings = BenchSettings(resolutions=tuple(args.resolutions), batch=args.batch, repeats=args.repeats,
                             threads=args.threads, models=tuple(parse_models(args.models)), volume=args.volume,
                             seed=args.seed, quick=args.quick, physical_ref_spp=args.physical_ref_spp,
                             physical=not args.no_physical, physical_max_resolution=args.physical_max_resolution,
                             train=not args.no_train,
                             train_steps=args.train_steps)
    result = run_bench(settings, log=lambda line: print(line, flush=True))
    written = write_outputs(result, out)
    print("wrote:")
    for p in [written["json"], written["markdown"], *written["plots"]]:
        print(f"  {p}")
    if args.doc is not None:
        print(f"  {write_doc(result, Path(args.doc), written['plots'])}")
    return 0


def _add_bench(sub: "argparse._SubParsersAction") -> None:
    from .bench import RESOLUTIONS

    p = sub.add_parser(
        "bench", help="measure the renderers' speed/accuracy trade (JSON, Markdown, Pareto plots)",
        description="Time (forward, forward+backward), memory, image and gradient error against a "
                    "converged reference, and a memory-traffic bound, for the closed form, the ray "
                    "marcher's default and one option varied at a time, and for EA the plain layer, the "
                    "authors' EA layer and the path tracer; plus training images/s per renderer. Writes "
                    "OUT/bench.json, OUT/bench.md and OUT/pareto_<model>_<N>.png; with --doc, also the "
                    "generated section of that Markdown file (docs/speed_accuracy.md).")
    p.add_argument("--resolutions", type=int, nargs="+", default=[32, 64], choices=RESOLUTIONS, metavar="N",
                   help=f"volume resolutions, among {', '.join(map(str, RESOLUTIONS))} (default: 32 64)")
    p.add_argument("--batch", type=_positive_int, default=8, help="random views per call (default: %(default)s)")
    p.add_argument("--repeats", type=_positive_int, default=3,
                   help="timed calls after one warm-up; the best counts (default: %(default)s)")
    p.add_argument("--threads", type=_positive_int, default=None,
                   help="torch and Dr.Jit threads (default: leave them as they are: all cores)")
    p.add_argument("--models", default="vh,ao,ea", help="comma-separated models (default: %(default)s)")
    p.add_argument("--volume", choices=("figure", "cloud"), default="figure",
                   help="built-in test volume (default: %(default)s)")
    p.add_argument("--seed", type=_non_negative_int, default=0,
                   help="seed of the views, the loss weights and the path tracer (default: %(default)s)")
    p.add_argument("--physical-ref-spp", type=_positive_int, default=32,
                   help="spp of the path tracer's own reference (default: %(default)s)")
    p.add_argument("--train-steps", type=_positive_int, default=5,
                   help="timed training steps per renderer, after 2 warm-up steps (default: %(default)s)")
    p.add_argument("--no-train", action="store_true", help="skip the training-speed measurement")
    p.add_argument("--no-physical", action="store_true",
                   help="skip the path-tracer rows (most of a run's time at 64³ and above)")
    p.add_argument("--physical-max-resolution", type=_positive_int, default=64, metavar="N",
                   help="measure the path tracer only up to N³ (default: %(default)s; at 128³ its rows take "
                        "most of an hour on 2 cores)")
    p.add_argument("--quick", action="store_true",
                   help="a reduced set: the smallest resolution, fewer configurations, one timed call, "
                        "path tracer at spp 1 only, one training step (seconds at 16³, batch 2)")
    p.add_argument("--out", default="bench", help="output folder (default: %(default)s/)")
    p.add_argument("--doc", default=None,
                   help="also rewrite the generated section of this Markdown file, e.g. docs/speed_accuracy.md, "
                        "and copy the plots next to it")
    p.set_defaults(handler=_cmd_bench)


# --------------------------------------------------------------------------- make-dataset


def _elevation(text: str):
    """'30' → 30.0 (a ring); '0,60' → (0.0, 60.0) (a band)."""
    try:
        parts = [float(x) for x in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number or 'low,high' in degrees, got {text!r}") from None
    if len(parts) == 1:
        return parts[0]
    if len(parts) == 2:
        return tuple(parts)
    raise argparse.ArgumentTypeError(f"expected a number or 'low,high' in degrees, got {text!r}")


#: make-dataset's flags of the physical formation alone, and their defaults (None: not given).
_PHYSICAL_FLAGS = {"lighting": ("--lighting", "sunsky"), "spp": ("--spp", 32), "max_depth": ("--max-depth", 8)}


def _check_dataset_flags(args: argparse.Namespace) -> None:
    """Refuse the flags the chosen formation or view distribution would ignore; fill in the defaults."""
    given = [flag for key, (flag, _) in _PHYSICAL_FLAGS.items() if getattr(args, key) is not None]
    if given and args.formation != "physical":
        raise CLIError(f"{', '.join(given)}: only --formation physical reads {'them' if len(given) > 1 else 'it'}, "
                       f"and --formation {args.formation} would ignore {'them' if len(given) > 1 else 'it'}; "
                       f"drop {'them' if len(given) > 1 else 'it'} or use --formation physical")
    for key, (_, default) in _PHYSICAL_FLAGS.items():
        if getattr(args, key) is None:
            setattr(args, key, default)
    if args.elevation is not None and args.view_dist == "sphere":
        raise CLIError("--elevation: --view-dist sphere covers every elevation and would ignore it; drop it, or "
                       "use --view-dist band (low,high) or ring (one number)")


def _cmd_make_dataset(args: argparse.Namespace) -> int:
    from .data import shapes
    from .data.collection import CollectionSpec, check_envmap, default_envmaps, make_collection
    from .data.preview import contact_sheet

    known = shapes.list_classes()
    classes = known if args.shape_class == "all" else [c.strip() for c in args.shape_class.split(",")]
    for c in classes:
        if c not in known:
            raise CLIError(f"unknown shape class {c!r}; known: {', '.join(known)} (or 'all')")
    _check_dataset_flags(args)
    out = Path(args.out)
    if args.preview:
        for c in classes:
            path = contact_sheet(c, out / f"preview_{c}.png", n_shapes=args.preview_shapes,
                                 resolution=args.resolution, seed=args.seed)
            print(f"wrote {path}")
        return 0
    for path in args.envmap or ():                          # named on the command line: checked even if unused
        check_envmap(path, what="--envmap")
    envmaps = tuple(args.envmap) if args.envmap else tuple(default_envmaps())
    for c in classes:
        spec = CollectionSpec(
            shape_class=c, n_shapes=args.shapes, views_per_shape=args.views, resolution=args.resolution,
            formation=args.formation, renderer=args.renderer, filter=args.filter, views=args.view_dist,
            elevation=args.elevation, lighting=args.lighting,
            envmaps=envmaps if (args.formation == "physical" and args.lighting != "sunsky") else (),
            spp=args.spp, max_depth=args.max_depth, camera=args.camera, fov=args.fov,
            distance=args.distance, seed=args.seed)
        folder = out / c if len(classes) > 1 or args.class_subfolder else out
        manifest = make_collection(folder, spec, overwrite=args.overwrite, progress=not args.quiet)
        print(f"{c}: {spec.n_shapes * spec.views_per_shape} images in {folder} (manifest: {manifest})")
    return 0


def _add_make_dataset(sub: "argparse._SubParsersAction") -> None:
    from .data.collection import FORMATIONS
    from .render.settings import RenderSettings
    from .views import DEFAULT_ELEVATION, DISTRIBUTIONS

    p = sub.add_parser(
        "make-dataset", help="render a procedural shape class to an image collection",
        description="Render SHAPES shapes × VIEWS random views of a procedural class in one image "
                    "formation (vh, ao, ea with either renderer, or physically based under natural "
                    "light). Writes sRGB PNGs with alpha, linear EXRs, ground-truth volumes (.npz, "
                    ".vol) and a manifest. Re-running resumes a half-written collection. With "
                    "--preview, writes a contact sheet per class instead.")
    p.add_argument("--class", dest="shape_class", default="all",
                   help="shape class, comma-separated classes, or 'all' (default: %(default)s)")
    p.add_argument("--shapes", type=_positive_int, default=100, help="shapes per class (default: %(default)s)")
    p.add_argument("--views", type=_positive_int, default=10, help="images per shape (default: %(default)s)")
    p.add_argument("--resolution", type=_positive_int, default=64, help="N, 16 … 128 (default: %(default)s)")
    p.add_argument("--formation", choices=FORMATIONS, default="ea",
                   help="image formation (default: %(default)s)")
    p.add_argument("--renderer", choices=("closed_form", "mitsuba"), default="closed_form",
                   help="renderer for vh/ao/ea (default: %(default)s)")
    p.add_argument("--filter", choices=("trilinear", "nearest"), default="trilinear")
    p.add_argument("--view-dist", choices=DISTRIBUTIONS, default="sphere",
                   help="view distribution (default: %(default)s)")
    p.add_argument("--elevation", type=_elevation, default=None,
                   help="'low,high' degrees for band (default {:g},{:g}); one number for ring (default {:g})"
                   .format(*DEFAULT_ELEVATION["band"], DEFAULT_ELEVATION["ring"]))
    p.add_argument("--lighting", choices=("sunsky", "envmap", "mixed"), default=None,
                   help="physical formation only: random sky, environment map, or either (default: sunsky)")
    p.add_argument("--envmap", action="append", default=None,
                   help="an environment map .exr (repeatable; default: scenes/envmaps/*.exr)")
    p.add_argument("--spp", type=_positive_int, default=None,
                   help="physical formation only: samples per pixel (default: 32)")
    p.add_argument("--max-depth", type=_positive_int, default=None,
                   help="physical formation only: longest path (default: 8)")
    p.add_argument("--camera", choices=("orthographic", "perspective"), default="orthographic",
                   help="vh/ao/ea images: the camera (default: %(default)s)")
    p.add_argument("--fov", type=_positive_float, default=RenderSettings.fov,
                   help="perspective: full field of view in degrees (default: %(default)s)")
    p.add_argument("--distance", type=_positive_float, default=None,
                   help="perspective: camera distance from the centre, > 1 (default: 1 / tan(fov/2))")
    p.add_argument("--seed", type=_non_negative_int, default=0, help="master seed (default: %(default)s)")
    p.add_argument("--out", default="data", help="output folder (default: %(default)s/)")
    p.add_argument("--class-subfolder", action="store_true",
                   help="write one class into OUT/CLASS (always done for several classes)")
    p.add_argument("--overwrite", action="store_true", help="start over instead of resuming")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--preview", action="store_true",
                   help="write a contact sheet per class (shapes × 8 views) instead of a collection")
    p.add_argument("--preview-shapes", type=_positive_int, default=4,
                   help="shapes per contact sheet (default: %(default)s)")
    p.set_defaults(handler=_cmd_make_dataset)


# --------------------------------------------------------------------------- train / reconstruct / generate


def _cmd_train(args: argparse.Namespace) -> int:
    from .config import load_config
    from .train import train

    cfg = load_config(args.config, args.set or ())
    config_file = Path(args.config) if args.config else None
    run_dir = train(cfg, resume=args.resume, progress=not args.quiet, config_file=config_file)
    if int(os.environ.get("RANK", "0")) == 0:             # one line, not one per torchrun process
        print(f"run: {run_dir}")
    return 0


def _add_train(sub: "argparse._SubParsersAction") -> None:
    p = sub.add_parser("train", help="train PlatonicGAN from a config",
                       description="Train with a YAML config (configs/*.yaml); every key can be overridden "
                                   "with --set section.key=value. Writes a run folder with the resolved "
                                   "config, checkpoints, logs and samples (only into a new or empty folder or one of "
                                   "its own runs; the --config file is never written). Ctrl-C saves a checkpoint "
                                   "and exits with code 130; "
                                   "--resume continues exactly. Data parallel: torchrun --nproc-per-node N "
                                   "-m mitsuba_platonic.cli train ...")
    p.add_argument("--config", default=None,
                   help="YAML config: a file, or a packaged config's name (e.g. paper, or configs/paper.yaml "
                        "where no such file is here) (default: the built-in defaults)")
    p.add_argument("--set", action="append", metavar="KEY=VALUE", help="override a config key (repeatable)")
    p.add_argument("--resume", action="store_true", help="continue the run from its last checkpoint")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(handler=_cmd_train)


def _interrupted_export(command: str, written: List[Path], out: Path, detail: str) -> Interrupted:
    """The one line of a Ctrl-C in reconstruct/generate: how many files are on disk, and how to go on."""
    return Interrupted(f"{len(written)} complete file(s) written to {out} ({detail}); each file is whole; "
                       f"run the command again with --overwrite (or another --out) to redo them",
                       saved=f"{len(written)} file(s) in {out}")


def _cmd_reconstruct(args: argparse.Namespace) -> int:
    from .export import export_reconstructions
    from .model import Model

    model = Model.from_checkpoint(args.run)
    out = Path(args.out) if args.out else Path(args.run) / "reconstructions"
    written: List[Path] = []
    done_inputs = 0
    try:
        for path, done in export_reconstructions(model, args.images, out, background=args.background, crop=args.crop,
                                                 level=args.level, overwrite=args.overwrite, written=written):
            done_inputs += 1
            if done.no_mesh:
                print(f"{path}: no mesh: {done.no_mesh}", file=sys.stderr)
            print(f"{path} → " + ", ".join(str(p) for p in done.paths))
    except KeyboardInterrupt:
        raise _interrupted_export("reconstruct", written, out,
                                  f"{done_inputs} of {len(args.images)} input(s) finished") from None
    return 0


def _add_reconstruct(sub: "argparse._SubParsersAction") -> None:
    from .data.photos import CROPS

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
    p.add_argument("--background", choices=("white",), default=None, help="mask RGB photos on white")
    p.add_argument("--crop", choices=CROPS, default="image")
    p.add_argument("--level", type=float, default=0.5, help="iso-level of the mesh (default: %(default)s)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace the files of the same names an earlier call wrote into --out")
    p.set_defaults(handler=_cmd_reconstruct)


def _cmd_generate(args: argparse.Namespace) -> int:
    from .export import export_samples
    from .model import Model

    model = Model.from_checkpoint(args.run)
    out = Path(args.out) if args.out else Path(args.run) / "generated"
    written: List[Path] = []
    try:
        export_samples(model, args.n, out, seed=args.seed, overwrite=args.overwrite, written=written)
    except KeyboardInterrupt:
        samples = len({p.stem for p in written if p.name.startswith("sample_")})
        raise _interrupted_export("generate", written, out, f"{samples} of {args.n} sample(s) begun, "
                                                              f"samples.png not written") from None
    print(f"{args.n} volumes (step {model.step}) → {out} (samples.png: one row per sample, 4 views)")
    return 0


def _add_generate(sub: "argparse._SubParsersAction") -> None:
    p = sub.add_parser("generate", help="sample volumes from a trained generator",
                       description="Draw z ~ N(0, I), generate volumes, write sample_000.npz/.vol/.gif, … and a "
                                   "samples.png overview into --out. A folder holding an earlier call's samples "
                                   "is refused unless --overwrite, which deletes them first.")
    p.add_argument("--run", required=True, help="a run folder")
    p.add_argument("-n", type=_positive_int, default=16, help="number of samples (default: %(default)s)")
    p.add_argument("--seed", type=_non_negative_int, default=0)
    p.add_argument("--out", default=None, help="output folder (default: RUN/generated)")
    p.add_argument("--overwrite", action="store_true",
                   help="delete an earlier call's sample_* files and samples.png in --out first")
    p.set_defaults(handler=_cmd_generate)


def _cmd_quickstart(args: argparse.Namespace) -> int:
    if args.photos is not None:
        from .photo_quickstart import photo_quickstart

        report = photo_quickstart(Path(args.photos), Path(args.out or "quickstart-photos"), steps=args.steps,
                                  progress=not args.quiet, overrides=args.set or ())
    else:
        from .quickstart import quickstart

        report = quickstart(Path(args.out or "quickstart"), steps=args.steps, progress=not args.quiet,
                            overrides=args.set or ())
    print(report.read_text())
    print(f"report: {report}")
    return 0


def _add_quickstart(sub: "argparse._SubParsersAction") -> None:
    p = sub.add_parser("quickstart", help="the whole pipeline on a small procedural collection, or on your photos "
                                          "(--photos DIR) (CPU, minutes)",
                       description="Generate a small procedural collection, train single-image reconstruction "
                                   "at 32³ through the batched Mitsuba ray marcher (EA), reconstruct held-out images and "
                                   "write turntables, meshes and a report. With --photos DIR: train on your folder of "
                                   "cut-out photos instead and judge the held-out photos' reconstructions from every "
                                   "side.")
    p.add_argument("--photos", default=None, metavar="DIR",
                   help="train on your own folder of cut-out photos of one class instead (configs/photos.yaml), and "
                        "judge the held-out photos' reconstructions from every side")
    p.add_argument("--out", default=None,
                   help="output folder (default: quickstart/, or quickstart-photos/ with --photos)")
    p.add_argument("--steps", type=_positive_int, default=None, help="training steps (default: the config's)")
    p.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a key of configs/quickstart.yaml (configs/photos.yaml with --photos), e.g. "
                        "model.resolution=16 (repeatable)")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(handler=_cmd_quickstart)


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from .evaluate.report import run
    return run(args)


def _add_evaluate(sub: "argparse._SubParsersAction") -> None:
    from .evaluate.report import add_arguments
    p = sub.add_parser("evaluate", help="score trained runs as in the paper's Table 2 (docs/evaluation.md)",
                       description="Re-render held-out reconstructions and their ground truth (IF, VOL, ISO, "
                                   "VOX) under random skies, compare in 2D and 3D, and write report.md, "
                                   "figures and results.json. Runs trained on a photo folder get a real-photo "
                                   "section instead: held-out photos at the input view, novel views, front-card "
                                   "check.")
    add_arguments(p)
    p.set_defaults(handler=_cmd_evaluate)


def _cmd_convert_checkpoint(args: argparse.Namespace) -> int:
    from .checkpoint import convert_checkpoint

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
    from .checkpoint import checkpoint_files

    files: List[Path] = []
    for path in paths:
        if path.is_file():
            files.append(path)
        elif path.is_dir() and checkpoint_files(path / "checkpoints"):
            files += [p for p in checkpoint_files(path / "checkpoints") if p.is_file()]
        else:
            raise CLIError(f"{path} is neither a checkpoint file nor a run folder with checkpoints/*.pt")
    return files


def _add_convert_checkpoint(sub: "argparse._SubParsersAction") -> None:
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


# --------------------------------------------------------------------------- entry point

#: Subcommand registrars, in help order. Add ``_add_<command>`` functions here.
SUBCOMMANDS: Sequence[Callable[["argparse._SubParsersAction"], None]] = (
    _add_quickstart, _add_train, _add_reconstruct, _add_generate, _add_evaluate, _add_make_dataset, _add_compare,
    _add_bench, _add_convert_checkpoint)


def build_parser() -> argparse.ArgumentParser:
    """The ``platonic`` parser with one subparser per subcommand."""
    from . import __version__

    parser = argparse.ArgumentParser(
        prog=PROG, description="PlatonicGAN with closed-form and Mitsuba 3 rendering layers.")
    parser.add_argument("--version", action="version", version=f"{PROG} {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for add in SUBCOMMANDS:
        add(sub)
    return parser


#: What a Ctrl-C leaves, per command, where the command itself said nothing more precise.
_INTERRUPTED = {
    None: "while starting; nothing was written",
    "quickstart": "nothing was written beyond what the folder held; run the same command again to continue",
    "train": "no training step was saved beyond the run's last checkpoint, which is as it was; run the same "
             "command again (with --resume if the run has a checkpoint)",
    "reconstruct": "nothing was written; run the same command again",
    "generate": "nothing was written; run the same command again",
    "evaluate": "no report was written (report.md, results.json and the figures come at the end); run the same "
                "command again",
    "make-dataset": "the images already written are kept (each file whole); run the same command again to resume",
    "compare": "the files already in --out are whole, compare.json (written last) is missing; run the same "
               "command again",
    "bench": "nothing was written (the results are written at the end); run the same command again",
}


def _interrupt_message(command: Optional[str], e: BaseException) -> str:
    """The one line of a Ctrl-C: the command's own account (an :class:`Interrupted`), else :data:`_INTERRUPTED`."""
    where = f"{PROG} {command}" if command else PROG
    detail = str(e) if isinstance(e, Interrupted) and str(e) else _INTERRUPTED.get(command, _INTERRUPTED[None])
    return f"{where}: interrupted: {_one_line(detail)}"


def _one_line(text: str) -> str:
    return " ".join(part.strip() for part in str(text).splitlines() if part.strip())


def _interrupt_behind(e: BaseException) -> Optional[KeyboardInterrupt]:
    """The ``KeyboardInterrupt`` ``e`` is or was raised from (Dr.Jit re-raises a Ctrl-C in its
    callbacks as its own error, the interrupt only in the chain), if any."""
    from .fileio import _interrupt_behind as behind
    return behind(e)


def _printable_streams() -> None:
    """Make stdout and stderr print any text (help and messages hold ³, →, …): characters the
    terminal's encoding lacks (PYTHONIOENCODING=ascii) are escaped instead of raising."""
    for stream in (sys.stdout, sys.stderr):
        if hasattr(stream, "reconfigure"):
            try:
                stream.reconfigure(errors="backslashreplace")
            except (ValueError, OSError):
                pass


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run ``platonic`` with ``argv`` (default ``sys.argv[1:]``); return the exit code.

    Usage errors (argparse) and user errors (:class:`~mitsuba_platonic.errors.UserError`,
    ``BackendError``, and ``OSError``: a missing file, no permission, a full disk) print a
    one-line message on stderr and return 2; Ctrl-C, at any moment (numpy and torch load in
    here, where it is caught), prints one line on stderr saying what was saved and how to go on
    and returns 130; ``--help`` and ``--version`` return 0. Any other exception is a bug: it
    propagates with its traceback. A warning (a skipped photo, a checkpoint fallen back from) is
    one line, ``platonic <command>: warning: …``, not Python's file-and-source-line format.
    """
    _printable_streams()
    command: Optional[str] = None
    try:
        parser = build_parser()
        try:
            args = parser.parse_args(argv)
        except SystemExit as e:  # argparse has printed usage / help already
            return int(e.code) if isinstance(e.code, int) else 2
        command = args.command
        return _run(args)
    except KeyboardInterrupt as e:
        print(_interrupt_message(command, e), file=sys.stderr)
        return 130
    except (UserError, BackendError, OSError) as e:
        print(f"{PROG} {command}: error: {_one_line(e)}", file=sys.stderr)
        return 2
    except Exception as e:
        interrupt = _interrupt_behind(e)
        if interrupt is None:
            raise
        print(_interrupt_message(command, interrupt), file=sys.stderr)
        return 130


def _run(args: argparse.Namespace) -> int:
    """Call ``args.handler`` with warnings shown as one line each."""
    def one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
        print(f"{PROG} {args.command}: warning: {message}", file=sys.stderr if file is None else file)

    with warnings.catch_warnings():                          # restores Python's own display afterwards
        warnings.showwarning = one_line_warning
        return int(args.handler(args))


if __name__ == "__main__":
    sys.exit(main())
