"""Experiment configuration: every knob in one validated tree, loaded from YAML.

A config has five sections (``run``, ``data``, ``model``, ``render``, ``train``), each a
dataclass whose docstring says what its fields mean and whose ``validate()`` checks them. The
sections of the components below the config sit beside them (data, networks, renderer); training's
two sit here, in this package, because training reads the whole config (its code is above it):

- ``run``: :class:`~mitsuba_platonic.config.run_settings.RunConfig` (the run folder, seed, device, cadence)
- ``data``: :class:`~mitsuba_platonic.data.settings.DataConfig` (a procedural collection or a photo folder)
- ``model``: :class:`~mitsuba_platonic.networks.settings.ModelConfig` (the networks' sizes and initialisations)
- ``render``: :class:`~mitsuba_platonic.render.settings.RenderSettings` (the renderer's own settings)
- ``train``: :class:`~mitsuba_platonic.config.train_settings.TrainConfig` (task, mode, losses, optimisers)

This module composes them (:class:`Config`), loads YAML, applies command-line overrides and checks
how the sections combine (:meth:`Config.validate`: colour needs the EA image formation, a 3D mode
needs procedural data, the renderer matches how the images were formed). Loading checks every key
and type: an unknown key or a wrong type is an error that names the key (``train.batch_size:
expected int, got 'eight'``); numbers must be finite (no ``.inf``, ``.nan``). pydantic checks keys
and types (on the plain dataclasses: other modules construct them directly); the sections'
``validate()`` and :meth:`Config.validate` check ranges, choices and combinations. Command-line
overrides use dotted keys, ``--set run.steps=500``; values are parsed as YAML scalars (``true``,
``1e-4``, ``[0.5, 0.9]``, ``null``). A config file may extend another (``extends: photos``) and set only
what differs (:mod:`.files`: how files are found, read and merged). Every section and :class:`ConfigError` stay importable from here;
:mod:`.loading` reads what runs saved back into a config.
"""

from __future__ import annotations

import dataclasses
import os
import re
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, Optional, Sequence, Union

import pydantic
import yaml
from pydantic_core import SchemaValidator, core_schema

from ..data.settings import DataConfig
from ..networks.settings import ModelConfig
from ..render.settings import LIT, SINGLE_SCATTERING, RenderSettings as RenderConfig
from ..settings_checks import ConfigError, cut, quoted
from ..views import DEFAULT_ELEVATION
from .files import config_file, load_yaml, read_config_file, yaml_problem
from .run_settings import RunConfig
from .train_settings import MODES_3D, PRGAN, TrainConfig

__all__ = ["Config", "RunConfig", "DataConfig", "ModelConfig", "RenderConfig", "TrainConfig",
           "load_config", "config_file", "config_from_dict", "apply_overrides", "load_yaml", "yaml_problem",
           "ConfigError"]


#: The override the ``--set`` errors show as an example (a test checks that it is accepted).
OVERRIDE_EXAMPLE = "run.steps=500"

_FLOAT = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)[eE][-+]?\d+")


@dataclass
class Config:
    """A whole experiment: its five sections, each its owner's dataclass (module docstring)."""

    run: RunConfig = field(default_factory=RunConfig)
    data: DataConfig = field(default_factory=DataConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    render: RenderConfig = field(default_factory=RenderConfig)
    train: TrainConfig = field(default_factory=TrainConfig)

    def to_dict(self) -> Dict[str, Any]:
        return dataclasses.asdict(self)

    def validate(self) -> "Config":
        """Check value ranges and combinations; raise :class:`ConfigError` naming the key. Each section
        checks its own values (its ``validate()``); what is checked here is how sections combine."""
        _typed(self.to_dict())                               # a config built in code: its types, finite numbers
        self.run.validate()
        self.data.validate()
        self.model.validate()
        try:
            self.render.validate()                           # the renderer's settings check themselves
        except ValueError as e:
            raise ConfigError(f"render.{e}") from None
        self.train.validate()
        if self.train.light == "head":
            if self.render.backend not in SINGLE_SCATTERING:
                raise ConfigError(f"train.light: 'head' reads a sun and a sky, the light of single scattering; "
                                  f"expected render.backend one of {list(SINGLE_SCATTERING)}, got {self.render.backend!r}")
        if self.train.colour_tv > 0 and self.render.model != "ea":
            raise ConfigError(f"train.colour_tv: colour needs render.model 'ea', got {self.render.model!r}")
        if self.model.photo_texture and self.render.camera != "orthographic":
            raise ConfigError("model.photo_texture: the photo is carried along the rays of an orthographic input "
                              f"camera; expected render.camera 'orthographic', got {self.render.camera!r}")
        if self.train.colour_offset > 0 and not self.model.photo_colour:
            raise ConfigError("train.colour_offset: it penalises G's colour offsets from the photo's colour, so it "
                              "needs model.photo_colour: true")
        if self.train.solidity > 0 and (self.train.task != "reconstruction" or self.train.mode != "platonic"
                                        or self.render.camera != "orthographic"):
            raise ConfigError("train.solidity: it fills each input ray between its first and its last matter, rays "
                              "parallel to depth in the input camera's frame, so it needs train.task 'reconstruction', "
                              "train.mode 'platonic' and render.camera 'orthographic'; got "
                              f"{self.train.task!r}, {self.train.mode!r} and {self.render.camera!r}")
        if self.train.depth_spread > 0 and (self.train.task != "reconstruction" or self.train.rec_target != "image"
                                            or self.render.model != "ea" or self.render.camera != "orthographic"):
            raise ConfigError("train.depth_spread: it weighs the input view's EA rays, parallel to depth in the input "
                              "camera's frame, so it needs train.task 'reconstruction', train.rec_target 'image', "
                              "render.model 'ea' and render.camera 'orthographic'; got "
                              f"{self.train.task!r}, {self.train.rec_target!r}, {self.render.model!r} and "
                              f"{self.render.camera!r}")
        if self.train.colour_match > 0 and self.render.model != "ea":
            raise ConfigError(f"train.colour_match: colour needs render.model 'ea', got {self.render.model!r}")
        if "colour" in self.train.photo_augment and self.render.model != "ea":
            raise ConfigError(f"train.photo_augment: 'colour' needs colour, render.model 'ea'; got {self.render.model!r}")
        if self.model.photo_colour and (self.train.task != "reconstruction" or self.render.model != "ea"
                                        or self.train.mode != "platonic"):
            raise ConfigError("model.photo_colour: the colour is read from the input photo, so it needs "
                              "train.task 'reconstruction', train.mode 'platonic' and render.model 'ea'; got "
                              f"{self.train.task!r}, {self.train.mode!r} and {self.render.model!r}")
        if self.train.mode in MODES_3D and self.data.source != "procedural":
            raise ConfigError(f"train.mode: {self.train.mode!r} needs 3D ground truth, i.e. data.source 'procedural'")
        if self.train.mode == "prgan":                       # the PrGAN-style baseline: VH, 8 views on one ring
            if self.render.model != "vh":
                raise ConfigError(f"render.model: {PRGAN} trains on visual hulls only; expected 'vh', "
                                  f"got {self.render.model!r}")
            if self.data.source == "procedural" and self.data.formation != "vh":
                raise ConfigError(f"data.formation: {PRGAN} trains on visual hull images only; expected 'vh', "
                                  f"got {self.data.formation!r}")
            if self.data.source == "procedural":
                ring = self.train.ring_elevation
                if self.data.view_distribution != "ring":
                    raise ConfigError(f"data.view_distribution: {PRGAN} needs a collection on its ring; "
                                      f"expected 'ring', got {self.data.view_distribution!r}")
                data_ring = DEFAULT_ELEVATION["ring"] if self.data.elevation is None else self.data.elevation
                if data_ring != ring:
                    raise ConfigError(f"data.elevation: {PRGAN} needs a collection on its ring at {ring:g}°; "
                                      f"got {data_ring!r}")
        if self.data.source == "procedural" and self.data.formation != "physical" \
                and self.render.backend not in LIT \
                and self.data.formation != self.render.model:
            raise ConfigError(f"render.model: {self.render.model!r} differs from data.formation "
                              f"{self.data.formation!r}; the renderer must match how the images were formed")
        return self


# The key-and-type check is pydantic's, run on Config and its sections' dataclasses (a copy of its
# schema for Config, the sections included, with three changes; the dataclasses themselves stay plain):
# every leaf is strict (ints are not bools, strings are not numbers; a float accepts an int) and
# finite (allow_inf_nan), unknown keys are errors; a section accepts a mapping, a list a tuple, a
# float a string in exponent form, which PyYAML (YAML 1.1) reads from `1e-4`, and Optional[X] is
# a union of X and None (pydantic's own form for it names no "null" in its errors).
Config.__pydantic_config__ = pydantic.ConfigDict(strict=True, extra="forbid", allow_inf_nan=False)


def _yaml_float(value: Any) -> Any:
    return float(value) if isinstance(value, str) and _FLOAT.fullmatch(value.strip()) else value


def _relaxed(schema: Any) -> Any:
    if isinstance(schema, list):
        return [_relaxed(s) for s in schema]
    if not isinstance(schema, dict):
        return schema
    schema = {k: _relaxed(v) for k, v in schema.items()}
    if schema.get("type") in ("dataclass", "list"):
        schema["strict"] = False
    if schema.get("type") == "float":
        return core_schema.no_info_before_validator_function(_yaml_float, schema)
    if schema.get("type") == "nullable":                  # a union with None: its message says "or null"
        return core_schema.union_schema([schema["schema"], core_schema.none_schema()])
    return schema


_VALIDATOR = SchemaValidator(_relaxed(pydantic.TypeAdapter(Config).core_schema))

# how pydantic's error types read in a message ("train.batch_size: expected int, got 'eight'")
_EXPECTED = {"int_type": "int", "float_type": "a number", "bool_type": "true or false", "string_type": "a string",
             "list_type": "a list", "dataclass_type": "a mapping", "none_required": "null"}


def _typed(data: Any) -> Config:
    """``data`` as a :class:`Config` of the declared types; else a one-line :class:`ConfigError`."""
    try:
        return _VALIDATOR.validate_python(data)
    except pydantic.ValidationError as e:
        raise _one_line(e, data) from None


def _one_line(e: pydantic.ValidationError, data: Any) -> ConfigError:
    """The first error as ``key: expected …, got …``. A union (``elevation``: null, a number or a
    list) fails once per member: the member that got deepest into the value names the key
    (``data.elevation[1]``), and members failing at the same depth are joined with 'or'."""
    errors = [(_key(err["loc"], data), err) for err in e.errors()]
    first = errors[0][0]
    same = [(k, err) for k, err in errors if k == first or k.startswith(first + "[")]
    key = max((k for k, _ in same), key=len)
    errors = [err for k, err in same if k == key]
    if errors[0]["type"] in ("unexpected_keyword_argument", "extra_forbidden"):
        cls = Config
        for part in errors[0]["loc"][:-1]:
            cls = typing.get_type_hints(cls)[part]
        known = ", ".join(sorted(f.name for f in dataclasses.fields(cls)))
        return ConfigError(f"{key}: unknown key (known: {known})")
    expected = dict.fromkeys(_EXPECTED.get(err["type"], err["msg"].replace("Input should be ", "", 1))
                             for err in errors)
    return ConfigError(f"{key or 'config'}: expected {' or '.join(expected)}, got {quoted(errors[0]['input'])}")


def _key(loc: Sequence[Any], data: Any) -> str:
    """pydantic's error location as a key into ``data`` (``train.betas[1]``), leaving out the names
    of union members that pydantic puts into the location."""
    key, node = "", data
    for part in loc:
        if isinstance(node, dict) and part in node:
            key, node = f"{key}.{part}" if key else str(part), node[part]
        elif isinstance(node, (list, tuple)) and isinstance(part, int):
            key, node = f"{key}[{part}]", node[part]
    return key


def apply_overrides(data: Dict[str, Any], overrides: Sequence[str]) -> Dict[str, Any]:
    """Apply ``key.sub=value`` strings (values parsed as YAML scalars) to a nested dict."""
    for item in overrides:
        if "=" not in item:
            raise ConfigError(f"override {quoted(item)}: expected key=value, e.g. {OVERRIDE_EXAMPLE}")
        key, text = item.split("=", 1)
        parts = key.strip().split(".")
        if len(parts) != 2 or not all(parts):
            raise ConfigError(f"override {quoted(item)}: expected section.key=value, e.g. {OVERRIDE_EXAMPLE}")
        try:
            value = load_yaml(text)
        except yaml.YAMLError as e:
            key = cut(key)                                    # the key as written, cut
            raise ConfigError(f"{key}: could not parse {quoted(text)}: {yaml_problem(e)}") from None
        data.setdefault(parts[0], {})
        if not isinstance(data[parts[0]], dict):
            raise ConfigError(f"{parts[0]}: expected a mapping")
        data[parts[0]][parts[1]] = value
    return data


def load_config(path: Optional[Union[str, Path]] = None, overrides: Sequence[str] = ()) -> Config:
    """Load a YAML config (or the defaults when ``path`` is None), its ``extends:`` chain merged in
    (:mod:`.files`), apply overrides, validate."""
    data: Dict[str, Any] = {} if path is None else read_config_file(path)
    return config_from_dict(apply_overrides(data, overrides))


def config_from_dict(data: Dict[str, Any]) -> Config:
    """A nested mapping (a YAML file's, a saved ``Config.to_dict()``) → a validated :class:`Config`;
    :class:`ConfigError` naming the first bad key."""
    if isinstance(data, dict):                               # an empty section (`train:` alone) is its defaults
        data = {name: {} if value is None else value for name, value in data.items()}
    return _expand_home(_typed(data)).validate()


#: The settings that name a file or folder: ``~`` (``~user``) in them is expanded, as a shell would,
#: here where every config is made, so that no command writes into a folder literally named ``~``.
PATH_KEYS = (("run", "out_dir"), ("data", "cache"), ("data", "path"))


def _expand_home(cfg: Config) -> Config:
    """``cfg`` with ``~`` expanded in the values of :data:`PATH_KEYS`."""
    for section, key in PATH_KEYS:
        part = getattr(cfg, section)
        value = getattr(part, key)
        if isinstance(value, str) and value.startswith("~"):
            setattr(part, key, os.path.expanduser(value))
    return cfg
