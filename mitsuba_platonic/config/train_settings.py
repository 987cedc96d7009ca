"""The train section of a config (``train:``) and every training choice list.

:class:`TrainConfig` is the section's dataclass, with the checks that concern it alone
(:meth:`TrainConfig.validate`); the config composes it and checks it against the other sections.
It sits in the config, not beside the training code, because that code reads the whole config:
a section inside ``train/`` made the config import the package that imports it. So the lists
the section checks live here, the losses', rolls' and augmentations' too, and the modules that
implement them import them from here (``train.losses.LOSSES`` is :data:`LOSSES`).

Each list stays importable from the module that uses it (``train.trainer.MODES``); the data
source's and the device's lists are their sections' (``data.settings.SOURCES``,
``config.run_settings.DEVICES``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import List, Optional, Union

from ..settings_checks import ConfigError, check_elevation, choice, non_negative, positive
from ..views import DISTRIBUTIONS

__all__ = ["TrainConfig", "TASKS", "MODES", "MODES_3D", "REC_TARGETS", "REC_LOSSES", "REC_CHANNELS", "POSES", "LIGHTS", "PRGAN",
           "LOSS_WEIGHTS", "LOSSES", "ROLLS", "AUGMENTS", "PHOTO_AUGMENTS"]

#: What E/G learn: reconstruct the input image, or generate from z ~ N(0, I).
TASKS = ("reconstruction", "generation")
#: Which critics train G (module docstring of :mod:`mitsuba_platonic.train.trainer`).
MODES = ("platonic", "platonic3d", "gan3d", "prgan")
#: Modes that learn from ground-truth volumes (a 3D critic D3).
MODES_3D = ("platonic3d", "gan3d")
#: train.rec_target: the reconstruction term compares the input image with v's render at the
#: input view, or v with the input image's ground-truth volume (3D modes)
REC_TARGETS = ("image", "volume")
#: train.rec_loss: the input-view term's distance, the paper's mean squared error or the mean
#: absolute error (docs/training.md, "The measurements")
REC_LOSSES = ("l2", "l1")
#: train.rec_channels: what of the input image the image term compares, all its channels or its
#: opacity alone (for a lit renderer whose light is not the photo's:
#: docs/training.md, "The measurements")
REC_CHANNELS = ("all", "alpha")
#: train.pose: G's volume in the input camera's frame, or upright and tilted by an elevation E reads
POSES = ("input", "elevation")
#: train.light: where the light of the input view's render comes from
LIGHTS = ("prior", "head")
#: The weights of the loss terms: each ≥ 0 (0: the term is off), checked by name.
LOSS_WEIGHTS = ("gp_weight", "rec_weight", "weight_3d", "pose_weight", "r1_weight", "colour_tv",
                "colour_match", "colour_offset", "depth_spread", "turn", "solidity")
#: How messages name ``train.mode: prgan``.
PRGAN = "the PrGAN-style baseline ('prgan')"
#: The GAN losses of :func:`~mitsuba_platonic.train.losses.d_loss` / ``g_loss`` (anything but the first is WGAN-GP).
LOSSES = ("nonsaturating", "wgan-gp")
#: train.d_roll: 'none' (D sees the images as rendered) | 'uniform' | 'matched' (:mod:`mitsuba_platonic.train.image_roll`).
ROLLS = ("none", "uniform", "matched")
#: The transforms ``train.d_augment`` may list, applied in this order (:mod:`mitsuba_platonic.train.augment`).
AUGMENTS = ("flip", "translation", "cutout")
#: The transforms ``train.photo_augment`` may list, applied in this order.
PHOTO_AUGMENTS = ("flip", "colour")


@dataclass
class TrainConfig:
    """The train section, one line per key (its tables in docs/training.md are made from these lines).

    task: 'reconstruction' (E encodes the input image; the reconstruction term at the input view) or
    'generation' (from z ~ N(0, I)).
    mode: 'platonic' (the 2D critic only), 'platonic3d' (+ a 3D critic on ground-truth volumes; G learns from
    both), 'gan3d' (the 3D-GAN baseline: WGAN-GP on volumes, no rendering) or 'prgan' (the PrGAN-style
    baseline: VH only, views from 8 azimuths on the ring at ``elevation`` (0° by default; reconstruction:
    0°, the input view's), G(z, one-hot view); docs/training.md, "Baselines (Table 2)").
    batch_size, random_views: the global batch (split across processes), and random views per volume per step:
    two reduce the depth stripes, with novel-view scores within one seed's noise
    (docs/training.md, "The measurements").
    view_distribution, elevation: p_view, where the random views are drawn; for photos, the band the
    photos' cameras were in ('band', [-10, 40]).
    pose, pose_weight: where G's volume stands, 'input' (in the input camera's frame, the paper's view-space
    reconstruction, where G builds every object upright whatever the elevation) | 'elevation'
    (reconstruction, mode 'platonic'): G builds the object upright in its own frame, a pose head reads the
    input camera's elevation θ̂ from E's code, the input-view term renders the volume tilted by θ̂ and the
    random views are drawn around the upright object, as the photos' cameras were ("The quickstart's
    choices"; docs/training.md, "The measurements"); pose_weight: λ of the term that teaches the head the elevations of
    G's own renders from those random views (0: none; only with 'elevation';
    docs/training.md, "The measurements").
    rec_weight: λ of the input-view (reconstruction) term (the shipped configs: 10; the photo configs: 20,
    against the turn's pull towards round).
    rec_target: what that term compares, 'image' (the input image with the render of v at the input view:
    PlatonicGAN's, 2D data only) or 'volume' (v with the input image's ground-truth volume in its camera's
    frame: 3D supervision, the 3D modes only; the 3D-GAN baseline's, which renders nothing;
    docs/training.md, "The measurements").
    rec_loss: the image term's distance, 'l2' (mean (I_front − x)², the paper's) or 'l1' (mean |I_front − x|:
    the median, not the mean, of what the code cannot tell apart; image targets only; the photo configs',
    docs/training.md, "The measurements").
    rec_channels: what the image term compares, 'all' channels (the paper's) or 'alpha' (the opacity alone,
    EA images: the silhouette and its soft edge), for a lit renderer whose light is drawn from a prior, not
    the photo's, where comparing the shading made shape noise (3D IoU 0.17 → 0.26 through single
    scattering; docs/training.md, "The measurements").
    light: the light of the input view's render under single scattering (render.backend 'single_scatter' or
    'scatter_march'), 'prior' (drawn from the prior, as every random view's is) or 'head': a light head reads
    the photo's sun direction and sky share from E's code, learnt from G's renders under the prior's
    lights, and the input view is rendered under it, so that the image term can compare colour and shading
    (rec_channels 'all'); it re-renders held-out shapes under new light better than EA (RMSE 13.21 against
    14.18) at the same 3D IoU (docs/training.md, "The measurements").
    loss, gp_weight: the GAN loss, 'nonsaturating' | 'wgan-gp' (the 3D-GAN baseline's), and the WGAN-GP
    penalty's weight λ.
    lr_d: D's Adam learning rate: with the gate and no normalisation the authors' 1e-5 leaves novel views
    thinner than the billboard (IoU 0.156 against 0.493); the quickstart uses 1e-4 with R1
    (docs/training.md, "The measurements").
    d_gate: update D only while its *soft* accuracy ½(mean σ(l_real) + 1 − mean σ(l_fake)) ≤ this (0.6, the
    authors' gate; null: always, as with R1); it never triggers at lr_d 2e-5 in the quickstart, and keeps a
    faster D (lr_d 1e-4) from collapsing G, which it does ungated (IoU 0 ungated, 0.642 gated).
    r1_weight: γ of the R1 penalty γ/2 · E‖∇ₓD(x)‖² on real images (Mescheder et al. 2018), added to every
    critic's non-saturating loss (0: none; WGAN-GP has its own penalty; 1 in the shipped configs:
    :func:`mitsuba_platonic.train.losses.r1_penalty`, docs/training.md, "The measurements").
    d_steps: D (or D3) updates per G update, each on a fresh loss, in every mode.
    d_roll: 'none' | 'uniform': D sees every real and rendered image turned in-plane by its own random
    angle, so that the tilt of views drawn in the input camera's frame cannot give fakes away; 'matched'
    (reconstruction): the reals turned by the tilt a right volume's view would have, for an input elevation
    drawn from the collection's view distribution (procedural data; for photos the train section's);
    measured to gain nothing on the mushrooms, kept for collections with a wide spread of elevations and
    pose 'input' (:mod:`mitsuba_platonic.train.image_roll`, docs/training.md, "The measurements").
    d_augment: the differentiable augmentations of every image D sees, real or rendered, in D's and G's
    updates, from 'flip', 'translation', 'cutout' (none by default; for small photo collections, "The photo
    config's choices"; :mod:`mitsuba_platonic.train.augment`).
    weight_3d: the weight of the 3D critic's adversarial term ('platonic3d').
    colour_tv: the weight of G's density-weighted colour total variation (EA, not 'gan3d'; 0: none); it helps
    the photo configs' unseen side, and costs the procedural quickstart 0.02–0.03 of novel-view IoU
    (:func:`mitsuba_platonic.train.losses.colour_tv`, docs/training.md, "The measurements").
    colour_match: the weight of the term that holds the mean colour of each random view's object to the input
    photo's (reconstruction, EA, mode 'platonic'; 0: none; a photo config's colour term:
    :func:`mitsuba_platonic.train.losses.colour_match`).
    colour_offset: the weight of the density-weighted mean |ℓ| of G's colour offsets from the photo's colour
    (``model.photo_colour``; 0: none; a photo config's colour term: :func:`mitsuba_platonic.train.losses.colour_offset`).
    depth_spread: the weight of the distortion of the input view's EA weights along its rays, a prior that
    each ray's colour come from a thin surface, not a haze (reconstruction, image targets; 0: none; a photo
    config's colour term: :func:`mitsuba_platonic.train.losses.depth_spread`).
    turn: the weight of the prior that the object is probably round about its vertical axis, its upright
    opacity against itself turned by a random angle (train.pose 'elevation'; 0: none; 1 in the photo
    configs; set it to 0 for a class that is not round: :func:`mitsuba_platonic.train.losses.turn`).
    solidity: the weight of the prior that along each input ray the object is solid between its first and
    its last surface (reconstruction, platonic mode, orthographic camera; 0: none; 1 in the photo configs:
    :func:`mitsuba_platonic.train.losses.solidity`).
    photo_augment: transforms of each step's photos before E, the reconstruction target and D read them, from
    'flip', 'colour' (none by default; modes 'platonic' and 'prgan', image targets; 'colour' needs EA), so
    that E reads colour from a photo instead of memorising a few dozen photos
    (:func:`mitsuba_platonic.train.augment.augment_photos`, docs/training.md, "The measurements").
    ema: null, or the decay β of an exponential moving average of E's and G's weights, which samples,
    checkpoints' inference weights and evaluation then use (0.99 in the shipped configs:
    :meth:`mitsuba_platonic.train.trainer.Trainer.inference_model`, docs/training.md, "The measurements").
    lr_g, lr_e, betas: G's and E's Adam learning rates and Adam's betas, as the paper's.
    """

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
    rec_loss: str = "l2"
    rec_channels: str = "all"
    light: str = "prior"
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
    colour_match: float = 0.0
    colour_offset: float = 0.0
    depth_spread: float = 0.0
    turn: float = 0.0
    solidity: float = 0.0
    ema: Optional[float] = None
    d_augment: List[str] = field(default_factory=list)
    photo_augment: List[str] = field(default_factory=list)

    @property
    def ring_elevation(self) -> Union[float, List[float]]:
        """The elevation of the PrGAN-style baseline's ring: ``elevation``, null meaning 0."""
        return 0.0 if self.elevation is None else self.elevation

    def validate(self) -> "TrainConfig":
        """Check this section's values and combinations; raise
        :class:`~mitsuba_platonic.settings_checks.ConfigError` naming the key (``train.mode: ...``).
        Checks against other sections (the renderer's image formation, the data's source) are the config's."""
        check_elevation("train", self.view_distribution, self.elevation)
        choice("train.task", self.task, TASKS)
        choice("train.mode", self.mode, MODES)
        choice("train.view_distribution", self.view_distribution, DISTRIBUTIONS)
        choice("train.loss", self.loss, LOSSES)
        positive("train.batch_size", self.batch_size)
        positive("train.random_views", self.random_views)
        positive("train.d_steps", self.d_steps)
        choice("train.d_roll", self.d_roll, ROLLS)
        if self.d_roll == "matched" and (self.task != "reconstruction" or self.mode == "gan3d"):
            raise ConfigError("train.d_roll: 'matched' turns the photos by the tilt of views drawn in an input "
                              "camera's frame, so it needs train.task 'reconstruction' and a 2D critic "
                              f"(not mode 'gan3d'), got task {self.task!r}, mode {self.mode!r}")
        choice("train.pose", self.pose, POSES)
        for key in LOSS_WEIGHTS:                             # a negative weight turns a loss into a reward
            non_negative(f"train.{key}", getattr(self, key))
        if self.pose == "elevation":
            if self.task != "reconstruction" or self.mode != "platonic":
                raise ConfigError("train.pose: 'elevation' reads the input camera's elevation from the photo, so it "
                                  "needs train.task 'reconstruction' and train.mode 'platonic', got task "
                                  f"{self.task!r}, mode {self.mode!r}")
            if self.d_roll != "none":
                raise ConfigError("train.d_roll: with train.pose 'elevation' the random views are drawn around the "
                                  "upright object, as the photos' cameras were, so nothing is to be turned; "
                                  f"expected 'none', got {self.d_roll!r}")
        elif self.pose_weight > 0:
            raise ConfigError("train.pose_weight: the pose term trains the elevation head of train.pose "
                              f"'elevation'; with pose {self.pose!r} expected 0, got {self.pose_weight!r}")
        if self.turn > 0 and self.pose != "elevation":
            raise ConfigError("train.turn: the prior turns G's volume by a random angle about the object's vertical, which "
                              f"only an upright volume has, so it needs train.pose 'elevation', got {self.pose!r}")
        for key in ("lr_g", "lr_e", "lr_d"):
            if not getattr(self, key) > 0:
                raise ConfigError(f"train.{key}: expected a positive learning rate, got {getattr(self, key)!r}")
        if len(self.betas) != 2 or not all(0.0 <= b < 1.0 for b in self.betas):
            raise ConfigError(f"train.betas: expected two numbers in [0, 1), got {self.betas!r}")
        if self.r1_weight > 0 and self.loss != "nonsaturating":
            raise ConfigError("train.r1_weight: the R1 penalty is for the non-saturating loss; "
                              f"train.loss {self.loss!r} has its own (train.gp_weight)")
        if self.colour_match > 0 and (self.task != "reconstruction" or self.mode != "platonic"):
            raise ConfigError("train.colour_match: the random views answer to the input photo's colour, so it needs "
                              f"train.task 'reconstruction' and mode 'platonic', got task {self.task!r}, mode {self.mode!r}")
        if self.colour_tv > 0 and self.mode == "gan3d":
            raise ConfigError("train.colour_tv: the 'gan3d' baseline trains G on volumes alone, without priors")
        unknown = [a for a in self.d_augment if a not in AUGMENTS]
        if unknown or len(set(self.d_augment)) != len(self.d_augment):
            raise ConfigError(f"train.d_augment: expected distinct names from {list(AUGMENTS)}, got "
                              f"{self.d_augment!r}")
        if self.d_augment and self.mode == "gan3d":
            raise ConfigError("train.d_augment: the 'gan3d' baseline has no 2D critic to augment for")
        unknown = [a for a in self.photo_augment if a not in PHOTO_AUGMENTS]
        if unknown or len(set(self.photo_augment)) != len(self.photo_augment):
            raise ConfigError(f"train.photo_augment: expected distinct names from {list(PHOTO_AUGMENTS)}, got "
                              f"{self.photo_augment!r}")
        if self.photo_augment and (self.mode not in ("platonic", "prgan") or self.rec_target != "image"):
            raise ConfigError("train.photo_augment: new photos have no matching ground-truth volumes; expected "
                              f"train.mode 'platonic' or 'prgan' with rec_target 'image', got mode "
                              f"{self.mode!r}, rec_target {self.rec_target!r}")
        if self.ema is not None and not 0.0 < self.ema < 1.0:
            raise ConfigError(f"train.ema: expected null or a decay in (0, 1), e.g. 0.999, got {self.ema!r}")
        if self.d_gate is not None and not 0.0 < self.d_gate <= 1.0:
            raise ConfigError(f"train.d_gate: expected null or a number in (0, 1], got {self.d_gate!r}")
        choice("train.rec_target", self.rec_target, REC_TARGETS)
        choice("train.rec_loss", self.rec_loss, REC_LOSSES)
        choice("train.rec_channels", self.rec_channels, REC_CHANNELS)
        if self.rec_channels != "all" and self.rec_target != "image":
            raise ConfigError(f"train.rec_channels: {self.rec_channels!r} applies to the input-view image term; "
                              f"rec_target {self.rec_target!r} compares volumes")
        if self.rec_loss != "l2" and self.rec_target != "image":
            raise ConfigError(f"train.rec_loss: {self.rec_loss!r} applies to the input-view image term; "
                              f"rec_target {self.rec_target!r} compares volumes by their mean squared error")
        choice("train.light", self.light, LIGHTS)
        if self.light == "head" and (self.task != "reconstruction" or self.mode != "platonic"
                                     or self.rec_target != "image" or self.rec_channels != "all"):
            raise ConfigError("train.light: 'head' renders the input view under the light read from the photo so that "
                              "the image term compares its colour; it needs train.task 'reconstruction', mode "
                              f"'platonic', rec_target 'image' and rec_channels 'all', got task {self.task!r}, mode "
                              f"{self.mode!r}, rec_target {self.rec_target!r}, rec_channels {self.rec_channels!r}")
        if self.rec_target == "volume" and self.mode not in MODES_3D:
            raise ConfigError(f"train.rec_target: 'volume' needs 3D ground truth, i.e. train.mode one of "
                              f"{list(MODES_3D)}, got {self.mode!r}")
        if self.mode == "gan3d" and self.task == "reconstruction" and self.rec_target != "volume":
            raise ConfigError("train.rec_target: the 3D-GAN baseline ('gan3d') renders nothing, so its reconstruction "
                              "term compares volumes; expected 'volume', got 'image'")
        if self.mode == "prgan":                             # the PrGAN-style baseline: 8 views on one ring
            if self.view_distribution != "ring":
                raise ConfigError(f"train.view_distribution: {PRGAN} draws its views from 8 azimuths on one "
                                  f"ring; expected 'ring', got {self.view_distribution!r}")
            ring = self.ring_elevation
            if isinstance(ring, list) or not -90.0 <= ring <= 90.0:
                raise ConfigError(f"train.elevation: {PRGAN} needs one ring elevation in [-90, 90] degrees "
                                  f"(null: 0), got {self.elevation!r}")
            if self.task == "reconstruction" and ring != 0.0:
                raise ConfigError(f"train.elevation: {PRGAN} reconstructs in the input camera's frame, whose "
                                  f"view (ring view 0) is at elevation 0; expected 0 or null, got {ring!r}")
        return self
