"""Rendered collections: a procedural shape class → an unstructured image collection with 3D truth.

``make_collection(out, spec)`` renders ``n_shapes`` shapes × ``views_per_shape`` images, each
from its own random view, in one image formation:

- ``vh`` / ``ao`` / ``ea``: the PlatonicGAN layers, with either renderer (closed form or Mitsuba);
- ``physical``: Mitsuba's volumetric path tracer on the same medium under random natural light
  (:mod:`mitsuba_platonic.render.physical`).

Layout of a collection folder::

    collection.json          the spec (checked on resume: a different spec is an error)
    images/SSSSS_KK.png      8-bit sRGB, straight alpha: the training input
    exr/SSSSS_KK.exr         linear, premultiplied, with alpha (OpenEXR)
    volumes/SSSSS.npz        ground truth: ``volume`` (4, N, N, N) RGBA, ``shape_class``, ``seed``
    volumes/SSSSS.vol        the same grid in Mitsuba's .vol format ([Z, Y, X, C] layout)
    records.jsonl            one line per finished image (appended as images are written)
    manifest.json            every image's file, shape id and view (+ lighting, exposure):
                             metadata for evaluation only, never read by training

``overwrite`` (``--overwrite``) deletes only files the collection's own records name (the plan in
``collection.json``, ``records.jsonl``, ``manifest.json``) and the temporaries it writes; if the
folder holds anything else where a collection writes (``images/``, ``exr/``, ``volumes/``, the
records), or is no collection at all but has files there, it refuses and deletes nothing.

Crash safety and resume: every file is written to a temporary name and renamed into place, and an
image counts as done only once its PNG, EXR and record line all exist. Re-running the same
command skips finished images and shapes, so a half-written collection is completed without
re-rendering what is done. Views, shape seeds and lighting derive from ``seed`` and the image's
index alone, so a resumed run renders exactly what an uninterrupted one would.
"""

from __future__ import annotations

import json
import os
import re
import time
import warnings
from contextlib import contextmanager
from dataclasses import MISSING, asdict, dataclass, fields
from pathlib import Path
from typing import Any, Callable, Dict, Iterator, List, Optional, Tuple, Union

import numpy as np
import torch

from .. import views as V
from ..errors import Interrupted, UserError
from ..fileio import atomic_write
from ..images import exr_channel_names, save_exr, save_png, to_hwc, to_png_rgba
from ..progress import progress_bar
from ..render import RenderSettings, render
from ..render.physical import render_physical, sample_lighting
from ..render.settings import FORMATIONS, LIGHTINGS
from ..render.sky import ENVMAPS, baked_envmaps
from ..render.variant import ensure_variant
from ..volume import CHANNELS
from ..volume_io import write_vol
from . import shapes

__all__ = ["CollectionSpec", "make_collection", "load_manifest", "FORMATIONS", "RENDERERS",
           "default_envmaps", "check_envmap"]

RENDERERS = ("closed_form", "mitsuba")
SUBFOLDERS = ("images", "exr", "volumes")
RECORDS = ("collection.json", "records.jsonl", "manifest.json")
#: What atomic_write names the temporaries of a collection's files: ``.00000_00.tmp<pid>.png``, and
#: ``..00000_00.tmp<pid>.tmp<pid>.png`` where a writer that is atomic itself (save_png) writes the temporary.
_TEMPORARY = re.compile(r"\.{1,2}\d{5,}(_\d{2,})?(\.tmp\d+){1,2}\.(png|exr|npz|vol)")
#: ... and of its records (collection.json, records.jsonl, manifest.json) in the folder itself.
_RECORD_TEMPORARY = re.compile(r"\.(collection|records|manifest)\.tmp\d+\.(json|jsonl)")


def default_envmaps() -> List[str]:
    """Environment maps in the package's ``scenes/envmaps/`` (``*.exr``: any a user dropped there)
    and the skies baked from Mitsuba's ``sunsky`` (:func:`mitsuba_platonic.render.sky.baked_envmaps`:
    carried by the package where they were baked before it was built, else baked on first use;
    no photographic map ships for want of a licence)."""

    return sorted(set(str(p) for p in ENVMAPS.glob("*.exr")) | set(baked_envmaps()))


_EXR_MAGIC = b"\x76\x2f\x31\x01"


def check_envmap(path: Union[str, Path], what: str = "environment map") -> None:
    """Raise :class:`~mitsuba_platonic.errors.UserError` naming ``path`` unless it is an existing,
    readable OpenEXR file with colour channels (R, G, B or Y): what Mitsuba's ``envmap`` is given."""

    p = Path(path)
    if not p.is_file():
        raise UserError(f"{what} {str(path)!r} does not exist" if not p.exists() else
                        f"{what} {str(path)!r} is not a file")
    try:
        with open(p, "rb") as f:
            magic = f.read(4)
    except OSError as e:
        raise UserError(f"{what} {str(path)!r} cannot be read: {e}") from None
    expected = "expected a lat-long environment map in OpenEXR format (.exr), like scenes/envmaps/*.exr"
    if magic != _EXR_MAGIC:
        raise UserError(f"{what} {str(path)!r} is not an OpenEXR file (it does not start with the EXR "
                        f"magic number); {expected}")
    try:
        channels = exr_channel_names(p)
    except Exception as e:  # OpenEXR raises several types for a damaged header
        raise UserError(f"{what} {str(path)!r}: its OpenEXR header cannot be read ({type(e).__name__}: "
                        f"{' '.join(str(e).split())}); {expected}") from None
    if not ({"R", "G", "B"} <= set(channels) or "Y" in channels):
        raise UserError(f"{what} {str(path)!r} has no colour channels (R, G, B or Y), only "
                        f"{', '.join(channels) or 'none'}; {expected}")
    problem = _unreadable_pixels(p)
    if problem:
        raise UserError(f"{what} {str(path)!r} is truncated or damaged: its pixels cannot be read in full "
                        f"({problem}); {expected}")


#: Files whose pixels :func:`_unreadable_pixels` read in full: (path, size, mtime) → the problem or ''.
_READ_PIXELS: Dict[Tuple[str, int, int], str] = {}


def _unreadable_pixels(path: Path) -> str:
    """Read every pixel of the EXR ``path`` with Mitsuba's own loader on this thread, where a
    damaged file raises (when the ``envmap`` emitter reads it while a scene loads, on a worker
    thread, a truncated file aborts the process). Returns what is wrong, '' if nothing."""

    stat = path.stat()
    key = (str(path.resolve()), stat.st_size, stat.st_mtime_ns)
    if key not in _READ_PIXELS:
        mi = ensure_variant()
        try:
            mi.Bitmap(str(path))
            _READ_PIXELS[key] = ""
        except Exception as e:                               # Mitsuba raises RuntimeError with the reader's words
            _READ_PIXELS[key] = " ".join(str(e).replace(f'"{path}": ', "").split())
    return _READ_PIXELS[key]


@dataclass
class CollectionSpec:
    """Everything that determines a rendered collection (saved as ``collection.json``).

    shape_class: a registered class (:func:`mitsuba_platonic.data.shapes.list_classes`).
    n_shapes, views_per_shape: the collection has n_shapes × views_per_shape images.
    resolution: volume and image resolution N (16 … 128).
    formation: 'vh' | 'ao' | 'ea' | 'physical'.
    renderer: 'closed_form' | 'mitsuba' (vh/ao/ea; physical always path-traces with Mitsuba).
    filter: 'trilinear' | 'nearest' lookups.
    views: 'sphere' (uniform), 'band' (elevation range, degrees) or 'ring' (one elevation).
    elevation: (low, high) for 'band', a number for 'ring', ignored for 'sphere'.
    lighting: 'sunsky' | 'envmap' | 'mixed' (physical only); envmaps: EXR paths for 'envmap'.
    spp, max_depth: path tracer samples per pixel and path length (physical only).
    camera, fov, distance: the camera of the vh/ao/ea images, as the renderers take it
        (:class:`~mitsuba_platonic.render.RenderSettings`: 'orthographic', the default, or a
        'perspective' pinhole; physical images are orthographic only).
    exposure: 'metered' (k = 1 / the light's mean luminance) | 'auto' (per image, the camera-like
        95th percentile; collections made before metering read as this) (physical only; see
        :mod:`mitsuba_platonic.render.physical`).
    seed: master seed of shapes, views and lighting.
    """

    shape_class: str
    n_shapes: int = 100
    views_per_shape: int = 10
    resolution: int = 64
    formation: str = "ea"
    renderer: str = "closed_form"
    filter: str = "trilinear"
    views: str = "sphere"
    elevation: Union[float, Tuple[float, float], None] = None
    lighting: str = "sunsky"
    envmaps: Tuple[str, ...] = ()
    spp: int = 32
    max_depth: int = 8
    camera: str = RenderSettings.camera
    fov: float = RenderSettings.fov
    distance: Optional[float] = RenderSettings.distance
    exposure: str = "metered"
    seed: int = 0

    def validate(self) -> "CollectionSpec":
        """Check every field; raise ``ValueError`` naming the first bad one. Returns self."""
        if self.shape_class not in shapes.list_classes():
            raise UserError(f"shape_class must be one of {shapes.list_classes()}, got {self.shape_class!r}")
        for name in ("n_shapes", "views_per_shape", "spp", "max_depth"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise UserError(f"{name} must be a positive int, got {value!r}")
        if not isinstance(self.seed, int) or self.seed < 0:
            raise UserError(f"seed must be a non-negative int, got {self.seed!r}")
        if not isinstance(self.resolution, int) or not 16 <= self.resolution <= 128:
            raise UserError(f"resolution must be an int in [16, 128], got {self.resolution!r}")
        if self.formation not in FORMATIONS:
            raise UserError(f"formation must be one of {FORMATIONS}, got {self.formation!r}")
        if self.renderer not in RENDERERS:
            raise UserError(f"renderer must be one of {RENDERERS}, got {self.renderer!r}")
        if self.filter not in ("trilinear", "nearest"):
            raise UserError(f"filter must be 'trilinear' or 'nearest', got {self.filter!r}")
        if self.views not in V.DISTRIBUTIONS:
            raise UserError(f"views must be one of {V.DISTRIBUTIONS}, got {self.views!r}")
        if self.lighting not in LIGHTINGS:
            raise UserError(f"lighting must be one of {LIGHTINGS}, got {self.lighting!r}")
        if self.exposure not in ("metered", "auto"):
            raise UserError(f"exposure must be 'metered' or 'auto', got {self.exposure!r}")
        V.lens(self.camera, self.fov, self.distance)            # camera, fov and distance
        if self.formation == "physical" and self.camera != "orthographic":
            raise UserError("camera: physical (path-traced) collections are orthographic only")
        if self.formation == "physical" and self.lighting in ("envmap", "mixed") and not self.envmaps:
            if self.lighting == "envmap":
                raise UserError("lighting 'envmap' needs at least one environment map (.exr): pass "
                                "envmaps or drop EXR files into scenes/envmaps/")
        for path in self.envmaps:
            check_envmap(path)
        V.sample_views(1, self.views, seed=0, **self._view_kwargs())  # checks the elevation
        return self

    def _view_kwargs(self) -> Dict[str, Any]:
        if self.views == "sphere" or self.elevation is None:
            default = V.DEFAULT_ELEVATION.get(self.views)
            return {} if default is None else {"elevation": default}
        e = self.elevation
        return {"elevation": tuple(float(x) for x in e) if isinstance(e, (list, tuple)) else float(e)}

    def to_dict(self) -> Dict[str, Any]:
        d = asdict(self)
        d["envmaps"] = list(self.envmaps)
        if isinstance(d["elevation"], tuple):
            d["elevation"] = list(d["elevation"])
        return d

    @classmethod
    def from_dict(cls, d: Dict[str, Any]) -> "CollectionSpec":
        """The spec a ``collection.json`` (or a manifest's ``spec``) records; UserError if ``d``
        is no mapping of collection settings."""
        if not isinstance(d, dict):
            raise UserError(f"expected a JSON object of collection settings, got {_json_kind(d)}")
        known = {f.name for f in fields(cls)}
        unknown = set(d) - known
        if unknown:
            raise UserError(f"unknown collection setting(s) {sorted(unknown)}")
        d = dict(d)
        d.setdefault("exposure", "auto")               # collections made before metering
        d["envmaps"] = tuple(d.get("envmaps", ()))
        if isinstance(d.get("elevation"), list):
            d["elevation"] = tuple(d["elevation"])
        missing = sorted(f.name for f in fields(cls)
                         if f.name not in d and f.default is MISSING and f.default_factory is MISSING)
        if missing:
            raise UserError(f"collection setting(s) {missing} missing")
        return cls(**d)

    # -- the deterministic plan ------------------------------------------------------------

    def shape_seed(self, i: int) -> int:
        """Seed of shape i: a hash of (seed, i), so shapes don't depend on the collection size."""
        return int(np.random.SeedSequence([self.seed, i]).generate_state(1)[0] & 0x7FFFFFFF)

    def view(self, i: int, k: int) -> torch.Tensor:
        """The view ``(3,)`` of image (shape i, view k), from a generator seeded by (seed, i, k)."""
        g = torch.Generator()
        g.manual_seed(int(np.random.SeedSequence([self.seed, i, k, 1]).generate_state(1)[0]))
        return V.sample_views(1, self.views, seed=g, **self._view_kwargs())[0]

    def lighting_of(self, i: int, k: int):
        rng = np.random.default_rng([self.seed, i, k, 2])
        return sample_lighting(rng, self.lighting, self.envmaps)


def _json_kind(value: Any) -> str:
    """A JSON value's kind, as a message names it: 'a list', 'the number 5', 'null'."""
    if value is None:
        return "null"
    if isinstance(value, (bool, int, float)):
        return f"the {'boolean' if isinstance(value, bool) else 'number'} {json.dumps(value)}"
    return {dict: "an object", list: "a list", str: "a string"}.get(type(value), type(value).__name__)


def _manifest_problem(m: Any) -> str:
    """What is wrong with a parsed ``manifest.json`` (wrong shape), '' if it is whole."""
    if not isinstance(m, dict):
        return f"expected a JSON object, got {_json_kind(m)}"
    try:
        CollectionSpec.from_dict(m.get("spec"))
    except UserError as e:
        return f"its 'spec': {e}"
    images = m.get("images")
    if not isinstance(images, list):
        return f"its 'images': expected a list of image records, got {_json_kind(images)}"
    bad = [r for r in images if not (isinstance(r, dict) and all(isinstance(r.get(k), str) for k in ("image", "exr")))]
    if bad:
        return f"its 'images': {len(bad)} record(s) without the 'image' and 'exr' file names"
    return ""


def _read_spec(spec_file: Path) -> "CollectionSpec":
    """The spec ``collection.json`` records; UserError naming the file if it is damaged (it
    says what the images on disk were made with: nothing can resume or be deleted without it)."""
    try:
        return CollectionSpec.from_dict(json.loads(spec_file.read_text()))
    except ValueError as e:                                   # not JSON, not UTF-8, not a spec (UserError)
        why = " ".join(str(e).split())
        raise UserError(f"{spec_file} is damaged ({why}); it records the settings the collection in "
                        f"{spec_file.parent} was made with, so the collection cannot be resumed; nothing was "
                        f"changed: move the folder away or use another one") from None


def image_id(i: int, k: int) -> str:
    return f"{i:05d}_{k:02d}"


def _write_json(path: Path, data: Any) -> None:
    atomic_write(path, lambda p: p.write_text(json.dumps(data, indent=1)))


def _write_volume(folder: Path, i: int, spec: CollectionSpec, vol: torch.Tensor) -> None:
    npz = folder / f"{i:05d}.npz"
    vol_file = folder / f"{i:05d}.vol"
    if not npz.exists():
        atomic_write(npz, lambda p: np.savez_compressed(p, volume=vol.numpy(), shape_class=spec.shape_class,
                                                   seed=spec.shape_seed(i)))
    if not vol_file.exists():
        atomic_write(vol_file, lambda p: write_vol(vol, p))


def _read_records(path: Path) -> Dict[str, Dict[str, Any]]:
    records: Dict[str, Dict[str, Any]] = {}
    if path.exists():
        for line in path.read_text().splitlines():
            try:
                r = json.loads(line)
                records[r["id"]] = r
            except (ValueError, KeyError):
                continue  # a torn last line from a crash: that image is simply redone
    return records


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


def _missing_files(out: Path, spec: CollectionSpec) -> List[str]:
    """The files of the finished collection ``spec`` that ``out`` lacks (relative paths, in plan order)."""
    missing = []
    for i in range(spec.n_shapes):
        for k in range(spec.views_per_shape):
            missing += [rel for rel in (f"images/{image_id(i, k)}.png", f"exr/{image_id(i, k)}.exr")
                        if not (out / rel).is_file()]
        missing += [rel for rel in (f"volumes/{i:05d}.npz", f"volumes/{i:05d}.vol") if not (out / rel).is_file()]
    return missing


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
    if overwrite:
        _overwrite_plan(out)                         # refuse before writing anything (again under the lock)
    manifest_file = out / "manifest.json"
    if not overwrite and manifest_file.exists() and _finished(manifest_file, spec):
        if _temporaries(out):                        # a killed writer's leftovers: removed under the lock
            with _lock(out / ".lock"):
                _remove_temporaries(out)
        return manifest_file                         # finished: read-only, safe for concurrent readers
    out.mkdir(parents=True, exist_ok=True)
    with _lock(out / ".lock"):
        return _make_collection(out, spec, overwrite, progress)


def _finished(manifest_file: Path, spec: CollectionSpec) -> bool:
    """Whether the manifest says the collection ``spec`` is finished and all its files are there.
    A damaged manifest (not JSON, or JSON of another shape) is named in a warning: the
    collection is then finished again, which rebuilds it from ``records.jsonl``."""
    try:
        m = json.loads(manifest_file.read_text())
        problem = _manifest_problem(m)
    except ValueError as e:                                  # not JSON, or not UTF-8
        problem = f"not JSON: {' '.join(str(e).split())}"
    if problem:
        warnings.warn(f"{manifest_file} is damaged ({problem}); it is rebuilt from the collection's records")
        return False
    out = manifest_file.parent
    return (CollectionSpec.from_dict(m["spec"]) == spec
            and all((out / r["image"]).exists() and (out / r["exr"]).exists() for r in m["images"])
            and not _missing_files(out, spec))


def _overwrite_plan(out: Path) -> List[Path]:
    """The files ``overwrite`` deletes in ``out``: those the collection's records name.

    Raises ``ValueError`` (one line, naming ``out``) if ``out`` holds anything else in the places a
    collection writes, or is no collection (no readable ``collection.json``) but has files there.
    """
    if not out.exists():
        return []
    if not out.is_dir():
        raise UserError(f"overwrite: {out} is not a folder")
    spec: Optional[CollectionSpec] = None
    try:
        spec = CollectionSpec.from_dict(json.loads((out / "collection.json").read_text()))
    except (OSError, ValueError, TypeError, AttributeError):
        pass
    owned = set()
    if spec is not None:
        for i in range(spec.n_shapes):               # the plan: every file this spec writes
            owned |= {f"volumes/{i:05d}.npz", f"volumes/{i:05d}.vol"}
            for k in range(spec.views_per_shape):
                owned |= {f"images/{image_id(i, k)}.png", f"exr/{image_id(i, k)}.exr"}
        named = list(_read_records(out / "records.jsonl").values())
        try:
            named += json.loads((out / "manifest.json").read_text())["images"]
        except (OSError, ValueError, KeyError, TypeError):
            pass
        for r in named:
            if isinstance(r, dict):
                owned |= {v for key in ("image", "exr", "volume") if isinstance(v := r.get(key), str)}
                if isinstance(r.get("volume"), str) and r["volume"].endswith(".npz"):
                    owned.add(r["volume"][:-4] + ".vol")
    remove: List[Path] = []
    foreign: List[str] = []
    for name in RECORDS:
        path = out / name
        if not (path.exists() or path.is_symlink()):
            continue
        if spec is None or not path.is_file():
            foreign.append(name)
        elif name != "collection.json":              # rewritten, not deleted
            remove.append(path)
    for sub in SUBFOLDERS:
        folder = out / sub
        if not folder.is_dir():
            if folder.exists() or folder.is_symlink():
                foreign.append(sub)
            continue
        for path in sorted(folder.iterdir()):
            rel = f"{sub}/{path.name}"
            if not path.is_dir() and (rel in owned or (spec is not None and _TEMPORARY.fullmatch(path.name))):
                remove.append(path)
            else:
                foreign.append(rel + ("/" if path.is_dir() else ""))
    if foreign:
        shown = ", ".join(foreign[:3]) + (f" and {len(foreign) - 3} more" if len(foreign) > 3 else "")
        what = (f"holds {len(foreign)} file(s) its collection did not write" if spec is not None else
                f"is not a collection (no readable collection.json) but holds {len(foreign)} file(s) "
                f"overwriting would delete")
        raise UserError(f"overwrite (--overwrite): {out} {what} ({shown}); nothing was deleted: "
                        f"move them away or use another folder")
    return remove


def _temporaries(out: Path) -> List[Path]:
    """The temporaries a killed run left in ``out`` and its subfolders."""
    found: List[Path] = []
    for folder, pattern in [(out, _RECORD_TEMPORARY)] + [(out / sub, _TEMPORARY) for sub in SUBFOLDERS]:
        if folder.is_dir():
            found += [p for p in folder.iterdir() if pattern.fullmatch(p.name) and p.is_file()]
    return found


def _remove_temporaries(out: Path) -> None:
    """Delete :func:`_temporaries` (call it holding the collection's lock)."""
    for stray in _temporaries(out):
        stray.unlink(missing_ok=True)


@contextmanager
def _lock(path: Path) -> Iterator[None]:
    """An exclusive advisory lock: one writer per collection folder (others wait)."""
    import fcntl  # lazy: POSIX only, where a collection is locked
    with open(path, "w") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def _make_collection(out: Path, spec: CollectionSpec, overwrite: bool, progress: bool) -> Path:
    spec_file = out / "collection.json"
    if spec_file.exists() and not overwrite:
        # read through from_dict: a setting added later takes the value those collections were made with
        old = _read_spec(spec_file).to_dict()
        if old != spec.to_dict():
            diff = [f"{k}: {old.get(k)!r} → {v!r}" for k, v in spec.to_dict().items() if old.get(k) != v]
            raise UserError(f"{out} holds a collection made with other settings ({'; '.join(diff)}); "
                            f"use another folder, or overwrite=True (--overwrite) to start over")
    if overwrite:
        for f in _overwrite_plan(out):               # the collection's own files only
            f.unlink()
    out.mkdir(parents=True, exist_ok=True)
    _remove_temporaries(out)
    _write_json(spec_file, spec.to_dict())

    records_file = out / "records.jsonl"
    records = _read_records(records_file)
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
    missing = _missing_files(out, spec)
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
    _write_json(out / "manifest.json", manifest)
    return out / "manifest.json"


def _render_pending(out: Path, spec: CollectionSpec, records: Dict[str, Dict[str, Any]], records_file: Path,
                    done: Callable[[int, int], bool], bar: Any) -> None:
    """Render every image (and write every volume) of ``spec`` that is not done yet, shape by shape."""
    n, K = spec.n_shapes, spec.views_per_shape
    with open(records_file, "a+") as log:
        log.seek(0, os.SEEK_END)
        if log.tell() > 0:                           # end a torn last line before appending
            log.seek(log.tell() - 1)
            if log.read(1) != "\n":
                log.write("\n")
        for i in range(n):
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


def load_manifest(folder: Union[str, Path]) -> Dict[str, Any]:
    """Read a finished collection's ``manifest.json`` (raises ``FileNotFoundError`` if unfinished,
    :class:`~mitsuba_platonic.errors.UserError` naming it if it is damaged)."""
    path = Path(folder) / "manifest.json"
    if not path.exists():
        raise FileNotFoundError(f"{folder} has no manifest.json: the collection is unfinished "
                                f"(re-run make-dataset with the same settings to finish it)")
    try:
        m = json.loads(path.read_text())
        problem = _manifest_problem(m)
    except ValueError as e:
        problem = f"not JSON: {' '.join(str(e).split())}"
    if problem:
        raise UserError(f"{path} is damaged ({problem}); re-run make-dataset with the same settings to rebuild it")
    return m
