"""Whether a config's networks can be trained here: their parameters counted (on PyTorch's meta
device) against the memory free, before any data or run folder is written.

Moved out of :mod:`mitsuba_platonic.model` (issue 26): it reads the whole config (its defaults
included) and the critics' shapes, which sit above the model.
"""

from __future__ import annotations

import dataclasses
from typing import Optional, Tuple, Union

import torch

from ..config import Config, ConfigError
from ..config.train_settings import MODES_3D
from ..model import Model, critic_config
from ..networks.nets import Discriminator, VolumeDiscriminator
from ..networks.settings import ModelConfig
from ..runtime import budget

__all__ = ["parameter_count", "check_model_fits", "batch_bytes", "check_batch_fits", "TRAINING_BYTES_PER_PARAMETER",
           "SIZE_KEYS"]

#: Bytes each parameter takes while training, at least: fp32 weights, gradients and Adam's two moments.
TRAINING_BYTES_PER_PARAMETER = 16

#: The model keys that size the networks, which a refusal names (resolution is a short choice list).
SIZE_KEYS = ("latent", "width", "critic_width", "encoder_hidden")


def parameter_count(cfg: Config) -> int:
    """Parameters of every network training ``cfg`` builds (E, G, the pose head, D and D3), counted
    on PyTorch's meta device: nothing is allocated, so a size that cannot fit is counted too."""
    with torch.device("meta"):
        nets = [Model.from_config(cfg, init=False), Discriminator(critic_config(cfg))]
        if cfg.train.mode in MODES_3D:
            nets.append(VolumeDiscriminator(critic_config(cfg)))
    return sum(p.numel() for net in nets for p in net.parameters())


def _largest_size_key(cfg: Config) -> str:
    """The size key of ``cfg.model`` whose default would shrink the networks most."""
    count, best = parameter_count(cfg), ("resolution", 0)
    for key in SIZE_KEYS:
        default = getattr(ModelConfig(), key)
        if getattr(cfg.model, key) != default:
            smaller = dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, **{key: default}))
            saved = count - parameter_count(smaller)
            if saved > best[1]:
                best = (key, saved)
    return best[0]


def _available(device: torch.device) -> Tuple[Optional[int], str]:
    """(free bytes on ``device``, where the number comes from)."""
    if device.type == "cuda":
        return torch.cuda.mem_get_info(device)[0], f"free memory of {device}"
    return budget.available_memory()


def check_model_fits(cfg: Config, device: Union[str, torch.device, None] = None) -> None:
    """Raise :class:`~mitsuba_platonic.config.ConfigError` naming the model key to lower if the
    networks of ``cfg`` cannot be trained in the memory free on ``device`` (default: the one
    ``run.device`` picks): their parameters alone, at :data:`TRAINING_BYTES_PER_PARAMETER` bytes
    each, exceed it (a lower bound of the need)."""
    if device is None:
        cuda = cfg.run.device == "cuda" or (cfg.run.device == "auto" and torch.cuda.is_available())
        device = "cuda" if cuda and torch.cuda.is_available() else "cpu"
    count = parameter_count(cfg)
    need = count * TRAINING_BYTES_PER_PARAMETER
    have, source = _available(torch.device(device))
    if have is None or need <= have:
        check_batch_fits(cfg, device)
        return
    key = _largest_size_key(cfg)
    raise ConfigError(f"model.{key}: {getattr(cfg.model, key)} makes networks of {count:.3g} parameters, "
                      f"which need at least {need / 1e9:.3g} GB to train ({TRAINING_BYTES_PER_PARAMETER} bytes each: "
                      f"weights, gradients, Adam's moments), more than the {max(have, 0) / 1e9:.1f} GB available "
                      f"({source}); lower model.{key}")


def batch_bytes(cfg: Config, batch_size: int) -> int:
    """A lower bound of the memory a training batch of ``batch_size`` volumes takes beyond the
    weights: G's last two activations per volume, kept for the backward pass (``width`` channels at
    (R/2)³, then the volume's logits and values, C channels each at R³), float32."""
    r, c = cfg.model.resolution, 4 if cfg.render.model == "ea" else 1
    return int(batch_size) * (cfg.model.width * (r // 2) ** 3 + 2 * c * r ** 3) * 4


def check_batch_fits(cfg: Config, device: Union[str, torch.device] = "cpu") -> None:
    """:class:`~mitsuba_platonic.config.ConfigError` naming ``train.batch_size`` (with the largest
    batch that fits) where the networks' training state and :func:`batch_bytes` exceed the memory free
    on ``device``, before any data or run folder is written."""
    weights = parameter_count(cfg) * TRAINING_BYTES_PER_PARAMETER
    have = _available(torch.device(device))
    if have[0] is None or weights + batch_bytes(cfg, cfg.train.batch_size) <= have[0]:
        return
    most = max(0, (have[0] - weights) // max(batch_bytes(cfg, 1), 1))
    fix = (f"lower train.batch_size (at most about {most} fit)" if most else
           "not even a batch of 1 fits; lower model.resolution or model.width")
    try:
        budget.check_fits(weights + batch_bytes(cfg, cfg.train.batch_size), have,
                          f"train.batch_size: a batch of {cfg.train.batch_size} volumes of {cfg.model.resolution}³", fix)
    except ConfigError:
        raise
    except ValueError as e:
        raise ConfigError(str(e)) from None
