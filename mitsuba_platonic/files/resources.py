"""The package's data (scene files, configs, baked skies), found through :mod:`importlib.resources`.

The repository keeps ``scenes/`` and ``configs/`` at its top level; ``mitsuba_platonic/_data/``
links to them, and a wheel carries them as package data. This module is the one place that knows
where they are, so ``platonic`` finds them from any working directory and in any install:

- :func:`scenes_folder`: the Mitsuba scene files (``scenes/*.xml``, ``emitters/``, ``envmaps/``);
- :func:`config_path` / :func:`config_names`: the configs (``configs/*.yaml``);
- :func:`sky_cache`: where skies baked on first use go (next to the scene files in a checkout,
  the user's cache folder in an installed package, which may be read-only).
"""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path
from typing import List

__all__ = ["scenes_folder", "configs_folder", "config_names", "config_path", "sky_cache", "from_checkout"]

_PACKAGE = "mitsuba_platonic._data"


def _folder(name: str) -> Path:
    """The package data folder ``name`` as a file-system path (Mitsuba reads files, not streams)."""
    folder = resources.files(_PACKAGE) / name
    if not isinstance(folder, Path):
        raise RuntimeError(f"mitsuba_platonic's data ({name}/) must be on the file system, not in {folder!r}: "
                           "install the package from a wheel or a checkout, not a zip archive")
    return folder


def scenes_folder() -> Path:
    """The Mitsuba scene files (the repository's ``scenes/``)."""
    return _folder("scenes")


def configs_folder() -> Path:
    """The configs (the repository's ``configs/``)."""
    return _folder("configs")


def config_names() -> List[str]:
    """The packaged configs' names, without ``.yaml``: ``['baseline_gan3d', …, 'quickstart']``."""
    return sorted(p.stem for p in configs_folder().glob("*.yaml"))


def config_path(name: str) -> Path:
    """The packaged config ``name`` (``'quickstart'`` or ``'quickstart.yaml'``); FileNotFoundError
    naming the known configs where there is none."""
    stem = name[:-5] if name.endswith(".yaml") else name
    path = configs_folder() / f"{stem}.yaml"
    if "/" in stem or os.sep in stem or not path.is_file():
        raise FileNotFoundError(f"no packaged config {name!r}; packaged: {', '.join(config_names())}")
    return path


def from_checkout() -> bool:
    """Whether the data are a checkout's own folders (an editable install): ``_data/scenes`` is
    then the link to the top-level ``scenes/``, where a wheel has a folder of copies."""
    return scenes_folder().is_symlink()


def sky_cache() -> Path:
    """Where skies baked on first use are written: ``scenes/envmaps/`` in a checkout (git ignores
    them there), else ``$XDG_CACHE_HOME/mitsuba-platonic/envmaps`` (``~/.cache/…``): an installed
    package's folder may be read-only, and files written into it would outlive an uninstall."""
    if from_checkout():
        return scenes_folder() / "envmaps"
    cache = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(cache) / "mitsuba-platonic" / "envmaps"

