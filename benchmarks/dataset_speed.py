"""Benchmark: seconds per image of ``make-dataset`` per image formation, and the implied time of a
64³ × 1,000-image collection. Prints figures only.

    .venv/bin/python benchmarks/dataset_speed.py [--resolution 64] [--shapes 2] [--views 5] [--class chair]

Each configuration renders a fresh collection (shape generation, rendering, PNG/EXR/volume
writing: the whole job) into a temporary folder; seconds per image are wall time divided by
the number of images, and the 1,000-image figure multiplies that out.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from mitsuba_platonic.data import shapes
from mitsuba_platonic.data.render_collection import CollectionSpec, make_collection


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--resolution", type=int, default=64)
    ap.add_argument("--shapes", type=int, default=2)
    ap.add_argument("--views", type=int, default=5)
    ap.add_argument("--class", dest="shape_class", default=None)
    ap.add_argument("--spp", type=int, default=32)
    args = ap.parse_args()
    cls = args.shape_class or shapes.list_classes()[0]
    configs = [("vh", "closed_form"), ("ao", "closed_form"), ("ea", "closed_form"),
               ("vh", "mitsuba"), ("ao", "mitsuba"), ("ea", "mitsuba"), ("physical", "mitsuba")]
    n_images = args.shapes * args.views
    print(f"# make-dataset speed: class {cls}, {args.resolution}³, {n_images} images per configuration "
          f"(physical: {args.spp} spp, max_depth 8)")
    print(f"{'formation':<10} {'renderer':<12} {'s/image':>9} {'64³×1000 images':>16}")
    for formation, renderer in configs:
        spec = CollectionSpec(cls, n_shapes=args.shapes, views_per_shape=args.views, resolution=args.resolution,
                              formation=formation, renderer=renderer, spp=args.spp, seed=1)
        with tempfile.TemporaryDirectory() as tmp:
            # warm-up: compile kernels on a one-image collection first
            make_collection(Path(tmp) / "warm", CollectionSpec(cls, 1, 1, args.resolution, formation, renderer,
                                                              spp=args.spp), progress=False)
            t = time.perf_counter()
            make_collection(Path(tmp) / "c", spec, progress=False)
            per = (time.perf_counter() - t) / n_images
        total = per * 1000
        human = f"{total / 3600:.1f} h" if total > 5400 else f"{total / 60:.1f} min"
        print(f"{formation:<10} {renderer:<12} {per:>9.3f} {human:>16}")


if __name__ == "__main__":
    main()
