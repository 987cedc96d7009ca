"""The training components' choice lists: a leaf, so that the config validates against them
without importing the trainer, the run or the data loader (which import the config).

Each list stays importable from the module that uses it (``train.trainer.MODES``,
``train.run.DEVICES``, ``train.data.SOURCES``); the losses', rolls' and augmentations' lists live
beside their code (``train.losses.LOSSES``, ``train.roll.ROLLS``, ``train.augment.AUGMENTS``),
whose modules import no config either.
"""

from __future__ import annotations

__all__ = ["SOURCES", "DEVICES", "TASKS", "MODES", "MODES_3D", "REC_TARGETS", "POSES"]

#: data.source: a procedural collection rendered by make-dataset, or a folder of photos.
SOURCES = ("procedural", "folder")

#: run.device: 'auto' picks CUDA when available.
DEVICES = ("auto", "cpu", "cuda")

#: What E/G learn: reconstruct the input image, or generate from z ~ N(0, I).
TASKS = ("reconstruction", "generation")
#: Which critics train G (module docstring of :mod:`mitsuba_platonic.train.trainer`).
MODES = ("platonic", "platonic3d", "gan3d", "prgan")
#: Modes that learn from ground-truth volumes (a 3D critic D3).
MODES_3D = ("platonic3d", "gan3d")
#: train.rec_target: the reconstruction term compares the input image with v's render at the
#: input view, or v with the input image's ground-truth volume (3D modes)
REC_TARGETS = ("image", "volume")
#: train.pose: G's volume in the input camera's frame, or upright and tilted by an elevation E reads
POSES = ("input", "elevation")
