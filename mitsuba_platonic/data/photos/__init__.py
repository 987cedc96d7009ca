"""Photo collections: a folder of photos → a PyTorch dataset of premultiplied linear RGBA images.

PlatonicGAN learns from an *unstructured* collection: one folder of photos of one object
class, each showing one object cut out from its background. :class:`PhotoCollection` turns
such a folder into training images in the conventions of docs/conventions.md ("Images"):

- ``(4, R, R)`` float32 ``[r, g, b, alpha]`` in [0, 1], **linear** RGB **premultiplied** by
  alpha (the EA renderer's output), or ``(1, R, R)`` alpha only (``alpha_only=True``: the
  VH/AO opacity image). Row 0 is the top of the photo.

The pipeline, one module per step (each module's docstring states its maths and choices):

1. :mod:`.scan` — discovery (recursive, hidden paths ignored) and de-duplication by SHA-256;
2. :mod:`.decode` — decoding by content (PNG of any colour type, 8 or 16 bits; JPEG; WebP),
   EXIF orientation;
3. :mod:`.mask` — sRGB → linear colour, and the mask (the file's alpha, or a white
   background), cleaned; premultiplied colour;
4. :mod:`.frame` — crop, centred transparent padding to a square, antialiased resampling
   (:mod:`.prepare` chains 3 and 4 for one image);
5. :mod:`.split` — train / val / test by seeded content hash;
6. :mod:`.dataset` — the ``Dataset``.

Bad input never stops the loading of the others and is never dropped silently: each rejected
file is named in a :class:`PhotoCollectionWarning` and recorded in
:attr:`CollectionReport.skipped` with one of the reasons in :data:`REASONS`
(:mod:`.rejections`).

Example::

    from mitsuba_platonic.data.photos import PhotoCollection
    sets = PhotoCollection.load_splits("my_photos/", resolution=64)   # a folder of cut-out photos
    train = sets["train"]                  # a torch Dataset of (4, 64, 64) tensors
    print(train.report)                    # files found, duplicates, skipped files, split sizes
    loader = torch.utils.data.DataLoader(train, batch_size=8, shuffle=True)
"""

from .dataset import PhotoCollection
from .decode import SUPPORTED_FORMATS, DecodedImage, decode_image
from .frame import CROPS, MAX_ASPECT, frame_and_resample
from .mask import BACKGROUNDS, clean_mask, premultiplied_linear, srgb_decoding_table, \
    white_background_alpha
from .prepare import ImageOptions, PhotoOptions, prepare_image
from .rejections import REASONS, ImageRejected, PhotoCollectionWarning
from .scan import CollectionReport, PhotoEntry, SkippedFile
from .split import SPLITS, split_counts

__all__ = [
    "PhotoCollection",
    "CollectionReport",
    "SkippedFile",
    "PhotoEntry",
    "DecodedImage",
    "ImageOptions",
    "PhotoOptions",
    "ImageRejected",
    "PhotoCollectionWarning",
    "decode_image",
    "prepare_image",
    "white_background_alpha",
    "clean_mask",
    "premultiplied_linear",
    "frame_and_resample",
    "srgb_decoding_table",
    "split_counts",
    "SUPPORTED_FORMATS",
    "REASONS",
    "MAX_ASPECT",
    "SPLITS",
    "BACKGROUNDS",
    "CROPS",
]
