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

**Reading YAML** (:func:`load_yaml`, used for config files, ``--set`` values and a run folder's
``config.yaml``). PyYAML on its own takes a key written twice and keeps the last value, silently, and
recurses once per level of nesting, so a value nested a few thousand deep ends in ``RecursionError``.
Here a mapping that holds a key twice (a section or a setting) is refused naming the key and its
line, and so is nesting deeper than :data:`MAX_NESTING` levels, counted on the parser's event
stream (which does not recurse) before anything is built. Every problem is one line, its quotes cut
to :data:`~mitsuba_platonic.settings_checks.QUOTE_LIMIT` characters.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Dict, List, Union

import yaml

from ..files.fileio import read_input_text
from ..files.resources import config_names, config_path
from ..settings_checks import QUOTE_LIMIT, ConfigError, quoted

__all__ = ["config_file", "read_config_file", "merge_sections", "load_yaml", "yaml_problem", "EXTENDS",
           "MAX_DEPTH", "MAX_NESTING"]

#: The top-level key that names a config's parent.
EXTENDS = "extends"
#: How many files one chain of ``extends:`` may hold, the config itself included.
MAX_DEPTH = 8
#: How deep mappings and lists may nest in one YAML text (a config needs 3: section, key, list).
MAX_NESTING = 16

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


class _StrictLoader(yaml.SafeLoader):
    """PyYAML's safe loader, refusing a mapping that holds the same key twice."""

    def construct_mapping(self, node: yaml.Node, deep: bool = False) -> Dict[Any, Any]:
        if isinstance(node, yaml.MappingNode):
            seen = set()
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":    # '<<: *base' merges, and may be overridden
                    continue
                key = self.construct_object(key_node, deep=True)
                try:
                    duplicate = key in seen
                except TypeError:                              # an unhashable key: the base class names it
                    break
                if duplicate:
                    raise yaml.MarkedYAMLError(problem=f"the key {quoted(key)} is given twice in one mapping "
                                                       f"(PyYAML would keep the last silently)",
                                               problem_mark=key_node.start_mark)
                seen.add(key)
        return super().construct_mapping(node, deep=deep)


def load_yaml(text: str) -> Any:
    """``text`` parsed as YAML (the safe subset), refusing a key given twice in one mapping and nesting
    deeper than :data:`MAX_NESTING`; a problem is a :class:`yaml.YAMLError` (:func:`yaml_problem`
    puts it on one line)."""
    depth = 0
    for event in yaml.parse(text, Loader=yaml.SafeLoader):   # an event stream: no recursion per level
        if isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
            depth += 1
            if depth > MAX_NESTING:
                raise yaml.MarkedYAMLError(problem=f"nested more than {MAX_NESTING} levels deep (a config needs 3)",
                                           problem_mark=event.start_mark)
        elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
            depth -= 1
    try:
        return yaml.load(text, Loader=_StrictLoader)
    except RecursionError:                                     # aliases that nest each other
        raise yaml.YAMLError(f"nested too deeply through aliases (more than {MAX_NESTING} levels are refused)") \
            from None


def yaml_problem(e: yaml.YAMLError) -> str:
    """A YAML error on one line: its problem and where (PyYAML's own message spans lines), at most a
    few hundred characters."""
    mark = getattr(e, "problem_mark", None)
    where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
    problem = getattr(e, "problem", None) or str(e) or type(e).__name__
    return " ".join(f"{problem}{where}".split())[:QUOTE_LIMIT * 2]


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
        data = load_yaml(read_input_text(path, "config file"))   # a regular file, at most 16 MiB
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
                          f"this file, got {quoted(name)}")
    relative = path.parent / name
    if relative.is_file():
        return relative
    try:
        return config_path(name)
    except FileNotFoundError:
        pass
    raise ConfigError(f"{path}: {EXTENDS}: {quoted(name)} is neither a file in {path.parent} nor a packaged config "
                      f"(packaged: {', '.join(config_names())})")
