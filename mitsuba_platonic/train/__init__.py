"""Training: PlatonicGAN's Algorithm 1 with either renderer, runs, checkpoints and resume."""

from .run import RunError, load_run, train
from .trainer import Trainer

__all__ = ["train", "load_run", "Trainer", "RunError"]
