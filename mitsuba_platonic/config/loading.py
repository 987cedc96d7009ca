"""What training saved, read back: a checkpoint's config as a validated :class:`Config`, and its model.

The checkpoint file format (:mod:`mitsuba_platonic.files.checkpoint`) stores and returns plain data, the
config as the mapping ``Config.to_dict()`` wrote; this module, in the config's package, builds the
config and the model from it. Old run folders load as they did: a saved config that lacks keys
added since gets their defaults, as a YAML file would, and one that holds a retired option at the
value that left it off loads without it; one that had it on names the commit that still has its
code (:mod:`.retired`, the list of retired options).

:meth:`Model.from_checkpoint <mitsuba_platonic.model.Model.from_checkpoint>` is the public entry
point, one layer up; it hands its class to :func:`load_model`, so this module never imports the model's.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Dict, Optional, Tuple, Type, TypeVar, Union

import torch

from ..files.checkpoint import Checkpoint, RunError, load_weights, read_checkpoint, saved_config_dict
from . import Config, ConfigError, config_from_dict
from .retired import without_retired

__all__ = ["saved_config", "checkpoint_config", "config_difference", "RESUME_SECTIONS", "model_from_checkpoint",
           "load_model"]

M = TypeVar("M")


def saved_config(state: Dict[str, Any], path: Path, run_name: Optional[str] = None) -> Config:
    """The validated config saved in a checkpoint (``run.name`` replaced by ``run_name`` if given);
    :class:`RunError` naming ``path`` if it is not a mapping of sections or not valid."""
    saved = saved_config_dict(state, path, run_name)
    try:
        return config_from_dict(without_retired(saved))
    except ConfigError as e:
        raise RunError(f"{path}: the config saved in this checkpoint is not valid: {e}") from None


def checkpoint_config(ckpt: Checkpoint) -> Config:
    """The validated config of a checkpoint already read (:func:`~mitsuba_platonic.files.checkpoint.read_checkpoint`);
    :class:`RunError` naming its file if it is not valid."""
    return saved_config({"config": ckpt.config}, ckpt.path)


#: The config sections a run's networks and exact continuation depend on (only ``run.*`` may change).
RESUME_SECTIONS = ("data", "model", "render", "train")


def config_difference(saved: Config, current: Config, sections: Tuple[str, ...] = RESUME_SECTIONS,
                      there: str = "saved", here: str = "now") -> Optional[str]:
    """The first key of ``sections`` whose value differs between two configs, worded for a message
    (``model.width: 4 saved, 8 now``), else None."""
    a, b = saved.to_dict(), current.to_dict()
    for section in sections:
        for key in list(a[section]) + [k for k in b[section] if k not in a[section]]:
            if a[section].get(key) != b[section].get(key):
                return f"{section}.{key}: {a[section].get(key)!r} {there}, {b[section].get(key)!r} {here}"
    return None


def model_from_checkpoint(cls: Type[M], ckpt: Checkpoint, cfg: Optional[Config] = None) -> M:
    """The model (of class ``cls``, :class:`~mitsuba_platonic.model.Model`) of a checkpoint already
    read, for its config ``cfg`` (default: :func:`checkpoint_config`): the moving average of E's and
    G's weights when the run kept one (``train.ema``), else E and G as trained."""
    cfg = checkpoint_config(ckpt) if cfg is None else cfg
    trainer = ckpt.state["trainer"]
    nets = trainer["nets"]
    model = cls.from_config(cfg, init=False)
    what = "the networks of the config saved with it"           # weights and config from one file
    if "ema" in trainer:
        load_weights(model, trainer["ema"], ckpt.path, what)
    else:
        load_weights(model, {k: v for k, v in nets.items() if k.startswith(("E.", "G.", "P.", "L."))}, ckpt.path, what)
    _check_finite(model, ckpt.path)
    model.step, model.origin = ckpt.step, ckpt.path
    device = next(iter(nets.values())).device if nets else torch.device("cpu")
    return model.to(device)


def _check_finite(model: torch.nn.Module, path: Path) -> None:
    """:class:`RunError` naming ``path`` and the first weight that holds NaN or ±Inf (a run that
    diverged saved them; every volume would be NaN)."""
    for name, value in model.state_dict().items():
        if value.is_floating_point() and not bool(torch.isfinite(value).all()):
            what = "NaN" if bool(torch.isnan(value).any()) else "Inf"
            raise RunError(f"{path}: the checkpoint's weights hold {what} (first at {name}): the run diverged; use "
                           f"an earlier checkpoint "
                           f"(--run {path.parent}/step_NNNNNNN.pt) or train again")


def load_model(cls: Type[M], source: Union[str, Path], device: Union[str, torch.device] = "cpu") -> M:
    """:meth:`Model.from_checkpoint <mitsuba_platonic.model.Model.from_checkpoint>`: the model of a run
    folder (its newest loadable checkpoint) or of one checkpoint file (see there)."""
    return model_from_checkpoint(cls, read_checkpoint(source, device))
