"""Rendered collections: a procedural shape class → an unstructured image collection with 3D truth.

``make_collection(out, spec)`` renders ``n_shapes`` shapes × ``views_per_shape`` images, each
from its own random view, in one image formation:

- ``vh`` / ``ao`` / ``ea``: the PlatonicGAN layers, with either renderer (closed form or Mitsuba);
- ``physical``: Mitsuba's volumetric path tracer on the same medium under random natural light
  (:mod:`mitsuba_platonic.render.physical`).

This module renders; the rest of a collection lives beside it and is re-exported here:
:mod:`.collection_spec` (:class:`CollectionSpec`, the plan every image derives from),
:mod:`.collection_files` (the folder's layout, records, manifest, what ``overwrite`` deletes, the
lock) and :mod:`.envmaps` (the environment maps physical collections are lit by).

Crash safety and resume: every file is written to a temporary name and renamed into place, and an
image counts as done only once its PNG, EXR and record line all exist. Re-running the same
command skips finished images and shapes, so a half-written collection is completed without
re-rendering what is done. Views, shape seeds and lighting derive from ``seed`` and the image's
index alone, so a resumed run renders exactly what an uninterrupted one would.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Tuple, Union

import numpy as np
import torch

from ..errors import Interrupted, UserError, raise_if_ctrl_c
from ..fileio import atomic_write, confined, make_folder, open_file, remove
from ..images import save_exr, save_png, to_hwc, to_png_rgba
from ..progress import progress_bar
from ..render import render
from ..render.physical import render_physical
from ..volume import CHANNELS
from ..volume_io import write_vol
from . import shapes
from .collection_files import (RECORDS, SUBFOLDERS, image_id, is_finished, load_manifest, lock, missing_files,
                               overwrite_plan, read_records, read_spec, remove_temporaries, temporaries, write_json)
from .collection_spec import FORMATIONS, RENDERERS, CollectionSpec
from .envmaps import check_envmap, default_envmaps

__all__ = ["CollectionSpec", "make_collection", "load_manifest", "FORMATIONS", "RENDERERS",
           "default_envmaps", "check_envmap", "image_id", "SUBFOLDERS", "RECORDS"]


def make_collection(out: Union[str, Path], spec: CollectionSpec, overwrite: bool = False,
                    progress: bool = True) -> Path:
    """Render (or finish rendering) the collection ``spec`` into ``out``; return the manifest path.

    A collection counts as finished only if its manifest matches ``spec`` and every file it plans
    (images, EXRs, volumes) is there; a missing file is made again (the same bytes: everything
    derives from ``spec``), and nothing else is re-rendered.

    Raises ``ValueError`` (:class:`~mitsuba_platonic.errors.UserError`) if ``out`` holds a collection
    made with a different spec (unless ``overwrite``, which starts it over), and with ``overwrite``
    if ``out`` holds files that no collection wrote there (nothing is deleted then).
    :class:`~mitsuba_platonic.errors.Interrupted` (a ``KeyboardInterrupt``) on Ctrl-C while
    rendering, saying how many images are saved (a re-run resumes).
    """
    spec.validate()
    out = Path(out)
    with confined(out, (".lock", *RECORDS, *SUBFOLDERS)):   # a link in the folder is refused before any work
        return _finish_collection(out, spec, overwrite, progress)


def _finish_collection(out: Path, spec: CollectionSpec, overwrite: bool, progress: bool) -> Path:
    """:func:`make_collection` in the confined folder ``out``."""
    if overwrite:
        overwrite_plan(out)                          # refuse before writing anything (again under the lock)
    manifest_file = out / "manifest.json"
    if not overwrite and manifest_file.exists() and is_finished(manifest_file, spec):
        if temporaries(out):                         # a killed writer's leftovers: removed under the lock
            with lock(out / ".lock"):
                remove_temporaries(out)
        return manifest_file                         # finished: read-only, safe for concurrent readers
    make_folder(out)
    with lock(out / ".lock"):
        return _make_collection(out, spec, overwrite, progress)


def _make_collection(out: Path, spec: CollectionSpec, overwrite: bool, progress: bool) -> Path:
    spec_file = out / "collection.json"
    if spec_file.exists() and not overwrite:
        # read through from_dict: a setting added later takes the value those collections were made with
        old = read_spec(spec_file).to_dict()
        if old != spec.to_dict():
            diff = [f"{k}: {old.get(k)!r} → {v!r}" for k, v in spec.to_dict().items() if old.get(k) != v]
            raise UserError(f"{out} holds a collection made with other settings ({'; '.join(diff)}); "
                            f"use another folder, or overwrite=True (--overwrite) to start over")
    if overwrite:
        for f in overwrite_plan(out):                # the collection's own files only
            remove(f)
    make_folder(out)
    remove_temporaries(out)
    write_json(spec_file, spec.to_dict())

    records_file = out / "records.jsonl"
    records = read_records(records_file)
    n, K = spec.n_shapes, spec.views_per_shape

    def done(i: int, k: int) -> bool:
        iid = image_id(i, k)
        return (iid in records and (out / "images" / f"{iid}.png").exists()
                and (out / "exr" / f"{iid}.exr").exists())

    total = n * K
    finished = sum(done(i, k) for i in range(n) for k in range(K))
    bar = progress_bar(total, initial=finished, disable=not progress, unit="img",
                       desc=f"{spec.shape_class} {spec.formation}")
    t0 = time.perf_counter()
    try:
        _render_pending(out, spec, records, records_file, done, bar)
    except KeyboardInterrupt as e:                   # Ctrl-C: what is on disk is whole (atomic writes)
        bar.close()
        saved = (f"{sum(done(i, k) for i in range(n) for k in range(K))} of {total} images of the collection "
                 f"in {out} are saved")
        raise Interrupted(f"{saved}; run the same command again to render the rest", saved=saved) from e
    bar.close()
    missing = missing_files(out, spec)
    if missing:                                      # a file went away while we rendered
        more = f" and {len(missing) - 1} more file(s)" if len(missing) > 1 else ""
        raise UserError(f"{out / missing[0]}{more} of the collection went missing while it was rendered "
                        f"(removed by another program?); run the same command again to make them again")
    manifest = {
        "spec": spec.to_dict(),
        "note": "evaluation metadata: training must not read views or shape ids",
        "seconds": time.perf_counter() - t0,
        "images": [records[image_id(i, k)] for i in range(n) for k in range(K)],
    }
    write_json(out / "manifest.json", manifest)
    return out / "manifest.json"


def _render_pending(out: Path, spec: CollectionSpec, records: Dict[str, Dict[str, Any]], records_file: Path,
                    done: Callable[[int, int], bool], bar: Any) -> None:
    """Render every image (and write every volume) of ``spec`` that is not done yet, shape by shape."""
    n, K = spec.n_shapes, spec.views_per_shape
    with os.fdopen(open_file(records_file, os.O_RDWR | os.O_CREAT | os.O_APPEND), "a+") as log:
        log.seek(0, os.SEEK_END)
        if log.tell() > 0:                           # end a torn last line before appending
            log.seek(log.tell() - 1)
            if log.read(1) != "\n":
                log.write("\n")
        for i in range(n):
            raise_if_ctrl_c()                        # a Ctrl-C a library swallowed in the shape before
            pending = [k for k in range(K) if not done(i, k)]
            if not pending and all((out / "volumes" / f"{i:05d}{ext}").exists() for ext in (".npz", ".vol")):
                continue
            vol = shapes.generate(spec.shape_class, spec.shape_seed(i), spec.resolution)
            _write_volume(out / "volumes", i, spec, vol)
            if not pending:
                continue
            views = torch.stack([spec.view(i, k) for k in pending])
            lights = [spec.lighting_of(i, k) for k in pending] if spec.formation == "physical" else None
            images, exposures = _render_shape(spec, vol, views, lights)
            for j, k in enumerate(pending):
                iid = image_id(i, k)
                img = to_hwc(images[j])
                atomic_write(out / "exr" / f"{iid}.exr", lambda p: save_exr(p, img))
                atomic_write(out / "images" / f"{iid}.png", lambda p: save_png(p, to_png_rgba(img)))
                record = {"id": iid, "image": f"images/{iid}.png", "exr": f"exr/{iid}.exr",
                          "shape": i, "shape_seed": spec.shape_seed(i), "volume": f"volumes/{i:05d}.npz",
                          "view": [float(x) for x in views[j]]}
                if lights is not None:
                    record["lighting"] = lights[j].to_dict()
                    record["exposure"] = exposures[j]
                log.write(json.dumps(record) + "\n")
                log.flush()
                os.fsync(log.fileno())
                records[iid] = record
            bar.update(len(pending))


def _render_shape(spec: CollectionSpec, vol: torch.Tensor, views: torch.Tensor,
                  lights: Optional[list]) -> Tuple[torch.Tensor, List[float]]:
    """Render one shape from several views → ``(K, C, N, N)`` linear premultiplied, exposures."""
    if spec.formation == "physical":
        batch = vol[None].expand(len(views), -1, -1, -1, -1)
        return render_physical(batch, views, lights, spp=spec.spp, max_depth=spec.max_depth,
                               seed=spec.seed, filter=spec.filter, exposure=spec.exposure)
    v = vol if CHANNELS[spec.formation] == 4 else vol[3:]
    with torch.no_grad():
        images = render(v[None].expand(len(views), -1, -1, -1, -1).contiguous(), views,
                        spec.formation, spec.renderer, filter=spec.filter, camera=spec.camera,
                        fov=spec.fov, distance=spec.distance)
    return images, [1.0] * len(views)


def _write_volume(folder: Path, i: int, spec: CollectionSpec, vol: torch.Tensor) -> None:
    """Shape i's ground truth, ``SSSSS.npz`` and ``SSSSS.vol``, each unless it is there already."""
    npz = folder / f"{i:05d}.npz"
    vol_file = folder / f"{i:05d}.vol"
    if not npz.exists():
        atomic_write(npz, lambda p: np.savez_compressed(p, volume=vol.numpy(), shape_class=spec.shape_class,
                                                   seed=spec.shape_seed(i)))
    if not vol_file.exists():
        atomic_write(vol_file, lambda p: write_vol(vol, p))
