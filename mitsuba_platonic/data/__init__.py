"""Data: procedural shape classes with 3D ground truth (:mod:`.shapes`), rendered collections
(:mod:`.render_collection`, ``platonic make-dataset``), contact sheets (:mod:`.preview`), the
photo-collection loader (:mod:`.photos`) and the config's ``data:`` section (:mod:`.settings`)."""

from . import shapes
from .photos import (CollectionReport, ImageRejected, PhotoCollection, PhotoCollectionWarning, PhotoEntry,
                     SkippedFile, decode_image, prepare_image)

__all__ = ["shapes", "PhotoCollection", "CollectionReport", "PhotoEntry", "SkippedFile",
           "PhotoCollectionWarning", "ImageRejected", "decode_image", "prepare_image"]
