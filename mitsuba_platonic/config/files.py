"""Config files: found by path or by a packaged config's name, read as YAML, and ``extends:`` resolved.

A config file may name another in a top-level ``extends:`` key and set only what differs from it:

    # configs/photos64.yaml
    extends: photos
    run: {name: photos64}
    model: {resolution: 64}

The parent is a file relative to the child's folder where one exists (``extends: base.yaml``,
``extends: ../mine/base.yaml``), else a packaged config by name (``extends: photos``, as ``--config``
finds it). The merge is by section: the child's keys replace the parent's keys of the same section,
one by one, and every other key of the parent stays (a list value, ``train.d_augment``, is replaced
whole, not extended); a parent may extend another in turn, at most :data:`MAX_DEPTH` files deep.
A chain that comes back to a file (a cycle), a parent that does not exist, and a parent that is not a
mapping of sections are :class:`ConfigError`\\ s naming the files. Command-line overrides apply after
the whole chain is merged. A run folder's ``config.yaml`` holds the resolved config, every key, so a
run never depends on the files its config extended.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Dict, List, Union

import yaml

from ..files.resources import config_names, config_path
from ..settings_checks import ConfigError

__all__ = ["config_file", "read_config_file", "merge_sections", "yaml_problem", "EXTENDS", "MAX_DEPTH"]

#: The top-level key that names a config's parent.
EXTENDS = "extends"
#: How many files one chain of ``extends:`` may hold, the config itself included.
MAX_DEPTH = 8

_SECTIONS = "a mapping of sections (run, data, model, render, train)"


def config_file(path: Union[str, Path]) -> Path:
    """The config file ``path`` names: the file itself where it exists, else the packaged config
    of that name (``paper``, ``paper.yaml`` or ``configs/paper.yaml``: the repository's configs
    travel inside the package, so they are found from any folder, also one that holds a folder of
    the same name, such as a run folder ``paper/``). ConfigError otherwise."""

    p = Path(path)
    if p.is_file():
        return p
    if p.parent in (Path("."), Path("configs")) and p.suffix in ("", ".yaml"):
        try:
            return config_path(p.name)
        except FileNotFoundError:
            pass
    if p.exists():
        raise ConfigError(f"config file {str(path)!r} is not a file")
    raise ConfigError(f"config file {str(path)!r} does not exist (packaged configs, found by name from any "
                      f"folder: {', '.join(config_names())})")


def yaml_problem(e: yaml.YAMLError) -> str:
    """A YAML error on one line: its problem and where (PyYAML's own message spans lines)."""
    mark = getattr(e, "problem_mark", None)
    where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
    return f"{getattr(e, 'problem', None) or type(e).__name__}{where}"


def read_config_file(path: Union[str, Path]) -> Dict[str, Any]:
    """The sections of the config file ``path`` (:func:`config_file` finds it), its ``extends:``
    chain merged in (module docstring); :class:`ConfigError` naming the file that is wrong."""
    return _resolved(config_file(path), [])


def merge_sections(parent: Dict[str, Any], child: Dict[str, Any]) -> Dict[str, Any]:
    """``child``'s sections over ``parent``'s: a section both have is the parent's keys updated by the
    child's (``{'model': {'width': 16, 'norm': 'none'}}`` and ``{'model': {'width': 32}}`` give
    ``{'model': {'width': 32, 'norm': 'none'}}``); an empty section (``train:`` alone) changes nothing.
    A section that is not a mapping replaces the parent's, for the key check to name."""
    out = {name: dict(section) if isinstance(section, dict) else section for name, section in parent.items()}
    for name, section in child.items():
        if section is None and name in out:
            continue
        if isinstance(section, dict) and isinstance(out.get(name), dict):
            out[name].update(section)
        else:
            out[name] = dict(section) if isinstance(section, dict) else section
    return out


def _read(path: Path) -> Dict[str, Any]:
    """One file's mapping, as written (``extends:`` included)."""
    try:
        data = yaml.safe_load(path.read_text())
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not a YAML text file (not UTF-8 text)") from None
    except yaml.YAMLError as e:
        raise ConfigError(f"{path}: not valid YAML ({yaml_problem(e)})") from None
    if data is None:                                    # empty or comments only: not silently "all defaults"
        raise ConfigError(f"{path}: the config file is empty; expected {_SECTIONS}; for the defaults leave "
                          f"--config out, or start from a packaged config (--config quickstart)")
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected {_SECTIONS}, got a {type(data).__name__}")
    return data


def _resolved(path: Path, chain: List[Path]) -> Dict[str, Any]:
    """``path``'s sections merged over its parents'; ``chain``: the files that extend it, child first."""
    here = path.resolve()
    if here in (p.resolve() for p in chain):
        raise ConfigError(f"{chain[0]}: {EXTENDS}: the chain comes back to a file it holds: "
                          f"{' → '.join(str(p) for p in chain + [path])}")
    chain = chain + [path]
    if len(chain) > MAX_DEPTH:
        raise ConfigError(f"{chain[0]}: {EXTENDS}: more than {MAX_DEPTH} files deep: "
                          f"{' → '.join(str(p) for p in chain)}")
    data = _read(path)
    if EXTENDS not in data:
        return data
    name = data.pop(EXTENDS)
    return merge_sections(_resolved(_parent(path, name), chain), data)


def _parent(path: Path, name: Any) -> Path:
    """The file ``path``'s ``extends: name`` names: relative to ``path``'s folder where it exists,
    else a packaged config of that name."""
    if not isinstance(name, str) or not name.strip():
        raise ConfigError(f"{path}: {EXTENDS}: expected the name of a packaged config or a path relative to "
                          f"this file, got {name!r}")
    relative = path.parent / name
    if relative.is_file():
        return relative
    try:
        return config_path(name)
    except FileNotFoundError:
        pass
    raise ConfigError(f"{path}: {EXTENDS}: {name!r} is neither a file in {path.parent} nor a packaged config "
                      f"(packaged: {', '.join(config_names())})")
