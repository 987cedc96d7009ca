"""The files of a collection folder: its layout, records and manifest, what ``overwrite`` may
delete, the temporaries a killed writer leaves, and the one-writer lock.

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
``collection.json``, ``records.jsonl``, ``manifest.json``) and the temporaries it writes
(:func:`overwrite_plan`); if the folder holds anything else where a collection writes
(``images/``, ``exr/``, ``volumes/``, the records), or is no collection at all but has files
there, it refuses and deletes nothing. Rendering into the folder is :mod:`.render_collection`'s job.
"""

from __future__ import annotations

import json
import os
import re
import warnings
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Dict, Iterator, List, Optional, Set, Union

from ..errors import UserError
from ..files.fileio import atomic_write, open_file, read_input_text, remove
from .collection_spec import CollectionSpec, json_kind

__all__ = ["SUBFOLDERS", "RECORDS", "image_id", "load_manifest", "manifest_problem", "read_spec", "read_records",
           "write_json", "missing_files", "is_finished", "overwrite_plan", "temporaries", "remove_temporaries",
           "lock"]

SUBFOLDERS = ("images", "exr", "volumes")
RECORDS = ("collection.json", "records.jsonl", "manifest.json")
#: What atomic_write names the temporaries of a collection's files: ``.00000_00.tmp<pid>.png``, and
#: ``..00000_00.tmp<pid>.tmp<pid>.png`` where a writer that is atomic itself (save_png) writes the temporary.
_TEMPORARY = re.compile(r"\.{1,2}\d{5,}(_\d{2,})?(\.tmp\d+){1,2}\.(png|exr|npz|vol)")
#: ... and of its records (collection.json, records.jsonl, manifest.json) in the folder itself.
_RECORD_TEMPORARY = re.compile(r"\.(collection|records|manifest)\.tmp\d+\.(json|jsonl)")


def image_id(i: int, k: int) -> str:
    """The name of image (shape i, view k) without its extension: ``SSSSS_KK``."""
    return f"{i:05d}_{k:02d}"


def write_json(path: Path, data: Any) -> None:
    """Write ``data`` as JSON to ``path`` atomically (a temporary renamed into place)."""
    atomic_write(path, lambda p: p.write_text(json.dumps(data, indent=1)))


def read_records(path: Path) -> Dict[str, Dict[str, Any]]:
    """``records.jsonl`` as ``{image id: record}``; a torn line (a crash while appending) is skipped."""
    records: Dict[str, Dict[str, Any]] = {}
    if path.exists():
        for line in read_input_text(path, max_bytes=None).splitlines():
            try:
                r = json.loads(line)
                records[r["id"]] = r
            except (ValueError, KeyError):
                continue  # a torn last line from a crash: that image is simply redone
    return records


def read_spec(spec_file: Path) -> "CollectionSpec":
    """The spec ``collection.json`` records; UserError naming the file if it is damaged (it
    says what the images on disk were made with: nothing can resume or be deleted without it)."""
    try:
        return CollectionSpec.from_dict(json.loads(read_input_text(spec_file, max_bytes=None)))
    except ValueError as e:                                   # not JSON, not UTF-8, not a spec (UserError)
        why = " ".join(str(e).split())
        raise UserError(f"{spec_file} is damaged ({why}); it records the settings the collection in "
                        f"{spec_file.parent} was made with, so the collection cannot be resumed; nothing was "
                        f"changed: move the folder away or use another one") from None


def manifest_problem(m: Any) -> str:
    """What is wrong with a parsed ``manifest.json`` (wrong shape), '' if it is whole."""
    if not isinstance(m, dict):
        return f"expected a JSON object, got {json_kind(m)}"
    try:
        CollectionSpec.from_dict(m.get("spec"))
    except UserError as e:
        return f"its 'spec': {e}"
    images = m.get("images")
    if not isinstance(images, list):
        return f"its 'images': expected a list of image records, got {json_kind(images)}"
    bad = [r for r in images if not (isinstance(r, dict) and all(isinstance(r.get(k), str) for k in ("image", "exr")))]
    if bad:
        return f"its 'images': {len(bad)} record(s) without the 'image' and 'exr' file names"
    return ""


def load_manifest(folder: Union[str, Path]) -> Dict[str, Any]:
    """Read a finished collection's ``manifest.json`` (raises ``FileNotFoundError`` if unfinished,
    :class:`~mitsuba_platonic.errors.UserError` naming it if it is damaged)."""
    path = Path(folder) / "manifest.json"
    if not path.exists():
        raise FileNotFoundError(f"{folder} has no manifest.json: the collection is unfinished "
                                f"(re-run make-dataset with the same settings to finish it)")
    try:
        m = json.loads(read_input_text(path, max_bytes=None))
        problem = manifest_problem(m)
    except ValueError as e:
        problem = f"not JSON: {' '.join(str(e).split())}"
    if problem:
        raise UserError(f"{path} is damaged ({problem}); re-run make-dataset with the same settings to rebuild it")
    return m


def missing_files(out: Path, spec: CollectionSpec) -> List[str]:
    """The files of the finished collection ``spec`` that ``out`` lacks (relative paths, in plan order)."""
    missing = []
    for i in range(spec.n_shapes):
        for k in range(spec.views_per_shape):
            missing += [rel for rel in (f"images/{image_id(i, k)}.png", f"exr/{image_id(i, k)}.exr")
                        if not (out / rel).is_file()]
        missing += [rel for rel in (f"volumes/{i:05d}.npz", f"volumes/{i:05d}.vol") if not (out / rel).is_file()]
    return missing


def is_finished(manifest_file: Path, spec: CollectionSpec) -> bool:
    """Whether the manifest says the collection ``spec`` is finished and all its files are there.
    A damaged manifest (not JSON, or JSON of another shape) is named in a warning: the
    collection is then finished again, which rebuilds it from ``records.jsonl``."""
    try:
        m = json.loads(read_input_text(manifest_file, max_bytes=None))
        problem = manifest_problem(m)
    except ValueError as e:                                  # not JSON, or not UTF-8
        problem = f"not JSON: {' '.join(str(e).split())}"
    if problem:
        warnings.warn(f"{manifest_file} is damaged ({problem}); it is rebuilt from the collection's records")
        return False
    out = manifest_file.parent
    return (CollectionSpec.from_dict(m["spec"]) == spec
            and all((out / r["image"]).exists() and (out / r["exr"]).exists() for r in m["images"])
            and not missing_files(out, spec))


def overwrite_plan(out: Path) -> List[Path]:
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
        spec = CollectionSpec.from_dict(json.loads(read_input_text(out / "collection.json", max_bytes=None)))
    except (OSError, ValueError, TypeError, AttributeError):
        pass
    owned = _owned(out, spec) if spec is not None else set()
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



def _owned(out: Path, spec: CollectionSpec) -> Set[str]:
    """The files (relative paths) the collection ``spec`` in ``out`` wrote or plans to: its plan, and
    every file its records and manifest name (a volume's ``.vol`` beside its ``.npz``)."""
    owned: Set[str] = set()
    for i in range(spec.n_shapes):                   # the plan: every file this spec writes
        owned |= {f"volumes/{i:05d}.npz", f"volumes/{i:05d}.vol"}
        for k in range(spec.views_per_shape):
            owned |= {f"images/{image_id(i, k)}.png", f"exr/{image_id(i, k)}.exr"}
    named = list(read_records(out / "records.jsonl").values())
    try:
        named += json.loads(read_input_text(out / "manifest.json", max_bytes=None))["images"]
    except (OSError, ValueError, KeyError, TypeError):
        pass
    for r in named:
        if isinstance(r, dict):
            owned |= {v for key in ("image", "exr", "volume") if isinstance(v := r.get(key), str)}
            if isinstance(r.get("volume"), str) and r["volume"].endswith(".npz"):
                owned.add(r["volume"][:-4] + ".vol")
    return owned


def temporaries(out: Path) -> List[Path]:
    """The temporaries a killed run left in ``out`` and its subfolders."""
    found: List[Path] = []
    for folder, pattern in [(out, _RECORD_TEMPORARY)] + [(out / sub, _TEMPORARY) for sub in SUBFOLDERS]:
        if folder.is_dir():
            found += [p for p in folder.iterdir() if pattern.fullmatch(p.name) and p.is_file()]
    return found


def remove_temporaries(out: Path) -> None:
    """Delete :func:`temporaries` (call it holding the collection's lock)."""
    for stray in temporaries(out):
        remove(stray, missing_ok=True)


@contextmanager
def lock(path: Path) -> Iterator[None]:
    """An exclusive advisory lock: one writer per collection folder (others wait). The lock file is
    opened, never truncated, and never through a link (:func:`~mitsuba_platonic.files.fileio.open_file`)."""
    import fcntl  # lazy: POSIX only, where a collection is locked
    fd = open_file(path, os.O_RDWR | os.O_CREAT)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        os.close(fd)
