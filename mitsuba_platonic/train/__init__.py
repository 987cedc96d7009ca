"""Training: PlatonicGAN's Algorithm 1 with either renderer, runs, checkpoints and resume.

Above the config and the model: nothing below imports this package (the train and run sections it
reads are the config's, :mod:`mitsuba_platonic.config.train_settings` and
:mod:`~mitsuba_platonic.config.run_settings`), so its run and trainer are imported here at once.
"""

from .run import RunError, load_run, train
from .trainer import Trainer

__all__ = ["train", "load_run", "Trainer", "RunError"]
