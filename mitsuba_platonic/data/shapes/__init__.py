"""Procedural shape classes with 3D ground truth: RGBA volumes for training and evaluation.

Every class generates, from an integer seed, one member of an object class as a float32
``(4, N, N, N)`` volume ``[r, g, b, density]`` in [0, 1] in the layout of
:mod:`mitsuba_platonic.volume` (+y up, the object facing +z, the front camera)::

    from mitsuba_platonic.data import shapes
    shapes.list_classes()          # ['airplane', 'animal', 'chair', 'lathe', 'mushroom', 'tree']
    vol = shapes.generate("chair", seed=3, n=64)  # (4, 64, 64, 64), deterministic per (name, seed, n)

Shapes are centred (their bounding box at the origin) and scaled to fit the ball of radius
0.82, so no view clips them: density is exactly 0 beyond radius 0.82 + 1.25 Δ (voxel size
Δ = 2 / N). Thin parts are kept at least 1.5 voxels thick at every N, so they never vanish
at N = 16.

Built-in classes (one module each): ``airplane``, ``animal`` (four-legged), ``chair``, ``lathe``
(vases, goblets, bottles, barrels), ``mushroom``, ``tree``.

Orientation: every class faces +z, the front camera at azimuth 0° (:mod:`mitsuba_platonic.views`),
and a class with a length (the airplane's fuselage, the animal's body) lays it along z. So the *side
views* at azimuth ±90° (:data:`~mitsuba_platonic.views.SIDE_AZIMUTHS`) see that length broadside for
every class, and a collection photographed mostly from the sides (``views: sides``) needs no
per-class axis; a round class (lathe, mushroom, tree) has no preferred one, and the same ±90° apply.

Adding a class
--------------
Write one file that builds the shape from :class:`~.sdf.Part` s and registers itself::

    # my_shapes/table.py
    from mitsuba_platonic.data.shapes import register
    from mitsuba_platonic.data.shapes.sdf import box_part, composite

    @register("table")
    def table(rng, n):
        w, d, h = rng.uniform(0.8, 1.2), rng.uniform(0.5, 0.9), rng.uniform(0.6, 0.9)
        wood = tuple(rng.uniform([0.4, 0.2, 0.08], [0.7, 0.45, 0.2]))
        parts = [box_part((0, h, 0), (w, 0.04, d), wood)]
        parts += [box_part((sx * (w - 0.08), h / 2, sz * (d - 0.08)), (0.04, h / 2, 0.04), wood)
                  for sx in (-1, 1) for sz in (-1, 1)]
        return composite(parts, n)     # or simply: return parts

Importing the file registers the class (``import my_shapes.table``); after that
``generate("table", seed, n)`` works like the built-ins. To make it built in, put the file in
this package and add its module name to ``BUILTIN_CLASSES`` below. Draw every random number
from ``rng`` and never let the draws depend on ``n``, so a seed is the same object at every
resolution. :func:`registered` registers a class for the duration of a ``with`` block (tests).
"""

from __future__ import annotations

import importlib

from . import sdf
from .registry import (MAX_RESOLUTION, MIN_RESOLUTION, generate, get_class, list_classes,
                       register, registered, unregister)

__all__ = ["generate", "list_classes", "get_class", "register", "unregister", "registered",
           "sdf", "BUILTIN_CLASSES", "MIN_RESOLUTION", "MAX_RESOLUTION"]

#: Modules of this package that define (and register) the built-in classes.
BUILTIN_CLASSES = ("airplane", "animal", "chair", "lathe", "mushroom", "tree")

for _module in BUILTIN_CLASSES:
    importlib.import_module(f"{__name__}.{_module}")
del _module
