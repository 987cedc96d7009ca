"""The Mitsuba scene files in ``scenes/``, and the one loader the renderers build their scenes with.

The files are the single description of every scene the project renders (scenes/README.md):

    raymarch.xml        VH / AO: the density as a ``heterogeneous`` medium, the ``platonic_raymarch``
                        integrator (:mod:`.integrator`), an orthographic camera
    raymarch_ea.xml     the same for EA (density and colour)
    physical.xml        the path tracer's scene: the medium in a null-BSDF cube under a sky
                        (``volpath`` or ``prbvolpath``), lit by emitters/$lighting.xml
    emitters/*.xml      the skies: ``sunsky`` and ``envmap``

Each takes its grids and settings as Mitsuba ``$name`` parameters, so ``mi.load_file(path,
density="density.vol", resolution="32", ...)`` renders it with Mitsuba alone (the grids as
``.vol`` files: :func:`write_scene_grids`). The renderers load the same files with
:func:`load_scene`, which hands grids over in memory: it parses the file with the parameters,
puts each grid in place of its ``gridvolume``'s file name, and instantiates the result, so no
scene structure is written twice.
"""

from __future__ import annotations

import argparse
import math
import numbers
from pathlib import Path
from typing import Any, Dict, Mapping, Optional, Sequence, Union

import torch

from ...files.resources import scenes_folder
from ...files.volume_io import read_npz, write_vol
from ...runtime import budget
from ..grids import extinction
from ..variant import ensure_variant

__all__ = ["SCENES", "scene_path", "load_scene", "xml_value", "write_scene_grids"]

#: The scene files: the repository's top-level ``scenes/``, carried inside the package (:mod:`mitsuba_platonic.files.resources`).
SCENES = scenes_folder()


def scene_path(name: Union[str, Path]) -> Path:
    """``scenes/<name>.xml`` for a bare name ('raymarch', 'emitters/sunsky'), else the path itself."""
    p = Path(name)
    if p.suffix != ".xml":
        p = SCENES / f"{name}.xml"
    if not p.is_file():
        raise FileNotFoundError(f"no Mitsuba scene file {str(p)!r}")
    return p


def xml_value(value: Any) -> str:
    """A Python value as the text of a ``$name`` parameter: booleans 'true'/'false', numbers
    round-trip exactly (``repr``), sequences comma-separated ('0.3, 0.8, 0.5'), paths as strings."""
    if isinstance(value, (bool,)) or type(value).__name__ == "bool_":
        return "true" if value else "false"
    if isinstance(value, numbers.Integral):
        return str(int(value))
    if isinstance(value, numbers.Real):
        x = float(value)
        if not math.isfinite(x):
            raise ValueError(f"scene parameter must be finite, got {value!r}")
        return repr(x)
    if isinstance(value, (str, Path)):
        return str(value)
    if isinstance(value, Sequence) or hasattr(value, "__len__"):
        return ", ".join(xml_value(float(x)) for x in value)
    raise TypeError(f"cannot write {type(value).__name__} {value!r} as a scene parameter")


def _register_integrators() -> None:
    """Register the project's integrator (``platonic_raymarch``) with Mitsuba: the one place it happens."""
    from . import integrator  # noqa: F401  (registers on import)


def load_scene(name: Union[str, Path], grids: Optional[Mapping[str, Any]] = None,
               properties: Optional[Mapping[str, Mapping[str, Any]]] = None, **params: Any) -> Any:
    """Load a scene file (``scenes/<name>.xml`` or a path) with Mitsuba, grids given in memory.

    params: the file's ``$name`` parameters (any value :func:`xml_value` writes).
    grids: ``{id: data}``: the ``gridvolume`` with that id reads ``data`` (a ``[Z, Y, X, C]``
        array or tensor, or an ``mi.VolumeGrid``) instead of its ``filename``.
    properties: ``{id: {property: value}}``: more properties of the object with that id (values
        as Mitsuba takes them), e.g. a grid's fixed majorant ``max_value``.
    Returns what the file describes: an ``mi.Scene``, or the object at its root (an emitter).
    """
    mi = ensure_variant()
    _register_integrators()
    path = scene_path(name)
    config = mi.parser.ParserConfig(mi.variant())
    state = mi.parser.parse_file(config, str(path), **{k: xml_value(v) for k, v in params.items()})
    index = state.id_to_index

    def node(id: str) -> Any:
        if id not in index:
            raise KeyError(f"{path.name} has no object with id {id!r} (it has {', '.join(sorted(index))})")
        return state.nodes[index[id]].props

    for id, data in (grids or {}).items():
        props = node(id)
        if props.plugin_name() != "gridvolume":
            raise ValueError(f"{path.name}: object {id!r} is a {props.plugin_name()}, not a gridvolume")
        if "filename" in props.keys():
            del props["filename"]
        props["grid"] = data if isinstance(data, mi.VolumeGrid) else mi.VolumeGrid(data)
    for id, extra in (properties or {}).items():
        props = node(id)
        for key, value in extra.items():
            props[key] = value
    mi.parser.transform_all(config, state)
    return mi.parser.instantiate(config, state)


def write_scene_grids(volume: Any, folder: Union[str, Path]) -> Dict[str, Path]:
    """Write the grid files the scene files read for one ``(C, N, N, N)`` volume into ``folder``.

    ``density.vol`` (the density, raymarch*.xml), ``albedo.vol`` (the colour, EA volumes only) and
    ``sigma_t.vol`` (the path tracer's extinction, physical.xml; RGBA volumes only), each with
    :func:`mitsuba_platonic.files.volume_io.write_vol`. Returns ``{parameter: path}``.
    """
    v = torch.as_tensor(volume).detach().float().cpu()
    if v.dim() != 4 or v.shape[0] not in (1, 4):
        raise ValueError(f"expected a (1 or 4, N, N, N) volume, got {tuple(v.shape)}")
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    out = {"density": write_vol(v[-1:], folder / "density.vol")}
    if v.shape[0] == 4:
        out["albedo"] = write_vol(v[:3], folder / "albedo.vol")
        out["sigma_t"] = write_vol(extinction(v[3:]), folder / "sigma_t.vol")
    return out


def main(argv: Optional[Sequence[str]] = None) -> None:
    """``python -m mitsuba_platonic.render.mitsuba.scenes VOLUME.npz OUT``: write OUT/{density,albedo,sigma_t}.vol."""
    parser = argparse.ArgumentParser(prog="python -m mitsuba_platonic.render.mitsuba.scenes",
                                     description="Write the .vol grids the scenes/*.xml files read for a "
                                                 "volume saved as .npz (array 'volume', (C, N, N, N)).")
    parser.add_argument("volume", help="an .npz written by platonic generate/reconstruct")
    parser.add_argument("out", help="folder for density.vol, albedo.vol, sigma_t.vol")
    args = parser.parse_args(argv)
    volume = read_npz(Path(args.volume), fits=budget.memory_check("use a smaller volume"))[0]
    for key, path in write_scene_grids(volume, args.out).items():
        print(f"{key}={path}")


if __name__ == "__main__":
    main()
