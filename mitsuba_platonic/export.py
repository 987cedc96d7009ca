"""Export: a volume's files (.npz, Mitsuba .vol), turntable GIFs, and meshes (PLY with vertex colours).

:func:`export_volume` writes all of them for one volume (the volume files through
:func:`~mitsuba_platonic.files.volume_io.save_volume`, which owns their formats);
:func:`export_reconstructions` and :func:`export_samples` are the ``reconstruct`` and ``generate``
pipelines (a model's volumes, then :func:`export_volume`), which the command line and the
quickstart call.

Mesh extraction: marching cubes on the density channel at iso-level ``level`` (scikit-image),
in voxel-index space ``(d, h, w)``, mapped to the world by the volume convention
x = −1 + (w + ½)Δ, y = 1 − (h + ½)Δ, z = 1 − (d + ½)Δ; the flips reverse the triangle winding,
so faces are re-ordered to keep normals pointing out. Vertex colours are the RGB channels
sampled trilinearly at the vertices, sRGB-encoded to 8 bits (PLY viewers display sRGB).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Iterator, List, Optional, Sequence, Tuple, Union

import numpy as np
import torch
import torch.nn.functional as F

from .errors import UserError
from .files.fileio import atomic_write, make_folder, remove
from .files.names import readable_name
from .files.volume_io import save_volume
from .images import composite, linear_to_srgb, save_png, to_hwc
from .render.frames import display_frames, save_gif, turntable_frames
from .sheets import CELL, save_interpolation, save_sample_grid, save_turntables
from .runtime import budget
from .runtime.progress import progress_bar
from .volume import voxel_size, world_to_grid

if TYPE_CHECKING:
    from .model import Model

#: save_volume is volume_io's, named here too for the callers that import it from export (notebooks).
__all__ = ["save_volume", "display_frames", "turntable_frames", "save_gif", "extract_mesh",
           "save_ply", "Mesh", "Exported", "export_volume", "export_reconstructions", "export_samples", "check_samples_fit", "output_names", "TURNTABLE_AZIMUTHS", "INTERPOLATION_STEPS",
           "EXPORT_EXTENSIONS"]

PathLike = Union[str, Path]


def _with_ext(stem: Path, ext: str) -> Path:
    """``stem`` + ``ext`` (``shot.v1`` → ``shot.v1.npz``; ``Path.with_suffix`` would give ``shot.npz``)."""
    return stem.with_name(stem.name + ext)


class Mesh:
    """vertices ``(V, 3)`` world coordinates, faces ``(F, 3)`` indices, colours ``(V, 3)`` uint8."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, colours: np.ndarray):
        self.vertices, self.faces, self.colours = vertices, faces, colours


def extract_mesh(volume: torch.Tensor, level: float = 0.5) -> Mesh:
    """Marching cubes on the density (last channel) of ``(C, N, N, N)`` at ``level``."""
    from skimage.measure import marching_cubes  # lazy: scikit-image, only for meshes

    v = volume.detach().float().cpu()
    density = v[-1].numpy()
    if not density.min() < level < density.max():
        raise ValueError(f"the density never crosses the iso-level {level} (range "
                         f"[{density.min():.3g}, {density.max():.3g}]): no surface to extract")
    n = density.shape[-1]
    Δ = voxel_size(n)
    # pad with empty space so surfaces touching the border close
    verts_idx, faces, _, _ = marching_cubes(np.pad(density, 1), level=level)
    verts_idx -= 1.0
    d, h, w = verts_idx[:, 0], verts_idx[:, 1], verts_idx[:, 2]
    world = np.stack([-1.0 + (w + 0.5) * Δ, 1.0 - (h + 0.5) * Δ, 1.0 - (d + 0.5) * Δ], axis=1)
    faces = faces[:, ::-1].copy()                      # two axis flips → one reflection: fix winding
    if v.shape[0] == 4:
        grid = world_to_grid(torch.from_numpy(world).float())[None, :, None, None, :]
        rgb = F.grid_sample(v[None, :3], grid, mode="bilinear", padding_mode="border",
                            align_corners=False)[0, :, :, 0, 0].T.numpy()
        colours = (linear_to_srgb(rgb) * 255 + 0.5).astype(np.uint8)
    else:
        colours = np.full((len(world), 3), 200, np.uint8)
    return Mesh(world.astype(np.float32), faces.astype(np.int32), colours)


def save_ply(mesh: Mesh, path: PathLike) -> Path:
    """Binary little-endian PLY with float x, y, z, uchar red, green, blue and triangle faces."""
    path = Path(path)
    make_folder(path.parent)
    header = ("ply\nformat binary_little_endian 1.0\ncomment mitsuba-platonic marching cubes\n"
              f"element vertex {len(mesh.vertices)}\nproperty float x\nproperty float y\nproperty float z\n"
              "property uchar red\nproperty uchar green\nproperty uchar blue\n"
              f"element face {len(mesh.faces)}\nproperty list uchar int vertex_indices\nend_header\n")
    vertex = np.empty(len(mesh.vertices), dtype=[("p", "<f4", 3), ("c", "u1", 3)])
    vertex["p"], vertex["c"] = mesh.vertices, mesh.colours
    face = np.empty(len(mesh.faces), dtype=[("n", "u1"), ("i", "<i4", 3)])
    face["n"], face["i"] = 3, mesh.faces
    def write(tmp: Path) -> None:
        with open(tmp, "wb") as f:
            f.write(header.encode("ascii"))
            f.write(vertex.tobytes())
            f.write(face.tobytes())

    atomic_write(path, write)
    return path


# --------------------------------------------------------------------------- whole volumes


@dataclass
class Exported:
    """What :func:`export_volume` wrote (``paths``), and why it wrote no mesh (``no_mesh``) if it did not."""

    paths: List[Path] = field(default_factory=list)
    no_mesh: Optional[str] = None


def export_volume(volume: torch.Tensor, stem: PathLike, model: str, level: Optional[float] = 0.5,
                  frames: int = 36, written: Optional[List[Path]] = None) -> Exported:
    """One ``(C, N, N, N)`` volume → ``stem.npz``, ``stem.vol``, a turntable ``stem.gif`` of
    ``frames`` closed-form ``model`` renders and, unless ``level`` is None, a marching-cubes
    mesh ``stem.ply`` at that iso-level (none where the density never crosses it: ``no_mesh`` says so).
    Each file is whole or absent; ``written`` (if given) is appended each path as it is complete."""
    stem = Path(stem)
    volume = volume.detach().float().cpu()
    done = Exported()
    written = [] if written is None else written

    def wrote(*paths: Path) -> None:
        done.paths.extend(paths)
        written.extend(paths)

    wrote(*save_volume(volume, stem))
    wrote(save_gif(turntable_frames(volume, model, frames=frames), _with_ext(stem, ".gif")))
    if level is not None:
        try:
            mesh = extract_mesh(volume, level=level)
        except ValueError as e:                          # the density never crosses the level: no surface
            done.no_mesh = str(e)
        else:
            wrote(save_ply(mesh, _with_ext(stem, ".ply")))
    return done


def export_held_out(model: "Model", images: torch.Tensor, folder: PathLike, n: int = 4) -> List[Path]:
    """Up to ``n`` of the ``(M, C, R, R)`` held-out ``images``, spread over the set (different shapes
    or photos), reconstructed by ``model`` in the object's frame (upright for a model with a pose
    head, :meth:`~mitsuba_platonic.model.Model.reconstruct_upright`: its turntable turns about the
    object's vertical axis, its mesh stands) and exported with :func:`export_volume` as
    ``folder/heldout_<i>.*`` beside ``heldout_<i>_input.png`` (the image over white); returns the
    turntables and meshes written."""

    written: List[Path] = []
    picks = torch.linspace(0, len(images) - 1, min(n, len(images))).long().tolist()
    for i, j in enumerate(picks):
        stem = Path(folder) / f"heldout_{i}"
        done = export_volume(model.reconstruct_upright(images[j:j + 1])[0][0], stem, model.formation)
        written += [p for p in done.paths if p.suffix in (".gif", ".ply")]
        save_png(stem.with_name(stem.name + "_input.png"), linear_to_srgb(composite(to_hwc(images[j]), 1.0)))
    return written


#: The files :func:`export_volume` writes per name (``.ply`` only for reconstructions).
EXPORT_EXTENSIONS = (".npz", ".vol", ".gif", ".ply")



def output_names(images: Sequence[PathLike]) -> List[str]:
    """One distinct output name per input image, all inside the output folder.

    The name is the image's file name without its last extension (``shot.v1.png`` → ``shot.v1``),
    with characters other than letters and digits of any script (``Tür.jpg`` → ``Tür``;
    :func:`~mitsuba_platonic.files.names.readable_name`) and ``. _ + -`` replaced by ``_`` and leading
    dots by ``_`` (``..png`` → ``_``: never ``.``, ``..`` or a hidden file). A name an earlier input (in
    command-line order) already took, compared without regard to case, gets ``_2``, ``_3``, …
    (``a/x.png b/x.png`` → ``x``, ``x_2``).
    """
    names: List[str] = []
    taken = set()
    for image in images:
        base = readable_name(Path(image).stem, keep="._+-")
        if base.startswith(".") or not base:
            base = "_" + base.lstrip(".")
        name, k = base, 1
        while name.casefold() in taken:
            k += 1
            name = f"{base}_{k}"
        taken.add(name.casefold())
        names.append(name)
    return names


def _refuse_earlier(out: Path, found: List[Path]) -> None:
    """Raise :class:`UserError` naming what an earlier call left in ``out`` that this one would replace."""
    if found:
        shown = ", ".join(p.name for p in found[:4]) + (f" and {len(found) - 4} more" if len(found) > 4 else "")
        raise UserError(f"--out {out} already holds {shown} from an earlier call, which this call would "
                        f"replace; choose another --out, or pass --overwrite to replace them")


def export_reconstructions(model: "Model", images: Sequence[PathLike], out: PathLike, background: Optional[str] = None,
                           crop: str = "image", level: float = 0.5, overwrite: bool = False,
                           written: Optional[List[Path]] = None) -> Iterator[Tuple[Path, Exported]]:
    """``platonic reconstruct``: each image file → its volume → :func:`export_volume` as
    ``out/<name>.*`` (:func:`output_names`: one name per input); yields (image path, what was
    written) as each one is done. Unless ``overwrite``, refuses (:class:`UserError`, before any
    work) where a file it would write exists already. ``written`` collects every complete file."""
    out = Path(out)
    names = output_names(images)
    if not overwrite:
        _refuse_earlier(out, [out / (n + e) for n in names for e in EXPORT_EXTENSIONS if (out / (n + e)).exists()])
    for image, name in zip(images, names):
        path = Path(image)
        vol = model.reconstruct(model.load_image(path, background=background, crop=crop))[0]
        yield path, export_volume(vol, out / name, model.formation, level=level, written=written)


_SAMPLE = re.compile(r"sample_\d{3,}\.(npz|vol|gif|ply)|samples\.png|turntables\.png|interpolation\.png")


def check_samples_fit(model: "Model", n: int, out: PathLike) -> None:
    """:class:`UserError` naming ``-n`` where ``n`` samples cannot fit, before any work: the volumes
    ``model.generate`` holds at once (each twice: G's output and its CPU copy or logits) in the memory
    available, or their ``.vol`` files alone on the disk of ``out`` (lower bounds)."""
    volume = model.channels * model.resolution ** 3 * 4
    memory = budget.available_memory()
    if memory[0] is not None:
        most = max(memory[0], 0) // (2 * volume)
        budget.check_fits(2 * volume * n, memory, f"-n {n}: generating {n} volumes of {model.resolution}³ at once",
                          f"lower -n (at most about {most} fit)" if most else "not even one fits")
    disk = budget.free_disk(out)
    if disk[0] is not None:
        most = max(disk[0], 0) // (volume + 48)
        budget.check_fits((volume + 48) * n, disk, f"-n {n}: writing the .vol files of {n} samples alone",
                          f"lower -n (at most about {most} fit), or choose another --out", resource="disk space")


#: ``platonic generate``'s sheets (:mod:`mitsuba_platonic.sheets`): azimuths per turntable, steps of the walk.
TURNTABLE_AZIMUTHS = 8
INTERPOLATION_STEPS = 8


def export_samples(model: "Model", n: int, out: PathLike, seed: int = 0, overwrite: bool = False,
                   written: Optional[List[Path]] = None, progress: bool = False, cell: int = CELL,
                   turntables: int = TURNTABLE_AZIMUTHS, interpolation: int = INTERPOLATION_STEPS) -> List[Path]:
    """``platonic generate``: ``n`` volumes of ``model.generate(n, seed)`` → ``out/sample_NNN``
    .npz/.vol/.gif (24-frame turntables) and the sheets of :mod:`mitsuba_platonic.sheets`, every tile
    at least ``cell`` pixels: ``out/samples.png`` (the labelled grid), ``out/turntables.png`` (a line of
    ``turntables`` azimuths per sample; 0: none) and ``out/interpolation.png`` (``interpolation`` steps
    of the spherical walk from sample 0's latent to sample 1's, :func:`~mitsuba_platonic.sheets.slerp`;
    0 or n < 2: none); returns every path written, the sheets last.

    A folder holding an earlier call's samples is refused (:class:`UserError`, before any work),
    so that no old ``sample_NNN`` is left beside new ones; ``overwrite`` deletes them first. With
    ``progress``, a line on stderr at once (how many) and as the samples are written
    (:func:`~mitsuba_platonic.runtime.progress.progress_bar`)."""
    for name, value, least in (("turntables", turntables, 0), ("interpolation", interpolation, 0)):
        if isinstance(value, bool) or not isinstance(value, int) or value < least:
            raise UserError(f"{name} must be a non-negative int, got {value!r}")
    if interpolation == 1:
        raise UserError("an interpolation needs at least 2 steps (its two ends), or 0 for none")
    out = Path(out)
    check_samples_fit(model, n, out)
    earlier = sorted(p for p in out.iterdir() if _SAMPLE.fullmatch(p.name)) if out.is_dir() else []
    if not overwrite:
        _refuse_earlier(out, earlier)
    for p in earlier:
        remove(p)
    written = [] if written is None else written
    bar = progress_bar(n, unit="sample", desc="generate", disable=not progress, first_line=True, seconds=30.0)
    volumes = model.generate(n, seed).cpu()
    for i, vol in enumerate(volumes):
        export_volume(vol, out / f"sample_{i:03d}", model.formation, level=None, frames=24, written=written)
        bar.update(1)
    bar.close()
    step = getattr(model, "step", None)                     # a fresh model has none
    head = (f"step {step}, " if step is not None else "") + f"seed {seed}"
    written.append(save_sample_grid(volumes, model.formation, out / "samples.png", cell=cell,
                                    title=f"{n} samples ({head})"))
    if turntables:
        written.append(save_turntables(volumes, model.formation, out / "turntables.png", azimuths=turntables,
                                       cell=cell))
    if interpolation and n >= 2:
        z = model.latents(2, seed)                           # generate(n, seed)'s first two latents, whatever n
        written.append(save_interpolation(model, z[0], z[1], out / "interpolation.png", interpolation, cell,
                                          title=f"sample_000 to sample_001 ({head}): G(slerp(z0, z1; t))")[0])
    return written
