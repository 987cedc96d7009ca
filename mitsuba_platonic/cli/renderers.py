"""``platonic compare`` and ``platonic bench``: the renderers measured against each other.

- ``compare``: render a volume with the closed-form layers and the Mitsuba ray marcher from a
  few views and report how far apart and how fast they are (:mod:`mitsuba_platonic.bench.compare`);
  with ``--light``, single scattering against Mitsuba's volpath (:mod:`mitsuba_platonic.bench.compare_light`).
- ``bench``: the renderers' speed/accuracy trade: times, memory, image and gradient errors,
  JSON, Markdown and Pareto plots (:mod:`mitsuba_platonic.bench`).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any, Dict, List, Tuple

from ..files.fileio import confined
from ..files.outputs import MARKER, check_output_folder, claim_output_folder, output_lock
from .args import CLIError, parse_models, positive_float, positive_int, resolution, seed

if TYPE_CHECKING:
    import torch

__all__ = ["add_compare", "add_bench"]

#: What compare writes into ``--out`` by fixed names (:func:`~mitsuba_platonic.files.fileio.confined`: none may be a link).
COMPARE_PARTS = (MARKER, "compare.json", "compare_light.json", "compare_light.png",
                 *(f"compare_{m}.png" for m in ("vh", "ao", "ea")))


def _earlier_comparison(out: Path) -> bool:
    """Whether ``out`` holds a comparison written before :data:`~mitsuba_platonic.files.outputs.MARKER`
    existed: a ``compare.json`` or ``compare_light.json`` with the keys compare writes."""
    for name, keys in (("compare.json", {"volume", "repeats", "view_vectors", "results"}),
                       ("compare_light.json", {"volume", "settings", "results"})):
        try:
            data = json.loads((out / name).read_text())
        except (OSError, ValueError):
            continue
        if isinstance(data, dict) and set(data) == keys:
            return True
    return False

#: compare's flags for the renderer settings they set (their errors name the flag).
_COMPARE_FLAGS = {"step": "--step", "spp": "--spp", "jitter": "--jitter", "filter": "--filter"}


def _check_compare_settings(args: argparse.Namespace) -> None:
    """The marcher's settings from compare's flags, checked by the renderer before any work."""
    from ..render.settings import RenderSettings

    try:
        RenderSettings.for_call("mitsuba", "ea", filter=args.filter, step=args.step, spp=args.spp,
                                jitter=args.jitter)
    except ValueError as e:
        key, _, rest = str(e).partition(": ")
        if key in _COMPARE_FLAGS:
            raise CLIError(f"{_COMPARE_FLAGS[key]}: {rest}") from None
        raise CLIError(str(e)) from None


def _cmd_compare_light(args: argparse.Namespace, volume, views) -> int:
    """``--light``: single scattering (scatter_march) against volpath at depth 2, the extremes included."""
    if volume.shape[1] != 4:
        raise CLIError(f"--light: the volume needs colour ([r, g, b, density], C = 4), got C = {volume.shape[1]}")
    if args.jitter or args.step != 1.0 or args.filter != "trilinear":
        raise CLIError("--light: --step, --jitter and --filter set the EA marcher; single scattering marches "
                       "--steps-per-voxel samples per voxel with trilinear lookups")
    for flag, value, least in (("--steps-per-voxel", args.steps_per_voxel, 2), ("--ref-renders", args.ref_renders, 4)):
        if value < least:
            raise CLIError(f"{flag}: expected an int ≥ {least}, got {value}")
    if math.isqrt(args.spp) ** 2 != args.spp:
        raise CLIError(f"--spp: single scattering's rays per pixel: expected a square number (1, 4, 9, …), "
                       f"got {args.spp}")
    out = Path(args.out)
    with confined(out, COMPARE_PARTS), output_lock(out, "compare"):   # no link, one command at a time in --out
        claim_output_folder(out, "compare", args.overwrite, earlier=_earlier_comparison)
        return _compare_light_into(args, volume, views, out)


def _compare_light_into(args: argparse.Namespace, volume: "torch.Tensor", views: "torch.Tensor", out: Path) -> int:
    """``compare --light`` into the claimed, confined folder ``out``."""
    from ..bench.compare_light import BLOCK, compare_light, format_light_table, light_cases, light_figure, write_light_summary

    cases = light_cases(volume, views, seed=args.seed)
    results = compare_light(cases, spp=args.ref_spp, renders=args.ref_renders, steps_per_voxel=args.steps_per_voxel,
                            ours_spp=args.spp, seed=args.seed, repeats=args.repeats)
    n = volume.shape[-1]
    settings = {"steps_per_voxel": args.steps_per_voxel, "spp": args.spp, "ref_spp": args.ref_spp,
                "ref_renders": args.ref_renders, "seed": args.seed, "repeats": args.repeats}
    print(f"single scattering (scatter_march, {args.steps_per_voxel} samples per voxel, spp {args.spp}) vs "
          f"volpath at max_depth 2 ({args.ref_renders} renders of {args.ref_spp} spp): {args.volume} at {n}³, "
          f"exposure none; z per {BLOCK} × {BLOCK} block against the renders' standard error")
    print(format_light_table(results))
    png = light_figure(results, out / "compare_light.png",
                       f"{args.volume} at {n}³: scatter_march vs volpath (max_depth 2)")
    summary = write_light_summary(out / "compare_light.json", args.volume, settings, results)
    print(f"wrote:\n  {png}\n  {summary}")
    return 0


def _cmd_compare(args: argparse.Namespace) -> int:
    from ..bench.compare import check_memory, comparison_views
    from ..files.volume_io import BUILTIN_PREFIX, load_volume
    from ..runtime import budget

    if not args.light:
        _check_compare_settings(args)
    if args.volume.startswith(BUILTIN_PREFIX):              # before building it: refuse what cannot fit
        n = 32 if args.resolution is None else args.resolution
        check_memory(n, args.views, builtin=True,
                     what=f"--resolution {n}" if args.resolution is not None else f"--volume {args.volume}")
    volume = load_volume(args.volume, args.resolution, fits=budget.memory_check("use a smaller --volume"))
    if not args.volume.startswith(BUILTIN_PREFIX):
        check_memory(volume.shape[-1], args.views, what=f"--volume {args.volume}")
    if args.light:
        return _cmd_compare_light(args, volume, comparison_views(args.views, seed=args.seed))
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
    with confined(out, COMPARE_PARTS), output_lock(out, "compare"):   # no link, one command at a time in --out
        claim_output_folder(out, "compare", args.overwrite, earlier=_earlier_comparison)
        return _compare_into(args, volume, views, models, options, out)


def _compare_into(args: argparse.Namespace, volume: "torch.Tensor", views: "torch.Tensor", models: List[str],
                  options: Dict[str, Any], out: Path) -> int:
    """``compare`` into the claimed, confined folder ``out``."""
    from ..bench.compare import compare, format_table, write_summary

    results = compare(volume, views, models, filter=args.filter, options=options, out_dir=out,
                      repeats=args.repeats, progress=not args.quiet)

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


def add_compare(sub: "argparse._SubParsersAction") -> None:
    from ..render.settings import FILTERS

    p = sub.add_parser(
        "compare", help="compare the closed-form and Mitsuba renderers on one volume",
        description="Render a volume with the closed-form layers and the Mitsuba ray marcher from "
                    "the front view plus random views; print max/mean absolute differences and "
                    "forward times, write comparison figures (PNG) and the Mitsuba renders (EXR).")
    p.add_argument("--volume", default="builtin:figure",
                   help="builtin:figure | builtin:cloud | a .npz file with an array 'volume' of shape "
                        "(C,N,N,N) or (1,C,N,N,N), C = 4 [r,g,b,density] or 1 [density], values in "
                        "[0,1] (default: %(default)s)")
    p.add_argument("--resolution", type=resolution, default=None,
                   help="N ≥ 2 for built-in volumes (default 32); must match a file's N if given")
    p.add_argument("--models", default="vh,ao,ea", help="comma-separated models (default: %(default)s)")
    p.add_argument("--views", type=positive_int, default=4,
                   help="number of views: the front view, then random views (default: %(default)s)")
    p.add_argument("--filter", choices=FILTERS, default="trilinear",
                   help="volume lookups, both backends (default: %(default)s)")
    p.add_argument("--step", type=positive_float, default=1.0,
                   help="Mitsuba ray-marching step in voxels (default: %(default)s)")
    p.add_argument("--spp", type=positive_int, default=1,
                   help="Mitsuba samples per pixel; a perfect square unless --jitter (default: %(default)s)")
    p.add_argument("--jitter", action="store_true",
                   help="Mitsuba: random sub-pixel positions and sample depths")
    p.add_argument("--light", action="store_true",
                   help="compare single scattering under a sun and sky (the scatter_march backend) with "
                        "Mitsuba's volpath at max_depth 2 instead, the extremes included (opaque voxels, an "
                        "empty volume, suns at the horizon, behind the camera and behind the object, the sky "
                        "alone); writes compare_light.png and compare_light.json")
    p.add_argument("--steps-per-voxel", type=positive_int, default=2,
                   help="--light: single scattering's samples per voxel, ≥ 2 (default: %(default)s)")
    p.add_argument("--ref-spp", type=positive_int, default=128,
                   help="--light: volpath's samples per pixel per render (default: %(default)s)")
    p.add_argument("--ref-renders", type=positive_int, default=8,
                   help="--light: independent volpath renders, ≥ 4; their spread is the standard error "
                        "(default: %(default)s)")
    p.add_argument("--out", default="compare", help="output folder: new, empty or an earlier compare's "
                                                    "(default: %(default)s/)")
    p.add_argument("--overwrite", action="store_true",
                   help="write into an --out that holds files compare did not write, replacing those of its names "
                        "(compare.json, compare_*.png, mitsuba_*.exr, compare_light.*)")
    p.add_argument("--seed", type=seed, default=0,
                   help="seed of the random views and of Mitsuba's sampler (default: %(default)s)")
    p.add_argument("--repeats", type=positive_int, default=3,
                   help="timed runs per backend after one warm-up; the best counts (default: %(default)s)")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(handler=_cmd_compare,
                   interrupted="the files already in --out are whole, compare.json (written last) is missing; "
                               "run the same command again")


# --------------------------------------------------------------------------- bench


def bench_parts() -> Tuple[str, ...]:
    """What bench writes into ``--out`` by fixed names (:func:`~mitsuba_platonic.files.fileio.confined`:
    none may be a link): the marker, ``bench.json``, ``bench.md`` and every Pareto plot it can draw."""
    from ..bench import RESOLUTIONS
    from ..volume import MODELS

    return (MARKER, "bench.json", "bench.md", *(f"pareto_{m}_{n}.png" for m in MODELS for n in RESOLUTIONS))


def _earlier_bench(out: Path) -> bool:
    """Whether ``out`` holds a bench written before :data:`~mitsuba_platonic.files.outputs.MARKER`
    existed: a ``bench.json`` with the keys bench writes beside a ``bench.md`` that starts as its do."""
    try:
        data = json.loads((out / "bench.json").read_text())
        return (isinstance(data, dict) and set(data) == {"meta", "views", "rows", "train"}
                and (out / "bench.md").read_text().startswith("# platonic bench\n"))
    except (OSError, ValueError):
        return False


def _cmd_bench(args: argparse.Namespace) -> int:
    out = Path(args.out)
    with confined(out, bench_parts()), output_lock(out, "bench"):   # no link, one command at a time in --out
        check_output_folder(out, "bench", args.overwrite, earlier=_earlier_bench)   # before the run
        return _bench_into(args, out)


def _bench_into(args: argparse.Namespace, out: Path) -> int:
    """``bench`` into the confined, locked folder ``out``, checked already; marked before its results are written."""
    from ..bench import DOC_BEGIN, DOC_END, BenchSettings, run_bench, write_doc, write_outputs

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
    claim_output_folder(out, "bench", args.overwrite, earlier=_earlier_bench)
    written = write_outputs(result, out)
    print("wrote:")
    for p in [written["json"], written["markdown"], *written["plots"]]:
        print(f"  {p}")
    if args.doc is not None:
        print(f"  {write_doc(result, Path(args.doc), written['plots'])}")
    return 0


def add_bench(sub: "argparse._SubParsersAction") -> None:
    from ..bench import RESOLUTIONS
    from ..volume import TEST_VOLUMES

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
    p.add_argument("--batch", type=positive_int, default=8, help="random views per call (default: %(default)s)")
    p.add_argument("--repeats", type=positive_int, default=3,
                   help="timed calls after one warm-up; the best counts (default: %(default)s)")
    p.add_argument("--threads", type=positive_int, default=None,
                   help="torch and Dr.Jit threads (default: leave them as they are: all cores)")
    p.add_argument("--models", default="vh,ao,ea", help="comma-separated models (default: %(default)s)")
    p.add_argument("--volume", choices=tuple(TEST_VOLUMES), default="figure",
                   help="built-in test volume (default: %(default)s)")
    p.add_argument("--seed", type=seed, default=0,
                   help="seed of the views, the loss weights and the path tracer (default: %(default)s)")
    p.add_argument("--physical-ref-spp", type=positive_int, default=32,
                   help="spp of the path tracer's own reference (default: %(default)s)")
    p.add_argument("--train-steps", type=positive_int, default=5,
                   help="timed training steps per renderer, after 2 warm-up steps (default: %(default)s)")
    p.add_argument("--no-train", action="store_true", help="skip the training-speed measurement")
    p.add_argument("--no-physical", action="store_true",
                   help="skip the rows of light: the path tracer's and single scattering's (most of a run's time "
                        "at 64³ and above)")
    p.add_argument("--physical-max-resolution", type=positive_int, default=64, metavar="N",
                   help="measure the path tracer only up to N³ (default: %(default)s; at 128³ its rows take "
                        "most of an hour on 2 cores)")
    p.add_argument("--quick", action="store_true",
                   help="a reduced set: the smallest resolution, fewer configurations, one timed call, "
                        "path tracer at spp 1 only, one training step (seconds at 16³, batch 2)")
    p.add_argument("--out", default="bench", help="output folder: new, empty or an earlier bench's "
                                                  "(default: %(default)s/)")
    p.add_argument("--overwrite", action="store_true",
                   help="write into an --out that holds files bench did not write, replacing those of its names "
                        "(bench.json, bench.md, pareto_*.png)")
    p.add_argument("--doc", default=None,
                   help="also rewrite the generated section of this Markdown file, e.g. docs/speed_accuracy.md, "
                        "and copy the plots next to it")
    p.set_defaults(handler=_cmd_bench,
                   interrupted="nothing was written (the results are written at the end); run the same command "
                               "again")
