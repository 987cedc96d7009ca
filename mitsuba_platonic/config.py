"""Experiment configuration: every knob in one validated tree, loaded from YAML.

A config has five sections (``run``, ``data``, ``model``, ``render``, ``train``), each a
dataclass whose docstring says what its fields mean (``render`` is the renderer's own
:class:`~mitsuba_platonic.render.RenderSettings`; the others are below). Loading checks every key and type:
an unknown key or a wrong type is an error that names the key (``train.batch_size: expected
int, got 'eight'``); numbers must be finite (no ``.inf``, ``.nan``). pydantic checks keys and types
(on the plain dataclasses: other modules construct them directly); :meth:`Config.validate` checks
ranges, choices and combinations. Command-line overrides use
dotted keys, ``--set train.steps=500``; values are parsed as YAML scalars (``true``, ``1e-4``,
``[0.5, 0.9]``, ``null``).
"""

from __future__ import annotations

import dataclasses
import os
import re
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Literal, Optional, Sequence, Union

import pydantic
import yaml
from pydantic_core import SchemaValidator, core_schema

from .data.photos import BACKGROUNDS, CROPS, PhotoOptions
from .errors import UserError
from .models import INITS, NORMS, RESOLUTIONS, UPSAMPLES
from .render.settings import FORMATIONS
from .render.settings import RenderSettings as RenderConfig
from .resources import config_names, config_path
from .train.augment import AUGMENTS, PHOTO_AUGMENTS
from .train.losses import LOSSES
from .train.roll import ROLLS
from .train.settings import DEVICES, MODES, MODES_3D, POSES, REC_TARGETS, SOURCES, TASKS
from .views import DEFAULT_ELEVATION, DISTRIBUTIONS, sample_views

__all__ = ["Config", "RunConfig", "DataConfig", "ModelConfig", "RenderConfig", "TrainConfig",
           "load_config", "config_file", "config_from_dict", "apply_overrides", "ConfigError"]


_FLOAT = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)[eE][-+]?\d+")


class ConfigError(UserError):
    """A bad configuration; the message names the key."""


@dataclass
class RunConfig:
    """name: run folder name under ``out_dir`` (one folder name: no '/', no '..'); seed: master seed;
    device: 'auto' | 'cpu' | 'cuda'; steps: training steps; log_every / sample_every / checkpoint_every: in steps;
    threads: torch and Dr.Jit CPU threads (0 = all cores); drjit_threads: Dr.Jit's worker threads
    while training, 'auto' or a count (1: its launches run on the training thread alone; 'auto' picks
    1 for the marcher at N ≤ 32 on a CPU, docs/training.md "Threads"); keep_checkpoints: how many to keep."""

    name: str = "run"
    out_dir: str = "runs"
    seed: int = 0
    device: str = "auto"
    steps: int = 2000
    log_every: int = 10
    sample_every: int = 250
    checkpoint_every: int = 250
    threads: int = 0
    drjit_threads: Union[Literal["auto"], int] = "auto"
    keep_checkpoints: int = 3


@dataclass
class DataConfig(PhotoOptions):
    """source: 'procedural' (render a built-in class with make-dataset, cached under ``cache``)
    or 'folder' (an unstructured photo collection at ``path``).
    Procedural: shape_class, n_shapes, views_per_shape, formation ('vh'|'ao'|'ea'|'physical'),
    view_distribution ('sphere'|'band'|'ring'), elevation, seed.
    Folder: the photo options background, threshold, crop, margin, clean, fill_holes and erode,
    inherited from (and explained by) :class:`mitsuba_platonic.data.photos.PhotoOptions`.
    split: the train split's share; the rest is held out (val/test) for evaluation."""

    source: str = "procedural"
    path: Optional[str] = None
    cache: str = "data"
    shape_class: str = "chair"
    n_shapes: int = 200
    views_per_shape: int = 4
    formation: str = "ea"
    view_distribution: str = "sphere"
    elevation: Optional[Union[float, List[float]]] = None
    split: float = 0.9
    seed: int = 0

    def photo_options(self) -> Dict[str, Any]:
        """Keyword arguments of ``PhotoCollection`` / ``PhotoCollection.load_splits`` for a
        folder source: the split shares (the held-out rest halved into val and test), the seed
        and the image options above (``resolution`` and ``alpha_only`` come from the model and
        renderer)."""
        rest = (1.0 - self.split) / 2.0
        return {"splits": (self.split, rest, rest), "seed": self.seed, **self.image_kwargs()}


@dataclass
class ModelConfig:
    """resolution: volume and image size R (16 | 32 | 64 | 128); latent: size of z;
    width: channels at the highest resolution (the paper: 64); norm: 'batch' (the paper) |
    'instance' | 'none'. The default is 'none': with BatchNorm the quickstart's reconstruction
    loss stays at 0.21 and novel-view IoU at 0.18 (0.007 and 0.63 without; docs/training.md);
    'none' also makes data-parallel training identical to single-process training.
    encoder_hidden: width of the encoder's last layer before its Linear to z (0, the default:
    none; the authors' encoder: 1024, see docs/paper.md). upsample: how G doubles its
    resolution, 'transposed' (the paper's k4 s2 transposed convolutions) | 'resize' (nearest ×2
    and a k3 convolution; mitsuba_platonic.models.UPSAMPLES). critic_init: how the critics D and
    D3 start, 'dcgan' (N(0, 0.02), as every network and the paper) | 'he' (He's initialisation
    for LeakyReLU, drawn from the run's seed after the others): without normalisation a DCGAN
    critic's logits are ~5e-4 and it does not learn in the quickstart's 2,000 steps
    (docs/training.md, "A discriminator that never learns"). init: how E and G start, 'dcgan'
    (the paper's) | 'he' (He's, scaled by each layer's fan-in; G's output layer keeps the start
    at density 1/R: mitsuba_platonic.models.init_he): without normalisation the DCGAN
    initialisation gives every input image the same first volume (docs/training.md).
    critic_width: channels of the critics' (D's, D3's) first layer, doubling per stage as E's;
    null: ``width``. D is a 2D network: at 32 it costs little next to G's 3D convolutions
    (docs/training.md, "E and G that start blind, and a wider D")."""

    resolution: int = 32
    latent: int = 64
    width: int = 16
    norm: str = "none"
    encoder_hidden: int = 0
    upsample: str = "transposed"
    critic_init: str = "dcgan"
    init: str = "dcgan"
    critic_width: Optional[int] = None


@dataclass
class TrainConfig:
    """task: 'reconstruction' (E encodes the input image; L2 at the input view) or 'generation'
    (z ~ N(0, I)); mode: 'platonic' (2D discriminator only), 'platonic3d' (+ a 3D discriminator on
    ground-truth volumes; G learns from both), 'gan3d' (the 3D-GAN baseline: WGAN-GP on volumes,
    no rendering) or 'prgan' (the PrGAN-style baseline: VH only, views from 8 azimuths on the ring
    at ``elevation`` (0° by default; reconstruction: 0°, the input view's), G(z, one-hot view)).
    batch_size: global batch (split across processes); random_views: random views per volume per step;
    view_distribution / elevation: p_view; loss: 'nonsaturating' | 'wgan-gp'; gp_weight: WGAN-GP λ;
    rec_weight: λ of the reconstruction term; rec_target: what that term compares, 'image' (the
    input image with the render of v at the input view: PlatonicGAN's, 2D data only) or 'volume'
    (v with the input image's ground-truth volume in its camera's frame: 3D supervision, the 3D
    modes only; the 3D-GAN baseline's, which renders nothing); weight_3d: weight of the 3D adversarial term;
    lr_g, lr_e, lr_d: Adam learning rates (lr_d 2e-5, not the authors' 1e-5: measured in
    docs/training.md); betas: Adam betas; d_gate: update D only while its *soft* accuracy
    ½(mean σ(l_real) + 1 − mean σ(l_fake)) ≤ this (0.6, the authors' gate; null: always). It never
    triggers at lr_d 2e-5 in the quickstart, and keeps a faster D (lr_d 1e-4) from collapsing G,
    which it does ungated (docs/training.md); d_steps: D (or D3) updates per G update, each on a
    fresh loss, in every mode; d_roll: 'none' | 'uniform': D sees every real and rendered image
    turned in-plane by its own random angle, so that the tilt of views drawn in the input camera's
    frame cannot give fakes away; 'matched' (reconstruction): the reals turned by the tilt a right
    volume's view would have, for an input elevation drawn from the collection's view distribution
    (procedural data; for photos the train section's) (:mod:`mitsuba_platonic.train.roll`,
    docs/training.md); pose: where G's volume stands, 'input' (in the input camera's frame, the
    paper's view-space reconstruction) | 'elevation' (reconstruction, mode 'platonic'): G builds the
    object upright in its own frame, a pose head reads the input camera's elevation θ̂ from E's
    code, the input-view term renders the volume tilted by θ̂ and the random views are drawn
    around the upright object, as the photos' cameras were; pose_weight: λ of the term that
    teaches the head the elevations of G's own renders from those random views (0: none; only
    with 'elevation') (:mod:`mitsuba_platonic.train.trainer`, docs/training.md, "An elevation read
    from the photo");
    r1_weight: γ of the R1 penalty γ/2 · E‖∇ₓD(x)‖² on real images (Mescheder et al. 2018),
    added to every critic's non-saturating loss (0: none; WGAN-GP has its own penalty)
    (:func:`mitsuba_platonic.train.losses.r1_penalty`, docs/training.md); colour_tv: weight of
    G's density-weighted colour total variation (EA, not 'gan3d'; 0: none)
    (:func:`mitsuba_platonic.train.losses.colour_tv`, docs/training.md); ema: null, or the decay β
    of an exponential moving average of E's and G's weights, which samples, checkpoints' inference
    weights and evaluation then use (:meth:`mitsuba_platonic.train.trainer.Trainer.inference_model`,
    docs/training.md); d_augment: the differentiable augmentations of every image D sees, real or
    rendered, in D's and G's updates, from 'flip', 'translation', 'cutout' (none by default; for
    small photo collections, :mod:`mitsuba_platonic.train.augment`, docs/training.md); photo_augment:
    transforms of each step's photos before E, the reconstruction target and D read them, from
    'flip', 'colour' (none by default; modes 'platonic' and 'prgan', image targets; 'colour' needs
    EA), so that E reads colour from a photo instead of memorising a few dozen photos
    (:func:`mitsuba_platonic.train.augment.augment_photos`, docs/training.md, "Real photos")."""

    task: str = "reconstruction"
    mode: str = "platonic"
    batch_size: int = 8
    random_views: int = 1
    view_distribution: str = "sphere"
    elevation: Optional[Union[float, List[float]]] = None
    loss: str = "nonsaturating"
    gp_weight: float = 10.0
    rec_weight: float = 5.0
    rec_target: str = "image"
    weight_3d: float = 1.0
    lr_g: float = 1e-3
    lr_e: float = 1e-3
    lr_d: float = 2e-5
    betas: List[float] = field(default_factory=lambda: [0.5, 0.9])
    d_gate: Optional[float] = 0.6
    d_steps: int = 1
    d_roll: str = "none"
    pose: str = "input"
    pose_weight: float = 0.0
    r1_weight: float = 0.0
    colour_tv: float = 0.0
    ema: Optional[float] = None
    d_augment: List[str] = field(default_factory=list)
    photo_augment: List[str] = field(default_factory=list)


@dataclass
class Config:
    run: RunConfig = field(default_factory=RunConfig)
    data: DataConfig = field(default_factory=DataConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    render: RenderConfig = field(default_factory=RenderConfig)
    train: TrainConfig = field(default_factory=TrainConfig)

    def to_dict(self) -> Dict[str, Any]:
        return dataclasses.asdict(self)

    def validate(self) -> "Config":
        """Check value ranges and combinations; raise :class:`ConfigError` naming the key."""
        _typed(self.to_dict())                               # a config built in code: its types, finite numbers
        _folder_name("run.name", self.run.name)
        _choice("run.device", self.run.device, DEVICES)
        for key in ("steps", "log_every", "sample_every", "checkpoint_every", "keep_checkpoints"):
            _positive(f"run.{key}", getattr(self.run, key))
        _non_negative("run.threads", self.run.threads)
        if self.run.drjit_threads != "auto":
            _positive("run.drjit_threads", self.run.drjit_threads)
        _non_negative("run.seed", self.run.seed)
        _choice("data.source", self.data.source, SOURCES)
        if self.data.source == "folder" and not self.data.path:
            raise ConfigError("data.path: required when data.source is 'folder'")
        _choice("data.formation", self.data.formation, FORMATIONS)
        _choice("data.view_distribution", self.data.view_distribution, DISTRIBUTIONS)
        _choice("data.background", self.data.background, BACKGROUNDS)
        _choice("data.crop", self.data.crop, CROPS)
        if not 0.0 <= self.data.margin < 0.5:
            raise ConfigError(f"data.margin: expected a share in [0, 0.5), got {self.data.margin!r}")
        if not 0.0 <= self.data.threshold < 1.0:
            raise ConfigError(f"data.threshold: expected a number in [0, 1), got {self.data.threshold!r}")
        _non_negative("data.erode", self.data.erode)
        _positive("data.n_shapes", self.data.n_shapes)
        _positive("data.views_per_shape", self.data.views_per_shape)
        if not 0.0 < self.data.split <= 1.0:
            raise ConfigError(f"data.split: expected a share in (0, 1], got {self.data.split!r}")
        _choice("model.resolution", self.model.resolution, RESOLUTIONS)
        _positive("model.latent", self.model.latent)
        _positive("model.width", self.model.width)
        _choice("model.norm", self.model.norm, NORMS)
        _choice("model.upsample", self.model.upsample, UPSAMPLES)
        _choice("model.critic_init", self.model.critic_init, INITS)
        _choice("model.init", self.model.init, INITS)
        if self.model.critic_width is not None:
            _positive("model.critic_width", self.model.critic_width)
        _non_negative("model.encoder_hidden", self.model.encoder_hidden)
        try:
            self.render.validate()                           # the renderer's settings check themselves
        except ValueError as e:
            raise ConfigError(f"render.{e}") from None
        for section in ("data", "train"):
            _check_elevation(section, getattr(self, section).view_distribution, getattr(self, section).elevation)
        _choice("train.task", self.train.task, TASKS)
        _choice("train.mode", self.train.mode, MODES)
        _choice("train.view_distribution", self.train.view_distribution, DISTRIBUTIONS)
        _choice("train.loss", self.train.loss, LOSSES)
        _positive("train.batch_size", self.train.batch_size)
        _positive("train.random_views", self.train.random_views)
        _positive("train.d_steps", self.train.d_steps)
        _choice("train.d_roll", self.train.d_roll, ROLLS)
        if self.train.d_roll == "matched" and (self.train.task != "reconstruction" or self.train.mode == "gan3d"):
            raise ConfigError("train.d_roll: 'matched' turns the photos by the tilt of views drawn in an input "
                              "camera's frame, so it needs train.task 'reconstruction' and a 2D critic "
                              f"(not mode 'gan3d'), got task {self.train.task!r}, mode {self.train.mode!r}")
        _choice("train.pose", self.train.pose, POSES)
        _non_negative("train.pose_weight", self.train.pose_weight)
        if self.train.pose == "elevation":
            if self.train.task != "reconstruction" or self.train.mode != "platonic":
                raise ConfigError("train.pose: 'elevation' reads the input camera's elevation from the photo, so it "
                                  "needs train.task 'reconstruction' and train.mode 'platonic', got task "
                                  f"{self.train.task!r}, mode {self.train.mode!r}")
            if self.train.d_roll != "none":
                raise ConfigError("train.d_roll: with train.pose 'elevation' the random views are drawn around the "
                                  "upright object, as the photos' cameras were, so nothing is to be turned; "
                                  f"expected 'none', got {self.train.d_roll!r}")
        elif self.train.pose_weight > 0:
            raise ConfigError("train.pose_weight: the pose term trains the elevation head of train.pose "
                              f"'elevation'; with pose {self.train.pose!r} expected 0, got {self.train.pose_weight!r}")
        for key in ("lr_g", "lr_e", "lr_d"):
            if not getattr(self.train, key) > 0:
                raise ConfigError(f"train.{key}: expected a positive learning rate, got {getattr(self.train, key)!r}")
        if len(self.train.betas) != 2 or not all(0.0 <= b < 1.0 for b in self.train.betas):
            raise ConfigError(f"train.betas: expected two numbers in [0, 1), got {self.train.betas!r}")
        _non_negative("train.r1_weight", self.train.r1_weight)
        if self.train.r1_weight > 0 and self.train.loss != "nonsaturating":
            raise ConfigError("train.r1_weight: the R1 penalty is for the non-saturating loss; "
                              f"train.loss {self.train.loss!r} has its own (train.gp_weight)")
        _non_negative("train.colour_tv", self.train.colour_tv)
        if self.train.colour_tv > 0 and self.render.model != "ea":
            raise ConfigError(f"train.colour_tv: colour needs render.model 'ea', got {self.render.model!r}")
        if self.train.colour_tv > 0 and self.train.mode == "gan3d":
            raise ConfigError("train.colour_tv: the 'gan3d' baseline trains G on volumes alone, without priors")
        unknown = [a for a in self.train.d_augment if a not in AUGMENTS]
        if unknown or len(set(self.train.d_augment)) != len(self.train.d_augment):
            raise ConfigError(f"train.d_augment: expected distinct names from {list(AUGMENTS)}, got "
                              f"{self.train.d_augment!r}")
        if self.train.d_augment and self.train.mode == "gan3d":
            raise ConfigError("train.d_augment: the 'gan3d' baseline has no 2D critic to augment for")
        unknown = [a for a in self.train.photo_augment if a not in PHOTO_AUGMENTS]
        if unknown or len(set(self.train.photo_augment)) != len(self.train.photo_augment):
            raise ConfigError(f"train.photo_augment: expected distinct names from {list(PHOTO_AUGMENTS)}, got "
                              f"{self.train.photo_augment!r}")
        if self.train.photo_augment and (self.train.mode not in ("platonic", "prgan") or self.train.rec_target != "image"):
            raise ConfigError("train.photo_augment: new photos have no matching ground-truth volumes; expected "
                              f"train.mode 'platonic' or 'prgan' with rec_target 'image', got mode "
                              f"{self.train.mode!r}, rec_target {self.train.rec_target!r}")
        if "colour" in self.train.photo_augment and self.render.model != "ea":
            raise ConfigError(f"train.photo_augment: 'colour' needs colour, render.model 'ea'; got {self.render.model!r}")
        if self.train.ema is not None and not 0.0 < self.train.ema < 1.0:
            raise ConfigError(f"train.ema: expected null or a decay in (0, 1), e.g. 0.999, got {self.train.ema!r}")
        if self.train.d_gate is not None and not 0.0 < self.train.d_gate <= 1.0:
            raise ConfigError(f"train.d_gate: expected null or a number in (0, 1], got {self.train.d_gate!r}")
        if self.train.mode in MODES_3D and self.data.source != "procedural":
            raise ConfigError(f"train.mode: {self.train.mode!r} needs 3D ground truth, i.e. data.source 'procedural'")
        _choice("train.rec_target", self.train.rec_target, REC_TARGETS)
        if self.train.rec_target == "volume" and self.train.mode not in MODES_3D:
            raise ConfigError(f"train.rec_target: 'volume' needs 3D ground truth, i.e. train.mode one of "
                              f"{list(MODES_3D)}, got {self.train.mode!r}")
        if self.train.mode == "gan3d" and self.train.task == "reconstruction" and self.train.rec_target != "volume":
            raise ConfigError("train.rec_target: the 3D-GAN baseline ('gan3d') renders nothing, so its reconstruction "
                              "term compares volumes; expected 'volume', got 'image'")
        if self.train.mode == "prgan":                       # the PrGAN-style baseline: VH, 8 views on one ring
            prgan = "the PrGAN-style baseline ('prgan')"
            if self.render.model != "vh":
                raise ConfigError(f"render.model: {prgan} trains on visual hulls only; expected 'vh', "
                                  f"got {self.render.model!r}")
            if self.data.source == "procedural" and self.data.formation != "vh":
                raise ConfigError(f"data.formation: {prgan} trains on visual hull images only; expected 'vh', "
                                  f"got {self.data.formation!r}")
            if self.train.view_distribution != "ring":
                raise ConfigError(f"train.view_distribution: {prgan} draws its views from 8 azimuths on one "
                                  f"ring; expected 'ring', got {self.train.view_distribution!r}")
            ring = 0.0 if self.train.elevation is None else self.train.elevation
            if isinstance(ring, list) or not -90.0 <= ring <= 90.0:
                raise ConfigError(f"train.elevation: {prgan} needs one ring elevation in [-90, 90] degrees "
                                  f"(null: 0), got {self.train.elevation!r}")
            if self.train.task == "reconstruction" and ring != 0.0:
                raise ConfigError(f"train.elevation: {prgan} reconstructs in the input camera's frame, whose "
                                  f"view (ring view 0) is at elevation 0; expected 0 or null, got {ring!r}")
            if self.data.source == "procedural":
                if self.data.view_distribution != "ring":
                    raise ConfigError(f"data.view_distribution: {prgan} needs a collection on its ring; "
                                      f"expected 'ring', got {self.data.view_distribution!r}")
                data_ring = DEFAULT_ELEVATION["ring"] if self.data.elevation is None else self.data.elevation
                if data_ring != ring:
                    raise ConfigError(f"data.elevation: {prgan} needs a collection on its ring at {ring:g}°; "
                                      f"got {data_ring!r}")
        if self.data.source == "procedural" and self.data.formation != "physical" \
                and self.render.backend != "physical" and self.data.formation != self.render.model:
            raise ConfigError(f"render.model: {self.render.model!r} differs from data.formation "
                              f"{self.data.formation!r}; the renderer must match how the images were formed")
        return self


def _folder_name(key: str, value: str) -> None:
    """One path component: no separator, not '.' or '..', not empty (so the run stays in out_dir)."""
    seps = {"/", "\\"} | ({os.sep, os.altsep} - {None})
    if not value or value in (".", "..") or any(sep in value for sep in seps) or "\0" in value:
        raise ConfigError(f"{key}: expected a single folder name (no '/', '..' or absolute path), got {value!r}")


def _choice(key: str, value: Any, choices: Sequence[Any]) -> None:
    if value not in choices:
        raise ConfigError(f"{key}: expected one of {list(choices)}, got {value!r}")


def _positive(key: str, value: Any) -> None:
    if not value > 0:
        raise ConfigError(f"{key}: expected a positive value, got {value!r}")


def _non_negative(key: str, value: Any) -> None:
    if value < 0:
        raise ConfigError(f"{key}: expected a non-negative value, got {value!r}")


# The key-and-type check is pydantic's, run on the dataclasses above (a copy of its schema for
# Config, the sections included, with three changes; the dataclasses themselves stay plain):
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
    return ConfigError(f"{key or 'config'}: expected {' or '.join(expected)}, got {errors[0]['input']!r}")


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
            raise ConfigError(f"override {item!r}: expected key=value, e.g. train.steps=500")
        key, text = item.split("=", 1)
        parts = key.strip().split(".")
        if len(parts) != 2 or not all(parts):
            raise ConfigError(f"override {item!r}: expected section.key=value, e.g. train.steps=500")
        try:
            value = yaml.safe_load(text)
        except yaml.YAMLError as e:
            raise ConfigError(f"{key}: could not parse {text!r}: {yaml_problem(e)}") from None
        data.setdefault(parts[0], {})
        if not isinstance(data[parts[0]], dict):
            raise ConfigError(f"{parts[0]}: expected a mapping")
        data[parts[0]][parts[1]] = value
    return data


def _check_elevation(section: str, distribution: str, elevation: Any) -> None:
    """``<section>.elevation`` fits ``<section>.view_distribution`` (the views' own check, naming the keys)."""
    if distribution not in DISTRIBUTIONS:
        return                                               # its own check names it
    if distribution == "sphere" or elevation is None:
        return                                               # sphere ignores it (train warns), None: the default
    try:
        sample_views(1, distribution, seed=0, elevation=tuple(elevation) if isinstance(elevation, list) else elevation)
    except (UserError, TypeError) as e:
        raise ConfigError(f"{section}.elevation: {e} (with {section}.view_distribution {distribution!r})") from None


def load_config(path: Optional[Union[str, Path]] = None, overrides: Sequence[str] = ()) -> Config:
    """Load a YAML config (or the defaults when ``path`` is None), apply overrides, validate."""
    data: Dict[str, Any] = {}
    if path is not None:
        path = config_file(path)
        try:
            data = yaml.safe_load(path.read_text()) or {}
        except UnicodeDecodeError:
            raise ConfigError(f"{path}: not a YAML text file (not UTF-8 text)") from None
        except yaml.YAMLError as e:
            raise ConfigError(f"{path}: not valid YAML ({yaml_problem(e)})") from None
        if not isinstance(data, dict):
            raise ConfigError(f"{path}: expected a mapping of sections (run, data, model, render, train), "
                              f"got a {type(data).__name__}")
    return config_from_dict(apply_overrides(data, overrides))


def config_file(path: Union[str, Path]) -> Path:
    """The config file ``path`` names: the file itself where it exists, else the packaged config
    of that name (``paper``, ``paper.yaml`` or ``configs/paper.yaml``: the repository's configs
    travel inside the package, so they are found from any folder). ConfigError otherwise."""

    p = Path(path)
    if p.is_file():
        return p
    if p.exists():
        raise ConfigError(f"config file {str(path)!r} is not a file")
    if p.parent in (Path("."), Path("configs")) and p.suffix in ("", ".yaml"):
        try:
            return config_path(p.name)
        except FileNotFoundError:
            pass
    raise ConfigError(f"config file {str(path)!r} does not exist (packaged configs, found by name from any "
                      f"folder: {', '.join(config_names())})")


def yaml_problem(e: yaml.YAMLError) -> str:
    """A YAML error on one line: its problem and where (PyYAML's own message spans lines)."""
    mark = getattr(e, "problem_mark", None)
    where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
    return f"{getattr(e, 'problem', None) or type(e).__name__}{where}"


def config_from_dict(data: Dict[str, Any]) -> Config:
    """A nested mapping (a YAML file's, a saved ``Config.to_dict()``) → a validated :class:`Config`;
    :class:`ConfigError` naming the first bad key."""
    if isinstance(data, dict):                               # an empty section (`train:` alone) is its defaults
        data = {name: {} if value is None else value for name, value in data.items()}
    return _typed(data).validate()
