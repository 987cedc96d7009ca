"""Volume files: a ``(C, N, N, N)`` volume read from and written to ``.npz`` and Mitsuba ``.vol``.

The one place that knows the two file formats (docs/conventions.md, "Volumes"):

- ``.npz``: a numpy archive with the array ``volume``, ``(C, N, N, N)`` (or ``(1, C, N, N, N)``),
  C = 4 ``[r, g, b, density]`` or 1 ``[density]``, values in [0, 1]. :func:`read_npz` checks all
  of that and says what is wrong; :func:`write_npz` writes it.
- ``.vol``: Mitsuba's grid file, written here with numpy byte for byte as ``mi.VolumeGrid.write``
  does (so writing one needs neither Mitsuba nor LLVM): ``VOL``, version 3, encoding 1 (float32),
  the sizes x, y, z and the channel count (int32), the bounding box [0, 1]³ (6 float32), then the
  grid ``[Z, Y, X, C]`` (:func:`to_mitsuba_grid`) with C fastest, little-endian.

:func:`save_volume` writes both beside each other, each whole or not at all; :func:`load_volume`
reads a volume the command line names (``builtin:<kind>`` or a ``.npz`` file).

A file is checked before it is read (:func:`~mitsuba_platonic.files.fileio.check_input_file`: a
regular file, no FIFO or device), and the size it declares (a ``.npz``'s array header, a ``.vol``'s
length) is handed to the reader's ``fits`` (the command's memory check,
:func:`mitsuba_platonic.runtime.budget.memory_check`, which this layer below the machine's does not
import) before anything of that size is allocated: a small compressed file may declare a volume of
many gigabytes.

Importing it loads numpy, not torch: :func:`read_volume_array` reads and checks a file with numpy
alone (``platonic view`` checks its SOURCE before torch has loaded); the functions that return
tensors import torch when they run.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Callable, List, Optional, Union

import numpy as np

from ..errors import UserError
from .fileio import InputFileRefused, atomic_write, check_input_file, make_folder, read_input_file

if TYPE_CHECKING:
    import torch

__all__ = ["BUILTIN_PREFIX", "VolumeFileError", "to_mitsuba_grid", "read_npz", "read_vol", "read_volume_file",
           "read_volume_array",
           "load_volume", "write_npz", "write_vol", "save_volume"]

PathLike = Union[str, Path]
#: A memory check: ``fits(bytes, what)`` raises a :class:`~mitsuba_platonic.errors.UserError` where
#: ``bytes`` cannot be allocated (:func:`mitsuba_platonic.runtime.budget.memory_check`).
Fits = Optional[Callable[[int, str], None]]

#: How a built-in test volume is named where a volume file could be: ``builtin:figure``.
BUILTIN_PREFIX = "builtin:"

#: The ``.vol`` header before the sizes: magic, version 3, encoding 1 (float32).
_VOL_MAGIC = b"VOL\x03" + np.int32(1).astype("<i4").tobytes()


class VolumeFileError(UserError):
    """A volume file that does not exist, cannot be read or holds no valid volume."""


def to_mitsuba_grid(v: torch.Tensor) -> torch.Tensor:
    """``(C, D, H, W)`` torch volume → ``(N, N, N, C)`` Mitsuba grid ``[Z, Y, X, C]`` (a view, no copy):
    a permute and two flips (Z = N−1−d, Y = N−1−h, X = w), the layout of Mitsuba's grids and ``.vol`` files."""
    return v.permute(1, 2, 3, 0).flip(0, 1)                   # [d, h, w, c] → [Z, Y, X, C]


# --------------------------------------------------------------------------- reading


def _existing_file(path: Path) -> "tuple[Path, str]":
    """``(Path, its name)``; :class:`VolumeFileError` where it is missing or not a file."""
    path = Path(path)
    name = str(path)
    if not path.exists():
        raise VolumeFileError(f"volume file {name!r} does not exist")
    try:
        check_input_file(path, "volume file")
    except InputFileRefused as e:
        raise VolumeFileError(str(e)) from None
    return path, name


#: The bytes reading a volume of ``n`` values of ``itemsize`` bytes takes at least: the array as
#: stored, and its float32 copy (:func:`_checked`).
def _reading_bytes(n: int, itemsize: int) -> int:
    return n * (itemsize + 4)


def _check_declared(name: str, shape: "tuple[int, ...]", itemsize: int, fits: Fits) -> None:
    """:class:`VolumeFileError` where ``fits`` refuses the bytes reading the array of ``shape`` that
    file ``name`` declares takes (before it is allocated); nothing is checked without ``fits``."""
    if fits is None:
        return
    n = int(np.prod(shape, dtype=object)) if shape else 1
    try:
        fits(_reading_bytes(n, itemsize), f"{name!r}: its array 'volume' of shape {tuple(shape)}")
    except UserError as e:
        raise VolumeFileError(str(e)) from None


def _npz_header(archive: "np.lib.npyio.NpzFile", name: str) -> "tuple[tuple[int, ...], np.dtype]":
    """The shape and dtype the ``volume`` member of ``archive`` declares, read from its ``.npy`` header
    alone (nothing decompressed beyond it)."""
    fmt = np.lib.format
    try:
        member = "volume.npy" if "volume.npy" in archive.zip.namelist() else "volume"
        with archive.zip.open(member) as f:
            version = fmt.read_magic(f)
            read = {(1, 0): fmt.read_array_header_1_0, (2, 0): fmt.read_array_header_2_0}.get(version)
            if read is None:
                raise ValueError(f"format version {version}")
            shape, _, dtype = read(f)
    except Exception as e:
        raise VolumeFileError(f"could not read array 'volume' from {name!r}: {e}") from None
    return tuple(int(d) for d in shape), dtype


def _tensor(v: np.ndarray) -> "torch.Tensor":
    """A checked ``(C, N, N, N)`` array → the ``(1, C, N, N, N)`` tensor on its memory."""
    import torch  # lazy: reading a file into numpy (read_volume_array) needs no torch

    return torch.from_numpy(v)[None]


def read_npz(path: Path, fits: Fits = None) -> torch.Tensor:
    """Read and validate the array ``volume`` of a ``.npz`` file → ``(1, C, N, N, N)`` float32.

    Raises :class:`VolumeFileError` naming the file and what is wrong (missing, not an archive, no
    array ``volume``, a wrong shape, values outside [0, 1], a declared size ``fits`` refuses, …)."""
    return _tensor(_npz_array(path, fits))


def _npz_array(path: Path, fits: Fits = None) -> np.ndarray:
    """:func:`read_npz`'s checked ``(C, N, N, N)`` array, read with numpy alone."""
    path, name = _existing_file(path)
    try:
        archive = np.load(path, allow_pickle=False)
    except OSError as e:    # the file itself (permissions, I/O)
        raise VolumeFileError(f"could not read {name!r}: {e.strerror or e}") from None
    except Exception:       # numpy's text for other content advises allow_pickle, which would run its code
        raise VolumeFileError(f"{name!r} is not a valid .npz volume (not a numpy archive, or a damaged one); "
                              f"expected a file written by numpy.savez(path, volume=array)") from None
    if not isinstance(archive, np.lib.npyio.NpzFile):
        raise VolumeFileError(f"{name!r} is a single .npy array, not a .npz archive; save it with "
                              f"numpy.savez({name!r}, volume=array)")
    with archive:
        if "volume" not in archive.files:
            found = ", ".join(archive.files) or "no arrays"
            raise VolumeFileError(f"{name!r} has no array named 'volume' (found: {found}); save it with "
                                  f"numpy.savez(path, volume=array)")
        shape, dtype = _npz_header(archive, name)
        _check_declared(name, shape, dtype.itemsize, fits)    # before the array is decompressed
        try:
            v = archive["volume"]
        except Exception as e:
            raise VolumeFileError(f"could not read array 'volume' from {name!r}: {e}") from None
    return _checked(v, name)


def read_vol(path: Path, fits: Fits = None) -> torch.Tensor:
    """Read a Mitsuba ``.vol`` grid (float32, the layout :func:`write_vol` writes) → ``(1, C, N, N, N)``
    float32, checked as :func:`read_npz` checks its array (cubic, C = 1 or 4, values in [0, 1]).

    Raises :class:`VolumeFileError` naming the file and what is wrong (missing, not a ``.vol``, an
    encoding other than float32, a size that does not match its header, …)."""
    return _tensor(_vol_array(path, fits))


def _vol_array(path: Path, fits: Fits = None) -> np.ndarray:
    """:func:`read_vol`'s checked ``(C, N, N, N)`` array, read with numpy alone."""
    path, name = _existing_file(path)
    _check_declared(name, (path.stat().st_size // 4,), 4, fits)   # the whole file is read, then copied
    try:
        data = read_input_file(path, "volume file", max_bytes=None)
    except InputFileRefused as e:
        raise VolumeFileError(str(e)) from None
    header = len(_VOL_MAGIC) + 4 * 4 + 6 * 4
    if len(data) < header or data[:3] != b"VOL":
        raise VolumeFileError(f"{name!r} is not a Mitsuba .vol file (it does not start with 'VOL' and a header)")
    if data[:len(_VOL_MAGIC)] != _VOL_MAGIC:
        raise VolumeFileError(f"{name!r}: only version 3 .vol files of float32 values (encoding 1) are read")
    x, y, z, c = (int(i) for i in np.frombuffer(data, "<i4", 4, len(_VOL_MAGIC)))
    if min(x, y, z, c) < 1 or len(data) - header != 4 * x * y * z * c:
        raise VolumeFileError(f"{name!r}: its header says {x}×{y}×{z}×{c} values, its body holds "
                              f"{(len(data) - header) // 4} (a truncated or damaged file)")
    grid = np.frombuffer(data, "<f4", x * y * z * c, header).reshape(z, y, x, c)
    v = grid[::-1, ::-1].transpose(3, 0, 1, 2)          # [Z, Y, X, C] → (C, D, H, W): to_mitsuba_grid's inverse
    return _checked(v, name)


def read_volume_file(path: PathLike, fits: Fits = None) -> torch.Tensor:
    """A ``.npz`` (:func:`read_npz`) or ``.vol`` (:func:`read_vol`) file → ``(1, C, N, N, N)``."""
    return _tensor(read_volume_array(path, fits))


def read_volume_array(path: PathLike, fits: Fits = None) -> np.ndarray:
    """A ``.npz`` or ``.vol`` file → its checked ``(C, N, N, N)`` float32 array (what
    :func:`read_volume_file` returns, as numpy, read and checked without torch); the same errors."""
    path = Path(path)
    if path.suffix.lower() == ".npz":
        return _npz_array(path, fits)
    if path.suffix.lower() == ".vol":
        return _vol_array(path, fits)
    raise VolumeFileError(f"{str(path)!r}: expected a volume file ending in .npz or .vol")


def _checked(v: np.ndarray, name: str) -> np.ndarray:
    """The array ``volume`` of file ``name`` as a contiguous ``(C, N, N, N)`` float32, or :class:`VolumeFileError`."""
    expected = ("must have shape (C, N, N, N) or (1, C, N, N, N) with C = 4 [r, g, b, density] "
                "or C = 1 [density]")
    if v.ndim == 5:
        if v.shape[0] != 1:
            raise VolumeFileError(f"{name!r}: array 'volume' {expected}, got shape {v.shape} "
                                  f"(batch {v.shape[0]} ≠ 1)")
        v = v[0]
    if v.ndim != 4:
        raise VolumeFileError(f"{name!r}: array 'volume' {expected}, got shape {v.shape}")
    if v.shape[0] not in (1, 4):
        raise VolumeFileError(f"{name!r}: array 'volume' {expected}, got shape {v.shape} with C = {v.shape[0]}")
    if not v.shape[1] == v.shape[2] == v.shape[3]:
        raise VolumeFileError(f"{name!r}: array 'volume' must be cubic (N, N, N), got spatial shape {v.shape[1:]}")
    if v.shape[1] < 2:
        raise VolumeFileError(f"{name!r}: array 'volume' needs a resolution N of at least 2, got {v.shape[1]}")
    if not (np.issubdtype(v.dtype, np.floating) or np.issubdtype(v.dtype, np.integer) or v.dtype == bool):
        raise VolumeFileError(f"{name!r}: array 'volume' must hold numbers, got dtype {v.dtype}")
    v = v.astype(np.float32)
    if not np.isfinite(v).all():
        raise VolumeFileError(f"{name!r}: array 'volume' contains NaN or Inf")
    lo, hi = float(v.min()), float(v.max())
    if lo < 0.0 or hi > 1.0:
        bad = np.argwhere((v < 0.0) | (v > 1.0))
        raise VolumeFileError(f"{name!r}: array 'volume' values must lie in [0, 1], got range "
                              f"[{lo:.6g}, {hi:.6g}] ({len(bad)} value(s) outside, the first at index "
                              f"{tuple(int(i) for i in bad[0])}, channel first)")
    return np.ascontiguousarray(v)


def load_volume(spec: str, resolution: Optional[int] = None, fits: Fits = None) -> torch.Tensor:
    """``builtin:<kind>`` (a :func:`~mitsuba_platonic.volume.test_volume` at ``resolution``, default
    32) or a path to a ``.npz`` file holding ``volume`` → ``(1, C, N, N, N)``, C = 4 or 1.

    For a file, ``resolution`` (if given) must match the file's N. The messages name the command
    line's ``--volume`` and ``--resolution``, which pass ``spec`` and ``resolution`` through.
    """
    from ..volume import TEST_VOLUMES, test_volume  # lazy: torch, which reading a file into numpy does without

    if spec.startswith(BUILTIN_PREFIX):
        kind = spec[len(BUILTIN_PREFIX):]
        if kind not in TEST_VOLUMES:
            choices = ", ".join(BUILTIN_PREFIX + k for k in TEST_VOLUMES)
            raise VolumeFileError(f"unknown built-in volume {spec!r}; expected one of {choices} or a .npz file")
        n = 32 if resolution is None else resolution
        return test_volume(n, kind, "ea")
    path = Path(spec)
    if path.suffix.lower() != ".npz":
        raise VolumeFileError(f"--volume must be builtin:figure, builtin:cloud or a .npz file, got {spec!r}")
    v = read_npz(path, fits)
    if resolution is not None and resolution != v.shape[-1]:
        raise VolumeFileError(f"--resolution {resolution} does not match {spec!r}, whose volume is "
                              f"{v.shape[-1]}³ (leave --resolution out for files)")
    return v


# --------------------------------------------------------------------------- writing


def write_npz(volume: torch.Tensor, path: PathLike) -> Path:
    """Write a ``(C, N, N, N)`` volume to ``path`` as a compressed ``.npz`` with the array ``volume``
    (directly: wrap it in :func:`~mitsuba_platonic.files.fileio.atomic_write` for a whole-or-nothing file)."""
    np.savez_compressed(path, volume=volume.detach().float().cpu().numpy())
    return Path(path)


def write_vol(volume: torch.Tensor, path: PathLike) -> Path:
    """Write a ``(C, N, N, N)`` volume in Mitsuba's ``.vol`` format (grid layout ``[Z, Y, X, C]``), the
    bytes ``mi.VolumeGrid(grid).write(path)`` writes, without Mitsuba."""
    grid = to_mitsuba_grid(volume.detach().float().cpu()).contiguous().numpy()
    z, y, x, c = grid.shape
    header = _VOL_MAGIC + np.array([x, y, z, c], "<i4").tobytes() + np.array([0, 0, 0, 1, 1, 1], "<f4").tobytes()
    with open(path, "wb") as f:
        f.write(header)
        f.write(grid.astype("<f4", copy=False).tobytes())
    return Path(path)


def save_volume(volume: torch.Tensor, stem: PathLike) -> List[Path]:
    """Write a ``(C, N, N, N)`` volume as ``stem.npz`` (array ``volume``) and ``stem.vol`` (Mitsuba),
    each whole or not at all (:func:`~mitsuba_platonic.files.fileio.atomic_write`); ``stem`` keeps its dots
    (``shot.v1`` → ``shot.v1.npz``)."""
    stem = Path(stem)
    make_folder(stem.parent)
    npz, vol = stem.with_name(stem.name + ".npz"), stem.with_name(stem.name + ".vol")
    volume = volume.detach().float().cpu()
    atomic_write(npz, lambda tmp: write_npz(volume, tmp))
    atomic_write(vol, lambda tmp: write_vol(volume, tmp))
    return [npz, vol]
