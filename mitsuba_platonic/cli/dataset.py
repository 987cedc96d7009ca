"""``platonic make-dataset``: a procedural shape class rendered to an image collection
(:func:`mitsuba_platonic.data.render_collection.make_collection` per class), or contact sheets with
``--preview``."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Tuple, Union

from ..files.fileio import confined
from ..files.outputs import output_lock
from .args import CLIError, positive_float, positive_int, seed

__all__ = ["add_make_dataset"]

def _elevation(text: str) -> Union[float, Tuple[float, float]]:
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
    if args.renderer is not None and args.formation == "physical":
        raise CLIError(f"--renderer {args.renderer}: --formation physical always path-traces with Mitsuba and "
                       f"would ignore it; drop it, or use --formation vh, ao or ea")
    args.renderer = args.renderer or "closed_form"
    lens = [flag for flag, value in (("--fov", args.fov), ("--distance", args.distance)) if value is not None]
    if lens and args.camera != "perspective":
        raise CLIError(f"{', '.join(lens)}: only --camera perspective reads {'them' if len(lens) > 1 else 'it'}, "
                       f"and --camera {args.camera} would ignore {'them' if len(lens) > 1 else 'it'}; drop "
                       f"{'them' if len(lens) > 1 else 'it'} or add --camera perspective")
    if args.fov is None:
        from ..render.settings import RenderSettings
        args.fov = RenderSettings.fov
    if args.elevation is not None and args.view_dist == "sphere":
        raise CLIError("--elevation: --view-dist sphere covers every elevation and would ignore it; drop it, or "
                       "use --view-dist band or sides (low,high) or ring (one number)")
    if args.side_width is not None and args.view_dist != "sides":
        raise CLIError(f"--side-width: only --view-dist sides reads it, and --view-dist {args.view_dist} would "
                       f"ignore it; drop it or use --view-dist sides")


def _cmd_make_dataset(args: argparse.Namespace) -> int:
    from ..data import shapes
    from ..data.render_collection import CollectionSpec, check_collection_fits, make_collection, recorded_images
    from ..data.envmaps import check_envmap, default_envmaps
    from ..data.preview import contact_sheet

    known = shapes.list_classes()
    classes = known if args.shape_class == "all" else [c.strip() for c in args.shape_class.split(",")]
    for c in classes:
        if c not in known:
            raise CLIError(f"unknown shape class {c!r}; known: {', '.join(known)} (or 'all')")
    _check_dataset_flags(args)
    out = Path(args.out)
    if args.preview:
        with confined(out), output_lock(out, "make-dataset"):   # no sheet written through a link; one command at a time
            for c in classes:
                path = contact_sheet(c, out / f"preview_{c}.png", n_shapes=args.preview_shapes,
                                     resolution=args.resolution, seed=args.seed)
                print(f"wrote {path}")
        return 0
    for path in args.envmap or ():                          # named on the command line: checked even if unused
        check_envmap(path, what="--envmap")
    envmaps = tuple(args.envmap) if args.envmap else tuple(default_envmaps())
    specs = []
    for c in classes:
        specs.append(CollectionSpec(
            shape_class=c, n_shapes=args.shapes, views_per_shape=args.views, resolution=args.resolution,
            formation=args.formation, renderer=args.renderer, filter=args.filter, views=args.view_dist,
            elevation=args.elevation, side_width=args.side_width, lighting=args.lighting,
            envmaps=envmaps if (args.formation == "physical" and args.lighting != "sunsky") else (),
            spp=args.spp, max_depth=args.max_depth, camera=args.camera, fov=args.fov,
            distance=args.distance, seed=args.seed))
    specs[0].validate()
    folders = [out / c if len(classes) > 1 or args.class_subfolder else out for c in classes]
    done = 0 if args.overwrite else sum(recorded_images(folder) for folder in folders)   # a resume's images are there
    check_collection_fits(specs[0], out, classes=len(specs), names=("--shapes", "--views"), done=done)
    for c, spec, folder in zip(classes, specs, folders):
        manifest = make_collection(folder, spec, overwrite=args.overwrite, progress=not args.quiet)
        print(f"{c}: {spec.n_shapes * spec.views_per_shape} images in {folder} (manifest: {manifest})")
    return 0


def add_make_dataset(sub: "argparse._SubParsersAction") -> None:
    from ..data.collection_spec import RENDERERS
    from ..render.settings import CAMERAS, FILTERS, FORMATIONS, LIGHTINGS, RenderSettings
    from ..views import COLLECTION_DISTRIBUTIONS, DEFAULT_ELEVATION, DEFAULT_SIDE_WIDTH

    p = sub.add_parser(
        "make-dataset", help="render a procedural shape class to an image collection",
        description="Render SHAPES shapes × VIEWS random views of a procedural class in one image "
                    "formation (vh, ao, ea with either renderer, or physically based under natural "
                    "light). Writes sRGB PNGs with alpha, linear EXRs, ground-truth volumes (.npz, "
                    ".vol) and a manifest. Re-running resumes a half-written collection. With "
                    "--preview, writes a contact sheet per class instead.")
    p.add_argument("--class", dest="shape_class", default="all",
                   help="shape class, comma-separated classes, or 'all' (default: %(default)s)")
    p.add_argument("--shapes", type=positive_int, default=100, help="shapes per class (default: %(default)s)")
    p.add_argument("--views", type=positive_int, default=10, help="images per shape (default: %(default)s)")
    p.add_argument("--resolution", type=positive_int, default=64, help="N, 16 … 128 (default: %(default)s)")
    p.add_argument("--formation", choices=FORMATIONS, default="ea",
                   help="image formation (default: %(default)s)")
    p.add_argument("--renderer", choices=RENDERERS, default=None,
                   help="renderer for vh/ao/ea (default: closed_form)")
    p.add_argument("--filter", choices=FILTERS, default="trilinear")
    p.add_argument("--view-dist", choices=COLLECTION_DISTRIBUTIONS, default="sphere",
                   help="view distribution: sides = azimuths within ±SIDE_WIDTH of the side views ±90° "
                        "(which see an animal's or a vehicle's length broadside), elevations as band's "
                        "(default: %(default)s)")
    p.add_argument("--elevation", type=_elevation, default=None,
                   help="'low,high' degrees for band and sides (default {:g},{:g}); one number for ring "
                        "(default {:g})".format(*DEFAULT_ELEVATION["band"], DEFAULT_ELEVATION["ring"]))
    p.add_argument("--side-width", type=positive_float, default=None,
                   help="sides only: W, the half-width of the azimuth windows in degrees, 0 < W <= 90 "
                        "(default: {:g})".format(DEFAULT_SIDE_WIDTH))
    p.add_argument("--lighting", choices=LIGHTINGS, default=None,
                   help="physical formation only: random sky, environment map, or either (default: sunsky)")
    p.add_argument("--envmap", action="append", default=None,
                   help="an environment map .exr (repeatable; default: scenes/envmaps/*.exr)")
    p.add_argument("--spp", type=positive_int, default=None,
                   help="physical formation only: samples per pixel (default: 32)")
    p.add_argument("--max-depth", type=positive_int, default=None,
                   help="physical formation only: longest path (default: 8)")
    p.add_argument("--camera", choices=CAMERAS, default="orthographic",
                   help="vh/ao/ea images: the camera (default: %(default)s)")
    p.add_argument("--fov", type=positive_float, default=None,
                   help="perspective: full field of view in degrees (default: {:g})".format(RenderSettings.fov))
    p.add_argument("--distance", type=positive_float, default=None,
                   help="perspective: camera distance from the centre, > 1 (default: 1 / tan(fov/2))")
    p.add_argument("--seed", type=seed, default=0, help="master seed (default: %(default)s)")
    p.add_argument("--out", default="data", help="output folder (default: %(default)s/)")
    p.add_argument("--class-subfolder", action="store_true",
                   help="write one class into OUT/CLASS (always done for several classes)")
    p.add_argument("--overwrite", action="store_true", help="start over instead of resuming")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--preview", action="store_true",
                   help="write a contact sheet per class (shapes × 8 views) instead of a collection")
    p.add_argument("--preview-shapes", type=positive_int, default=4,
                   help="shapes per contact sheet (default: %(default)s)")
    p.set_defaults(handler=_cmd_make_dataset,
                   interrupted="the images already written are kept (each file whole); run the same command "
                               "again to resume")
