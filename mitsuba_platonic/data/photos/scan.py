"""Scanning a folder: discovery, de-duplication, decoding of every unique file, the report.

1. **Discovery.** The folder is searched recursively; every regular file counts, whatever its
   sub-folder (published ``train/``, ``val/``, ``test/`` folders are ignored: the folder is one
   collection). Hidden files and folders (name starting with ``.``) are ignored and listed in
   :attr:`CollectionReport.ignored`. Symbolic links to folders are not followed.
2. **De-duplication.** Files with identical bytes (SHA-256 of the file) are one image; the
   copy with the smallest relative path (POSIX string order) is kept, the others are counted in
   :attr:`CollectionReport.duplicates` and listed in :attr:`CollectionReport.duplicate_groups`.
3. Each unique file goes through :func:`~.prepare.prepare_image` (decoding threads:
   ``min(8, CPUs)``); its ``(4, R, R)`` image is kept in memory (collections are small: 32
   photos at R = 64 take 2 MB).

Each rejected file is named in a :class:`~.rejections.PhotoCollectionWarning` and recorded in
:attr:`CollectionReport.skipped`. A folder with no usable image raises :class:`ValueError`
naming the folder and summarising the rejections; a missing folder raises
:class:`FileNotFoundError`.
"""

from __future__ import annotations

import hashlib
import logging
import os
import time
import warnings
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Tuple

import torch

from ...errors import UserError
from .decode import decode_image
from .mask import border_background, srgb_decoding_table
from .prepare import ImageOptions, prepare_image
from .rejections import REASONS, ImageRejected, PathLike, PhotoCollectionWarning
from .split import assign_splits

__all__ = ["SkippedFile", "PhotoEntry", "CollectionReport", "Scan", "scan", "opaque_photos_warning"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class SkippedFile:
    """A file that was not loaded: its path, a :data:`REASONS` key and a message naming it."""

    path: Path
    reason: str
    message: str


@dataclass(frozen=True)
class PhotoEntry:
    """One unique usable image of a collection.

    Attributes:
        path: the kept file (smallest relative path among byte-identical copies).
        sha256: hex SHA-256 of the file's bytes.
        size: ``(width, height)`` of the decoded photo (after EXIF orientation).
        format: ``"PNG"``, ``"JPEG"`` or ``"WEBP"``.
        bit_depth: 8 or 16.
        mask: ``"alpha"`` (the file's transparency) or ``"white"`` (white-background masking).
        duplicates: the other paths with the same bytes (dropped).
    """

    path: Path
    sha256: str
    size: Tuple[int, int]
    format: str
    bit_depth: int
    mask: str
    duplicates: Tuple[Path, ...] = ()


@dataclass
class CollectionReport:
    """What loading a folder found. ``str(report)`` gives a readable summary.

    Attributes:
        folder: the folder (absolute).
        files_found: regular, non-hidden files found (recursively).
        unique_files: distinct contents among them.
        duplicates: files dropped because an identical file was kept (``files_found −
            unique_files``).
        duplicate_groups: kept path → the dropped identical paths.
        usable: unique files that became training images.
        skipped: the unique files that were rejected, with reasons, in path order.
        ignored: hidden files and folders that were not looked at.
        split_sizes: images per split (``train``, ``val``, ``test``).
        seconds: wall time of the scan (hashing, decoding, resampling).
    """

    folder: Path
    files_found: int = 0
    unique_files: int = 0
    duplicates: int = 0
    duplicate_groups: Dict[Path, List[Path]] = field(default_factory=dict)
    usable: int = 0
    skipped: List[SkippedFile] = field(default_factory=list)
    ignored: List[Path] = field(default_factory=list)
    split_sizes: Dict[str, int] = field(default_factory=dict)
    seconds: float = 0.0

    @property
    def skipped_by_reason(self) -> Dict[str, int]:
        """Number of skipped files per reason (only reasons that occurred)."""
        counts: Dict[str, int] = {}
        for s in self.skipped:
            counts[s.reason] = counts.get(s.reason, 0) + 1
        return counts

    @property
    def skipped_files(self) -> List[Path]:
        """The paths of the skipped files."""
        return [s.path for s in self.skipped]

    def summary(self) -> str:
        """A few readable lines."""
        lines = [f"photo collection {self.folder}: {self.files_found} file(s), "
                 f"{self.unique_files} unique ({self.duplicates} duplicate(s) dropped), "
                 f"{self.usable} usable, {len(self.skipped)} skipped; "
                 f"{self.seconds:.2f} s"]
        if self.split_sizes:
            lines.append("  splits: " + ", ".join(f"{k} {v}" for k, v in self.split_sizes.items()))
        for reason, count in self.skipped_by_reason.items():
            lines.append(f"  skipped {count} × {reason} ({REASONS[reason]})")
        for s in self.skipped:
            lines.append(f"    {s.message}")
        if self.ignored:
            lines.append(f"  ignored {len(self.ignored)} hidden path(s)")
        return "\n".join(lines)

    __str__ = summary


def _examples(paths: List[Path], root: Path, shown: int = 3) -> str:
    names = [p.relative_to(root).as_posix() for p in sorted(paths)]
    return ", ".join(names[:shown]) + (f" and {len(names) - shown} more" if len(names) > shown else "")


def opaque_photos_warning(borders: Dict[Path, str], usable: int, root: Path) -> str:
    """The one warning line on a collection's photos without transparency (masked as photos on white,
    ``data.background: white``), ``borders`` what each one's border shows (:func:`~.mask.border_background`):
    how many there are with a few names, and how many of them and which do not show white around
    the object, whose mask is then (nearly) the whole frame."""
    line = (f"{len(borders)} of {usable} usable photo(s) have no transparency and were masked as photos on a "
            f"white background (data.background: white): {_examples(list(borders), root)}")
    wrong = {kind: [p for p, b in borders.items() if b == kind] for kind in ("black", "other")}
    if not any(wrong.values()):
        return line
    count = sum(len(v) for v in wrong.values())
    shown = "; ".join(f"{len(v)} on {'black' if kind == 'black' else 'another colour or a busy background'}: "
                      f"{_examples(v, root)}" for kind, v in wrong.items() if v)
    return (f"{line}; but {count} of them do not show a white background around the object ({shown}), so their "
            f"mask is (nearly) the whole frame: cut them out (PNG with transparency), photograph them on white, or "
            f"leave them out")


def _discover(folder: Path) -> Tuple[List[Path], List[Path], List[Path]]:
    """Files under ``folder``: regular non-hidden files (sorted by relative path), ignored
    hidden paths, and other non-hidden entries that are not regular files (broken links...)."""
    files: List[Path] = []
    ignored: List[Path] = []
    others: List[Path] = []
    for root, dirs, names in os.walk(folder, followlinks=False):
        root_path = Path(root)
        for d in sorted(dirs):
            if d.startswith("."):
                ignored.append(root_path / d)
        dirs[:] = sorted(d for d in dirs if not d.startswith("."))
        for n in sorted(names):
            p = root_path / n
            if n.startswith("."):
                ignored.append(p)
            elif p.is_file():
                files.append(p)
            else:
                others.append(p)
    files.sort(key=lambda p: p.relative_to(folder).as_posix())
    return files, sorted(ignored), others


def _file_sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _load_one(path: Path, options: ImageOptions):
    """Worker: decode and prepare one file → (entry fields, (4, R, R) array) or a SkippedFile."""
    try:
        decoded = decode_image(path)
        image = prepare_image(decoded, options.resolution, name=str(path),
                              **options.image_kwargs())
    except ImageRejected as err:
        return SkippedFile(path, err.reason, err.message)
    except OSError as err:
        return SkippedFile(path, "unreadable", f"{path}: cannot read the file "
                                               f"({type(err).__name__}: {err})")
    real_alpha = decoded.has_alpha and bool((decoded.pixels[..., 3] < decoded.max_value).any())
    border = None if real_alpha else border_background(decoded.pixels[..., :3], decoded.max_value, options.threshold)
    info = (decoded.size, decoded.format, decoded.bit_depth, "alpha" if real_alpha else "white")
    return info, image, border


@dataclass
class Scan:
    """A scanned folder: its usable images, their split assignment and the report."""

    entries: Dict[str, PhotoEntry]          # sha256 → entry (usable images)
    images: Dict[str, torch.Tensor]         # sha256 → (4, R, R)
    assignment: Dict[str, List[str]]        # split → sha256 list (content-hash order)
    report: CollectionReport
    options: ImageOptions
    fractions: Tuple[float, float, float]
    seed: int


def scan(folder: PathLike, options: ImageOptions, splits: Tuple[float, float, float],
         seed: int) -> Scan:
    """Discover, de-duplicate, decode and split a folder (see the module docstring)."""
    start = time.perf_counter()
    root = Path(folder).expanduser()
    if not root.exists():
        raise FileNotFoundError(f"photo folder {str(root)!r} does not exist")
    if not root.is_dir():
        raise NotADirectoryError(f"photo folder {str(root)!r} is not a folder")
    root = root.resolve()
    report = CollectionReport(folder=root)
    files, report.ignored, others = _discover(root)
    report.files_found = len(files) + len(others)
    report.skipped = [SkippedFile(p, "unreadable", f"{p}: not a regular file (a broken link?)")
                      for p in others]
    if not files and not others:
        hidden = (f"; only {len(report.ignored)} hidden entr(y/ies), which are ignored"
                  if report.ignored else "")
        raise UserError(f"no usable images in {str(root)!r}: the folder is empty (no files "
                        f"in it or its sub-folders{hidden})")

    groups: Dict[str, List[Path]] = {}
    for p in files:  # sorted by relative path: the first of a group is kept
        try:
            digest = _file_sha256(p)
        except OSError as err:
            report.skipped.append(SkippedFile(p, "unreadable", f"{p}: cannot read the file "
                                                               f"({type(err).__name__}: {err})"))
            continue
        groups.setdefault(digest, []).append(p)
    report.unique_files = len(groups) + len(report.skipped)  # unreadable files count once
    report.duplicates = sum(len(g) - 1 for g in groups.values())
    report.duplicate_groups = {g[0]: g[1:] for g in groups.values() if len(g) > 1}

    keys = list(groups)
    srgb_decoding_table(8)           # import colour-science (slow) once, before any thread
    import scipy.ndimage  # noqa: F401  (likewise)
    n_workers = min(8, os.cpu_count() or 1)
    if n_workers > 1 and len(keys) > 1:
        with ThreadPoolExecutor(max_workers=n_workers) as pool:
            results = list(pool.map(lambda k: _load_one(groups[k][0], options), keys))
    else:
        results = [_load_one(groups[k][0], options) for k in keys]

    entries: Dict[str, PhotoEntry] = {}
    images: Dict[str, torch.Tensor] = {}
    borders: Dict[Path, str] = {}                      # photos without transparency → what their border shows
    for key, result in zip(keys, results):
        if isinstance(result, SkippedFile):
            report.skipped.append(result)
            continue
        (size, fmt, bits, mask), image, border = result
        entries[key] = PhotoEntry(groups[key][0], key, size, fmt, bits, mask,
                                  tuple(groups[key][1:]))
        images[key] = torch.from_numpy(image)
        if border is not None:
            borders[groups[key][0]] = border
    report.skipped.sort(key=lambda s: s.path.relative_to(root).as_posix())
    report.usable = len(entries)
    for s in report.skipped:
        warnings.warn(f"skipped {s.message} [{s.reason}]", PhotoCollectionWarning, stacklevel=3)
    if borders:
        warnings.warn(opaque_photos_warning(borders, len(entries), root), PhotoCollectionWarning, stacklevel=3)

    if not entries:
        reasons = "; ".join(f"{count} {reason}" for reason, count in
                            report.skipped_by_reason.items())
        detail = "\n  ".join(s.message for s in report.skipped)
        raise UserError(f"no usable images in {str(root)!r}: all {report.unique_files} unique "
                        f"file(s) were rejected ({reasons}):\n  {detail}")

    assignment = assign_splits(list(entries), splits, seed)
    report.split_sizes = {k: len(assignment[k]) for k in ("train", "val", "test")}
    report.seconds = time.perf_counter() - start
    logger.info("%s", report.summary())
    return Scan(entries, images, assignment, report, options, splits, seed)
