"""Rendered collections: a procedural shape class → an unstructured image collection with 3D truth.

``make_collection(out, spec)`` renders ``n_shapes`` shapes × ``views_per_shape`` images, each
from its own random view, in one image formation:

- ``vh`` / ``ao`` / ``ea``: the PlatonicGAN layers, with either renderer (closed form or Mitsuba);
- ``physical``: Mitsuba's volumetric path tracer on the same medium under random natural light
  (:mod:`mitsuba_platonic.render.mitsuba.physical`).

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
from ..files.fileio import InputFileRefused, atomic_write, check_input_file, confined, make_folder, open_file, remove
from ..files.volume_io import write_vol
from ..images import save_exr, save_png, to_hwc, to_png_rgba
from ..render import render
from ..render.mitsuba.physical import render_physical
from ..runtime import budget
from ..runtime.progress import progress_bar
from ..volume import CHANNELS
from . import shapes
from .collection_files import (RECORDS, SUBFOLDERS, image_id, is_finished, load_manifest, lock, missing_files,
                               overwrite_plan, read_records, read_spec, remove_temporaries, temporaries, write_json)
from .collection_spec import FORMATIONS, RENDERERS, CollectionSpec
from .envmaps import check_envmap, default_envmaps

__all__ = ["CollectionSpec", "make_collection", "check_collection_fits", "collection_needs", "recorded_images", "load_manifest", "FORMATIONS", "RENDERERS",
           "default_envmaps", "check_envmap", "image_id", "SUBFOLDERS", "RECORDS"]


#: Views of one shape rendered in one batch: a shape's views are rendered a chunk at a time, so
#: that memory does not grow with ``--views`` (and the first images come within seconds).
VIEW_CHUNK = 64
#: A progress line at least this often (seconds) where output is a log, besides every tenth.
PROGRESS_SECONDS = 30.0
#: Lower bounds of what a collection takes, per image: memory for its record (a dict, held until the
#: manifest is written: measured about 0.9 KB) and disk for its record line, manifest entry, PNG and
#: EXR (about 450 bytes and ≥ 1 byte per pixel measured at 64²; the EXR alone is 2.5 to 4.5 bytes per
#: pixel); per shape the ``.vol`` file exactly (4 float32 channels per voxel and a 48-byte header).
RECORD_MEMORY, RECORD_DISK, IMAGE_DISK_PER_PIXEL, VOL_HEADER = 600, 300, 1, 48


def collection_needs(spec: CollectionSpec) -> Tuple[int, int]:
    """(memory, disk) a collection of ``spec`` needs at least, in bytes (lower bounds: what its
    records hold and its ``.vol`` files and images take)."""
    images = spec.n_shapes * spec.views_per_shape
    memory = images * RECORD_MEMORY
    disk = (images * (RECORD_DISK + IMAGE_DISK_PER_PIXEL * spec.resolution ** 2)
            + spec.n_shapes * (16 * spec.resolution ** 3 + VOL_HEADER))
    return memory, disk


def recorded_images(folder: Union[str, Path]) -> int:
    """How many images a (half-written) collection in ``folder`` has recorded: the lines of its
    ``records.jsonl`` (0 where there is none), read in blocks."""
    lines = 0
    try:
        with open(check_input_file(Path(folder) / "records.jsonl"), "rb") as f:   # no FIFO: it would block
            for block in iter(lambda: f.read(1 << 20), b""):
                lines += block.count(b"\n")
    except (OSError, InputFileRefused):                     # none, or no file: the records' reader refuses it
        return 0
    return lines


def check_collection_fits(spec: CollectionSpec, out: Union[str, Path], classes: int = 1,
                          names: Tuple[str, str] = ("n_shapes", "views_per_shape"), done: int = 0) -> None:
    """:class:`~mitsuba_platonic.errors.UserError` in one line, before anything is written, where
    ``classes`` collections of ``spec``'s size cannot fit: their records in the memory available, or
    their files on the disk of ``out`` (less the ``done`` images already there, a resumed collection's);
    it names the sizes by ``names`` (``--shapes``, ``--views`` on the command line; the spec's fields
    by default) and says how many images would fit."""
    memory, disk = collection_needs(spec)
    size = f"{names[0]} {spec.n_shapes} {names[1]} {spec.views_per_shape}"
    both = f"{names[0]} × {names[1]}"
    images = spec.n_shapes * spec.views_per_shape
    per_class = " per class" if classes > 1 else ""
    have = budget.available_memory()                 # one class at a time: its records are held until its manifest
    if have[0] is not None:
        budget.check_fits(memory, have, f"{size}: holding the records of {images} images",
                          f"at most about {max(have[0], 0) // RECORD_MEMORY} images ({both}) fit")
    have = budget.free_disk(out)
    if have[0] is not None:
        per_image = disk / max(images, 1)
        every = f" for {classes} classes" if classes > 1 else ""
        budget.check_fits(int(disk * classes - per_image * min(done, images * classes)), have, f"{size}{every}: writing {images * classes} images of "
                          f"{spec.resolution}² and their volumes",
                          f"at most about {int(max(have[0], 0) // per_image // classes)} images{per_class} "
                          f"({both}) fit; lower them, or write elsewhere{' (--out)' if names[0].startswith('--') else ''}",
                          resource="disk space")


def _finished(records: Dict[str, Dict[str, Any]], n: int, K: int, done: Callable[[int, int], bool]) -> int:
    """How many images of an ``n`` × ``K`` collection are done, from its records (not a loop over
    every image: a large collection's first line comes at once)."""
    count = 0
    for iid in records:
        try:
            i, k = (int(part) for part in iid.split("_"))
        except ValueError:
            continue
        count += i < n and k < K and done(i, k)
    return count


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
    check_collection_fits(spec, out, done=0 if overwrite else recorded_images(out))   # before the lock or a folder
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
    finished = _finished(records, n, K, done)
    bar = progress_bar(total, initial=finished, disable=not progress, unit="img",
                       desc=f"{spec.shape_class} {spec.formation}", first_line=finished < total,
                       seconds=PROGRESS_SECONDS)
    t0 = time.perf_counter()
    try:
        _render_pending(out, spec, records, records_file, done, bar)
    except KeyboardInterrupt as e:                   # Ctrl-C: what is on disk is whole (atomic writes)
        bar.close()
        saved = (f"{_finished(records, n, K, done)} of {total} images of the collection "
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
            vol = None
            for first in range(0, K, VIEW_CHUNK):    # a chunk of views at a time: memory stays bounded
                pending = [k for k in range(first, min(K, first + VIEW_CHUNK)) if not done(i, k)]
                if not pending:
                    continue
                if vol is None:
                    vol = shapes.generate(spec.shape_class, spec.shape_seed(i), spec.resolution)
                    _write_volume(out / "volumes", i, spec, vol)
                _render_views(out, spec, i, vol, pending, records, log, seed_offset=first)
                bar.update(len(pending))
                raise_if_ctrl_c()
            if vol is None and not all((out / "volumes" / f"{i:05d}{ext}").exists() for ext in (".npz", ".vol")):
                _write_volume(out / "volumes", i, spec,
                              shapes.generate(spec.shape_class, spec.shape_seed(i), spec.resolution))


def _render_views(out: Path, spec: CollectionSpec, i: int, vol: torch.Tensor, pending: List[int],
                  records: Dict[str, Dict[str, Any]], log: Any, seed_offset: int = 0) -> None:
    """Render views ``pending`` of shape ``i`` and write their images, EXRs and record lines
    (``seed_offset``: the chunk's first view, so that chunks do not repeat the path tracer's seeds)."""
    views = torch.stack([spec.view(i, k) for k in pending])
    lights = [spec.lighting_of(i, k) for k in pending] if spec.formation == "physical" else None
    images, exposures = _render_shape(spec, vol, views, lights, seed_offset)
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


def _render_shape(spec: CollectionSpec, vol: torch.Tensor, views: torch.Tensor,
                  lights: Optional[list], seed_offset: int = 0) -> Tuple[torch.Tensor, List[float]]:
    """Render one shape from several views → ``(K, C, N, N)`` linear premultiplied, exposures."""
    if spec.formation == "physical":
        batch = vol[None].expand(len(views), -1, -1, -1, -1)
        return render_physical(batch, views, lights, spp=spec.spp, max_depth=spec.max_depth,
                               seed=spec.seed + seed_offset, filter=spec.filter, exposure=spec.exposure)
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
