"""Photo-collection loader: the shared tree collection and crafted inputs of every kind."""

import io
import math
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

from mitsuba_platonic.data.photos import (
    ImageRejected,
    PhotoCollection,
    PhotoCollectionWarning,
    clean_mask,
    decode_image,
    premultiplied_linear,
    split_counts,
    srgb_decoding_table,
)
from mitsuba_platonic.data.photos.mask import border_background

TREE = (Path(__file__).resolve().parents[2] / "shared" / "data" / "tree").resolve()  # the loader resolves links
needs_tree = pytest.mark.skipif(not TREE.is_dir(), reason=f"{TREE} is absent")


def lin(code, bits=8):
    """Linear value of an sRGB code (via colour-science, independently of the loader's table)."""
    import colour

    return float(colour.cctf_decoding(code / (2 ** bits - 1), "sRGB"))


# --------------------------------------------------------------------------------------------
# Crafting files
# --------------------------------------------------------------------------------------------


def save(img: Image.Image, path: Path, **kw) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    img.save(path, **kw)
    return path


def rgba(arr) -> Image.Image:
    return Image.fromarray(np.asarray(arr, np.uint8), "RGBA")


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def _filtered(rows: np.ndarray, bpp: int) -> bytes:
    """PNG-filter byte rows (h, n) with filter type y % 5 on row y (all five filters)."""
    out = bytearray()
    prev = np.zeros(rows.shape[1], np.int64)
    for y, row in enumerate(rows.astype(np.int64)):
        a = np.concatenate([np.zeros(bpp, np.int64), row[:-bpp]])
        c = np.concatenate([np.zeros(bpp, np.int64), prev[:-bpp]])
        b = prev
        kind = y % 5
        if kind == 0:
            f = row
        elif kind == 1:
            f = row - a
        elif kind == 2:
            f = row - b
        elif kind == 3:
            f = row - (a + b) // 2
        else:
            p = a + b - c
            pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
            f = row - np.where((pa <= pb) & (pa <= pc), a, np.where(pb <= pc, b, c))
        out += bytes([kind]) + (f % 256).astype(np.uint8).tobytes()
        prev = row
    return bytes(out)


def png16(arr, colour_type: int, *, interlace: bool = False, trns=None, exif: bytes = b"") -> bytes:
    """A 16-bit PNG written by hand (Pillow cannot write 16-bit colour PNGs)."""
    arr = np.asarray(arr, np.uint16)
    if arr.ndim == 2:
        arr = arr[..., None]
    h, w, c = arr.shape
    bpp = 2 * c

    def encode(sub):
        if sub.shape[0] == 0 or sub.shape[1] == 0:
            return b""
        rows = np.frombuffer(sub.astype(">u2").tobytes(), np.uint8).reshape(sub.shape[0], -1)
        return _filtered(rows, bpp)

    if interlace:  # Adam7
        passes = [(0, 0, 8, 8), (4, 0, 8, 8), (0, 4, 4, 8), (2, 0, 4, 4), (0, 2, 2, 4),
                  (1, 0, 2, 2), (0, 1, 1, 2)]
        raw = b"".join(encode(arr[y0::dy, x0::dx]) for x0, y0, dx, dy in passes)
    else:
        raw = encode(arr)
    ihdr = struct.pack(">IIBBBBB", w, h, 16, colour_type, 0, 0, int(interlace))
    extra = _chunk(b"tRNS", struct.pack(">" + "H" * len(trns), *trns)) if trns else b""
    extra += _chunk(b"eXIf", exif) if exif else b""
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + extra
            + _chunk(b"IDAT", zlib.compress(raw)) + _chunk(b"IEND", b""))


def blob(seed: int, size=(24, 16)) -> Image.Image:
    """A small RGBA image with an opaque random-coloured rectangle (distinct per seed)."""
    rng = np.random.default_rng(seed)
    w, h = size
    arr = np.zeros((h, w, 4), np.uint8)
    arr[3:h - 3, 4:w - 4, :3] = rng.integers(0, 256, 3)
    arr[3:h - 3, 4:w - 4, 3] = 255
    arr[4, 5, :3] = seed % 256  # makes every seed's bytes distinct
    return rgba(arr)


# --------------------------------------------------------------------------------------------
# The tree collection
# --------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def tree_bbox():
    return PhotoCollection.load_splits(TREE, 64, crop="bbox", margin=0.05)


@pytest.fixture(scope="module")
def tree_image():
    return PhotoCollection(TREE, 64, "all")


@pytest.fixture(scope="module")
def tree_sources(tree_image):
    """Cleaned source alpha (full resolution) of each unique tree image, by SHA-256."""
    out = {}
    for e in tree_image.entries:
        out[e.sha256] = premultiplied_linear(decode_image(e.path))[..., 3]
    return out


@needs_tree
def test_tree_dedup_and_report(tree_bbox):
    full = tree_bbox["all"]
    rep = full.report
    assert rep.files_found == 48 and rep.unique_files == 32 and rep.duplicates == 16
    assert len(full) == 32 and rep.usable == 32 and rep.skipped == []
    assert len(set(full.hashes)) == 32 and len(set(full.files)) == 32
    assert len(rep.duplicate_groups) == 10
    rel = {k.relative_to(TREE).as_posix(): sorted(p.relative_to(TREE).as_posix() for p in v)
           for k, v in rep.duplicate_groups.items()}
    assert rel["test/7.png"] == ["test/9.png", "train/24.png", "val/7.png"]
    assert rel["test/11.png"] == ["train/26.png"]
    assert "16 duplicate(s) dropped" in str(rep)


@needs_tree
def test_tree_splits_disjoint_covering_deterministic(tree_bbox):
    sets = {k: set(v.hashes) for k, v in tree_bbox.items()}
    assert [len(tree_bbox[k]) for k in ("train", "val", "test")] == [26, 3, 3]
    assert not (sets["train"] & sets["val"] or sets["train"] & sets["test"]
                or sets["val"] & sets["test"])
    assert sets["train"] | sets["val"] | sets["test"] == sets["all"]
    assert tree_bbox["train"].report.split_sizes == {"train": 26, "val": 3, "test": 3}
    # the same seed gives the same splits (and the same pixels); alpha_only gives the alpha
    again = PhotoCollection(TREE, 64, "val", crop="bbox", margin=0.05, alpha_only=True)
    assert again.hashes == tree_bbox["val"].hashes
    assert again[0].shape == (1, 64, 64)
    assert torch.equal(again[0], tree_bbox["val"][0][3:4])


@needs_tree
def test_tree_values_premultiplied_and_binaryish(tree_bbox):
    from scipy import ndimage

    imgs = tree_bbox["all"].images()
    assert imgs.shape == (32, 4, 64, 64) and imgs.dtype == torch.float32
    assert imgs.min() >= 0 and imgs.max() <= 1
    assert (imgs[:, :3] <= imgs[:, 3:] + 1e-6).all()
    for img in imgs:
        a = img[3].numpy()
        inner = ndimage.minimum_filter(a, 3) > 0.5
        assert inner.sum() > 200
        assert a[inner].mean() > 0.97               # the interior is opaque
        assert ((a > 0.02) & (a < 0.98)).mean() < 0.25   # partial alpha only along edges
        assert a[0].max() < 0.05 and a[:, 0].max() < 0.05  # the margin is transparent


def _moments(a: np.ndarray):
    """Alpha-weighted mean and standard deviation of pixel-centre coordinates (row, col)."""
    ys, xs = np.indices(a.shape) + 0.5
    m = a.sum()
    my, mx = (a * ys).sum() / m, (a * xs).sum() / m
    sy = math.sqrt((a * (ys - my) ** 2).sum() / m)
    sx = math.sqrt((a * (xs - mx) ** 2).sum() / m)
    return my, mx, sy, sx


@needs_tree
@pytest.mark.parametrize("crop", ["bbox", "image"])
def test_tree_framing_centred_and_not_stretched(crop, tree_bbox, tree_image, tree_sources):
    """Output alpha moments = source moments mapped by one scale and a translation."""
    collection = tree_bbox["all"] if crop == "bbox" else tree_image
    R, margin = 64, collection.options.margin
    for entry, img in zip(collection.entries, collection.images()):
        src = tree_sources[entry.sha256]
        h, w = src.shape
        assert (w, h) == entry.size
        r0, c0 = 0, 0
        if crop == "bbox":
            rows, cols = np.flatnonzero(src.any(1)), np.flatnonzero(src.any(0))
            r0, c0 = rows[0], cols[0]
            h, w = rows[-1] - r0 + 1, cols[-1] - c0 + 1
        side = math.ceil(max(h, w) / (1 - 2 * margin) - 1e-9)
        s = R / side
        my, mx, sy, sx = _moments(src)
        out = img[3].numpy().astype(np.float64)
        oy, ox, osy, osx = _moments(out)
        assert abs(oy - (my - r0 + (side - h) // 2) * s) < 0.3
        assert abs(ox - (mx - c0 + (side - w) // 2) * s) < 0.3
        # one scale in both directions (the triangle filter adds a variance of ~1/6 px²)
        assert abs(osy - math.sqrt((sy * s) ** 2 + 1 / 6)) < 0.03 * osy
        assert abs(osx - math.sqrt((sx * s) ** 2 + 1 / 6)) < 0.03 * osx
        if crop == "bbox":  # the box is centred and fills R(1 − 2·margin) along its long side
            rows = np.flatnonzero(out.max(1) > 0.02)
            cols = np.flatnonzero(out.max(0) > 0.02)
            assert abs((rows[0] + rows[-1] + 1) / 2 - R / 2) <= 1.0
            assert abs((cols[0] + cols[-1] + 1) / 2 - R / 2) <= 1.0
            long_side = max(rows[-1] - rows[0] + 1, cols[-1] - cols[0] + 1)
            assert -1.5 <= long_side - R * (1 - 2 * margin) <= 3  # + the filter's footprint


@needs_tree
def test_tree_frame_lines_are_cleaned():
    """Most tree files carry an opaque 1–3 px white frame along the canvas edge."""
    d = decode_image(TREE / "test" / "0.png")
    assert d.format == "PNG" and d.mode == "P" and d.has_alpha and d.bit_depth == 8
    alpha = d.pixels[..., 3] > 0
    assert alpha[0].all() and alpha[-1].all()          # the frame is in the file
    cleaned = clean_mask(alpha)
    assert not cleaned[0].any() and not cleaned[:, 0].any() and not cleaned[-1].any()
    assert cleaned.sum() > 0.95 * (alpha.sum() - 2 * (alpha.shape[0] + alpha.shape[1]) * 2)


# --------------------------------------------------------------------------------------------
# Crafted inputs
# --------------------------------------------------------------------------------------------


def test_rgba_png_exact_at_native_size(tmp_path):
    arr = np.zeros((10, 20, 4), np.uint8)
    arr[..., :3] = (0, 255, 0)             # garbage colour under alpha 0
    arr[:, :10] = (255, 0, 0, 255)          # opaque red
    arr[2, 3] = (128, 64, 32, 128)          # half transparent
    save(rgba(arr), tmp_path / "a.png")
    c = PhotoCollection(tmp_path, 20, "all", clean=False)
    x = c[0].numpy()
    assert x.shape == (4, 20, 20)
    top = (20 - 10) // 2                    # centred, padded with transparent rows
    assert np.all(x[:, :top] == 0) and np.all(x[:, top + 10:] == 0)
    body = x[:, top:top + 10]
    assert np.allclose(body[:, 0, 0], [1, 0, 0, 1], atol=1e-6)
    assert np.all(body[:, :, 10:] == 0)     # premultiplied: the green is gone
    a = 128 / 255
    assert np.allclose(body[:, 2, 3], [lin(128) * a, lin(64) * a, lin(32) * a, a], atol=1e-6)
    assert c.entries[0].mask == "alpha" and c.entries[0].size == (20, 10)


def test_palette_trns_and_grey_alpha(tmp_path):
    pal = Image.new("P", (4, 2))
    pal.putpalette([200, 100, 50, 10, 20, 30, 255, 255, 255])
    pal.putdata([0, 1, 2, 1, 1, 1, 0, 2])
    save(pal, tmp_path / "pal.png", transparency=bytes([255, 128, 0]))
    d = decode_image(tmp_path / "pal.png")
    assert d.mode == "P" and d.has_alpha
    assert d.pixels[0, :3, 3].tolist() == [255, 128, 0]
    assert d.pixels[0, 0, :3].tolist() == [200, 100, 50]

    la = Image.fromarray(np.array([[[90, 255], [90, 0]], [[200, 64], [10, 255]]], np.uint8), "LA")
    save(la, tmp_path / "la.png")
    d = decode_image(tmp_path / "la.png")
    assert d.pixels.shape == (2, 2, 4) and d.has_alpha
    assert d.pixels[1, 0].tolist() == [200, 200, 200, 64]

    grey = Image.fromarray(np.array([[10, 20], [30, 10]], np.uint8), "L")
    save(grey, tmp_path / "key.png", transparency=10)    # grey with a tRNS colour key
    d = decode_image(tmp_path / "key.png")
    assert d.has_alpha and d.pixels[..., 3].tolist() == [[0, 255], [255, 0]]

    c = PhotoCollection(tmp_path, 4, "all", clean=False)
    assert len(c) == 3
    by_name = {e.path.name: img for e, img in zip(c.entries, c.images())}
    p = by_name["pal.png"].numpy()          # 4 × 2 → padded to 4 × 4, rows 1..2
    assert np.allclose(p[:, 1, 0], [lin(200), lin(100), lin(50), 1.0], atol=1e-6)
    assert np.allclose(p[:, 1, 1], [lin(10) * 128 / 255, lin(20) * 128 / 255,
                                    lin(30) * 128 / 255, 128 / 255], atol=1e-6)
    assert np.all(p[:, 1, 2] == 0)


@pytest.mark.parametrize("colour_type,channels", [(2, 3), (6, 4), (0, 1), (4, 2)])
@pytest.mark.parametrize("interlace", [False, True])
def test_png16_keeps_all_16_bits(tmp_path, colour_type, channels, interlace):
    rng = np.random.default_rng(colour_type)
    arr = rng.integers(0, 65536, (11, 13, channels)).astype(np.uint16)
    arr[0, 0], arr[0, 1] = 30000, 30001     # one code apart
    if channels in (2, 4):
        arr[..., -1] = np.maximum(arr[..., -1], 1)
    path = tmp_path / "deep.png"
    path.write_bytes(png16(arr, colour_type, interlace=interlace))
    d = decode_image(path)
    assert d.bit_depth == 16 and d.pixels.dtype == np.uint16
    expect = {1: lambda a: np.concatenate([a, a, a, np.full_like(a, 65535)], 2),
              2: lambda a: np.concatenate([a[..., :1]] * 3 + [a[..., 1:]], 2),
              3: lambda a: np.concatenate([a, np.full_like(a[..., :1], 65535)], 2),
              4: lambda a: a}[channels](arr)
    assert np.array_equal(d.pixels, expect)
    f = d.rgba()
    assert f[0, 1, 0] - f[0, 0, 0] == pytest.approx(1 / 65535, rel=1e-9)
    assert d.has_alpha == (channels in (2, 4))


def test_png16_trns_key_and_linear_output(tmp_path):
    arr = np.full((4, 6, 3), 40000, np.uint16)
    arr[:, :3] = (1, 2, 3)                  # the key colour: transparent
    arr[1, 4] = (40000, 40001, 40002)
    (tmp_path / "key16.png").write_bytes(png16(arr, 2, trns=(1, 2, 3)))
    d = decode_image(tmp_path / "key16.png")
    assert d.has_alpha and d.pixels[..., 3].tolist() == [[0, 0, 0, 65535, 65535, 65535]] * 4
    c = PhotoCollection(tmp_path, 6, "all", clean=False)
    x = c[0].numpy()[:, 1:5]                # 6 × 4 → padded to 6 × 6, rows 1..4
    table = srgb_decoding_table(16)
    assert np.all(x[:, :, :3] == 0)
    assert x[0, 1, 4] == pytest.approx(lin(40000, 16), abs=1e-7)
    assert x[1, 1, 4] == pytest.approx(float(table[40001]), abs=1e-7)
    assert x[1, 1, 4] > x[0, 1, 4] and x[2, 1, 4] > x[1, 1, 4]   # 16 bits survive


def _on_white(shape=(48, 64), box=(12, 36, 16, 48), colour=(30, 60, 150)):
    arr = np.full(shape + (3,), 255, np.uint8)
    arr[box[0]:box[1], box[2]:box[3]] = colour
    return arr


def test_jpeg_on_white_threshold_masking(tmp_path):
    save(Image.fromarray(_on_white()), tmp_path / "photo.jpg", quality=95)
    c = PhotoCollection(tmp_path, 64, "all", background="white", threshold=0.1)
    x = c[0].numpy()
    assert c.entries[0].format == "JPEG" and c.entries[0].mask == "white"
    top = (64 - 48) // 2
    a = x[3, top:top + 48]
    assert a[24, 32] == pytest.approx(1.0) and a[0, 0] == 0 and a[-1, -1] == 0
    inside = np.argwhere(a > 0.5)
    assert inside.min(0).tolist() == [12, 16] and inside.max(0).tolist() == [35, 47]
    assert np.allclose(x[:3, top + 24, 32], [lin(30), lin(60), lin(150)], atol=0.02)
    assert (x[:3] <= x[3:] + 1e-6).all()
    # without background="white" a photo without alpha has no mask: a clear error
    with pytest.raises(ValueError, match="no_alpha"), pytest.warns(PhotoCollectionWarning,
                                                                   match="data.background: white"):
        PhotoCollection(tmp_path, 64, "all")


def test_rgb_png_on_white_mask_softened_cleaned(tmp_path):
    arr = _on_white(colour=(200, 100, 50))
    arr[2:6, 2:6] = 250                     # near white (within 0.05): background
    arr[44, 60] = 0                          # a one-pixel speck: dropped by cleaning
    save(Image.fromarray(arr), tmp_path / "white.png")
    c = PhotoCollection(tmp_path, 64, "all", background="white")
    top = 8
    x = c[0].numpy()[:, top:top + 48]
    a = x[3]
    assert a[3, 3] == 0 and a[44, 60] == 0
    assert np.all(a[13:35, 17:47] == 1)      # interior
    assert a[20, 16] == pytest.approx(6 / 9) and a[12, 16] == pytest.approx(4 / 9)  # rim
    assert np.all(a[20, :16] == 0) and np.all(a[:12, 20] == 0)
    # the rim colour is un-mixed from white: p = clip(c − (1 − α), 0, α)
    expect = np.clip(np.array([lin(200), lin(100), lin(50)]) - (1 - 6 / 9), 0, 6 / 9)
    assert np.allclose(x[:3, 20, 16], expect, atol=1e-6)
    assert np.allclose(x[:3, 20, 30], [lin(200), lin(100), lin(50)], atol=1e-6)
    hard = premultiplied_linear(decode_image(tmp_path / "white.png"), background="white",
                                soften=False)
    assert set(np.unique(hard[..., 3])) == {0.0, 1.0}
    keep = PhotoCollection(tmp_path, 64, "all", background="white", clean=False)[0]
    assert keep[3, top + 44, 60] > 0


def test_white_holes_and_real_alpha_wins(tmp_path):
    ring = _on_white(box=(10, 38, 10, 54), colour=(0, 0, 0))
    ring[18:30, 20:44] = 255                 # an enclosed white hole
    save(Image.fromarray(ring), tmp_path / "ring.png")
    a = PhotoCollection(tmp_path, 64, "all", background="white")[0][3].numpy()
    assert a[8 + 24, 32] == 0
    filled = PhotoCollection(tmp_path, 64, "all", background="white", fill_holes=True)[0]
    assert filled[3, 8 + 24, 32] == 1
    # a file with a real alpha channel uses it even with background="white"
    arr = np.full((8, 8, 4), 255, np.uint8)
    arr[:4, :, 3] = 0
    (tmp_path / "ring.png").unlink()
    save(rgba(arr), tmp_path / "white_rgba.png")
    x = PhotoCollection(tmp_path, 8, "all", background="white", clean=False)[0]
    assert torch.all(x[3, :4] == 0) and torch.all(x[:, 4:] == 1)


def test_premultiplied_resampling_has_no_halo(tmp_path):
    """Transparent pixels' colour must not bleed into the edges when downsampling."""
    for name, under in (("black", 0), ("white", 255)):
        arr = np.zeros((90, 90, 4), np.uint8)
        arr[..., :3] = under
        yy, xx = np.indices((90, 90))
        disc = (yy - 44.5) ** 2 + (xx - 44.5) ** 2 < 30 ** 2
        arr[disc] = (128, 128, 128, 255)
        save(rgba(arr), tmp_path / name / "disc.png")
    results = []
    for name in ("black", "white"):
        x = PhotoCollection(tmp_path / name, 16, "all")[0].numpy()
        assert x.min() >= 0 and x[3].max() <= 1 and (x[:3] <= x[3:] + 1e-6).all()
        edge = x[3] > 0.05
        unpremult = x[:3][:, edge] / x[3][edge]
        assert np.allclose(unpremult, lin(128), atol=1e-3)
        results.append(x)
    assert np.array_equal(results[0], results[1])   # black vs white under alpha 0


def test_aspect_ratio_crop_and_margin(tmp_path):
    arr = np.zeros((60, 100, 4), np.uint8)
    arr[10:20, 50:90] = 255                  # a 40 × 10 opaque bar
    save(rgba(arr), tmp_path / "bar.png")
    x = PhotoCollection(tmp_path, 32, "all", crop="bbox")[0][3].numpy()
    rows, cols = np.flatnonzero(x.max(1) > 0.5), np.flatnonzero(x.max(0) > 0.5)
    assert (cols[0], cols[-1]) == (0, 31) and (rows[0], rows[-1]) == (12, 19)   # 32 × 8
    x = PhotoCollection(tmp_path, 50, "all", crop="bbox", margin=0.1)[0][3].numpy()
    cols, rows = np.flatnonzero(x.max(0) > 0.5), np.flatnonzero(x.max(1) > 0.5)
    assert (cols[0], cols[-1]) == (5, 44) and (rows[0], rows[-1]) == (20, 29)   # 40 × 10
    x = PhotoCollection(tmp_path, 50, "all")[0][3].numpy()    # photo framing: 100 × 60 → 50 × 30
    cols, rows = np.flatnonzero(x.max(0) > 0.5), np.flatnonzero(x.max(1) > 0.5)
    assert (cols[0], cols[-1]) == (25, 44) and (rows[0], rows[-1]) == (15, 19)


def test_exif_orientation_is_applied(tmp_path):
    arr = np.zeros((10, 20, 4), np.uint8)
    arr[:, :5] = 255                         # opaque on the left
    exif = Image.Exif()
    exif[0x0112] = 6                         # rotate 90° clockwise for display
    save(rgba(arr), tmp_path / "o.png", exif=exif)
    d = decode_image(tmp_path / "o.png")
    assert d.pixels.shape == (20, 10, 4)
    assert d.pixels[:5, :, 3].min() == 255 and d.pixels[5:, :, 3].max() == 0   # now on top


# --------------------------------------------------------------------------------------------
# Bad input
# --------------------------------------------------------------------------------------------


def _png_bytes(img: Image.Image) -> bytes:
    buf = io.BytesIO()
    img.save(buf, format="PNG")
    return buf.getvalue()


def test_bad_files_are_reported_and_good_ones_load(tmp_path):
    good = blob(1, (200, 150))
    save(good, tmp_path / "good.png")
    save(good, tmp_path / "z" / "same.png")                           # duplicate
    big = _png_bytes(Image.fromarray(
        np.random.default_rng(0).integers(0, 256, (120, 160, 4), dtype=np.uint8), "RGBA"))
    (tmp_path / "truncated.png").write_bytes(big[: len(big) // 2])
    (tmp_path / "random.png").write_bytes(np.random.default_rng(1).bytes(3000))
    (tmp_path / "notes.txt").write_text("not a photo\n")
    (tmp_path / "meta.json").write_text('{"class": "tree"}')
    save(rgba(np.zeros((8, 8, 4), np.uint8)), tmp_path / "clear.png")  # alpha 0 everywhere
    save(Image.new("RGB", (8, 8), (255, 0, 0)), tmp_path / "anim.gif")
    save(Image.new("RGB", (8, 8), (255, 0, 0)), tmp_path / "scan.tiff")
    save(Image.new("RGB", (8, 8), (255, 0, 0)), tmp_path / "opaque.jpg")
    (tmp_path / ".DS_Store").write_bytes(b"\0\1")
    expected = {"truncated.png": "corrupt", "random.png": "corrupt",
                "notes.txt": "not_an_image", "meta.json": "not_an_image",
                "clear.png": "fully_transparent", "anim.gif": "unsupported_format",
                "scan.tiff": "unsupported_format", "opaque.jpg": "no_alpha"}
    with pytest.warns(PhotoCollectionWarning) as record:
        c = PhotoCollection(tmp_path, 16, "all")
    messages = [str(w.message) for w in record if issubclass(w.category, PhotoCollectionWarning)]
    for name, reason in expected.items():
        hits = [m for m in messages if name in m]
        assert len(hits) == 1 and reason in hits[0], (name, messages)
    rep = c.report
    assert {s.path.name: s.reason for s in rep.skipped} == expected
    assert all(s.path.name in s.message for s in rep.skipped)
    assert rep.skipped_by_reason == {"corrupt": 2, "not_an_image": 2, "fully_transparent": 1,
                                     "unsupported_format": 2, "no_alpha": 1}
    assert rep.files_found == 10 and rep.duplicates == 1 and rep.usable == 1
    assert [p.name for p in rep.ignored] == [".DS_Store"]
    assert c.files == [tmp_path.resolve() / "good.png"]   # the smaller relative path is kept
    assert rep.duplicate_groups == {tmp_path.resolve() / "good.png":
                                    [tmp_path.resolve() / "z" / "same.png"]}
    assert "truncated.png" in str(rep) and "corrupt" in str(rep)


def test_empty_missing_and_all_bad_folders(tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(ValueError, match="folder is empty") as err:
        PhotoCollection(empty)
    assert str(empty) in str(err.value)
    (empty / ".hidden").write_text("x")
    with pytest.raises(ValueError, match="hidden"):
        PhotoCollection(empty)
    with pytest.raises(FileNotFoundError, match="nowhere"):
        PhotoCollection(tmp_path / "nowhere")
    (tmp_path / "file.png").write_bytes(b"x")
    with pytest.raises(NotADirectoryError):
        PhotoCollection(tmp_path / "file.png")
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "notes.txt").write_text("hello")
    (bad / "broken.png").write_bytes(b"\x89PNG\r\n\x1a\n" + b"\0" * 20)
    with pytest.warns(PhotoCollectionWarning), \
            pytest.raises(ValueError, match="bad") as err:
        PhotoCollection(bad)
    text = str(err.value)
    assert str(bad) in text and "notes.txt" in text and "broken.png" in text
    assert "not_an_image" in text and "corrupt" in text


# --------------------------------------------------------------------------------------------
# Splits and options
# --------------------------------------------------------------------------------------------


def test_splits_ignore_names_and_listing_order(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    for i in range(12):
        save(blob(i), a / f"img_{i:02d}.png")
        save(blob(i), b / f"sub{i % 3}" / f"{99 - i}.png")        # other names and folders
    sa = PhotoCollection.load_splits(a, 8)
    sb = PhotoCollection.load_splits(b, 8)
    for split in ("train", "val", "test", "all"):
        assert sa[split].hashes == sb[split].hashes
        assert all(torch.equal(x, y) for x, y in zip(sa[split], sb[split]))
    assert [len(sa[k]) for k in ("train", "val", "test")] == [10, 1, 1]
    other = PhotoCollection.load_splits(a, 8, seed=1)
    assert any(other[k].hashes != sa[k].hashes for k in ("train", "val", "test"))
    assert sorted(other["all"].hashes) == sorted(sa["all"].hashes)
    halves = PhotoCollection.load_splits(a, 8, splits=(0.5, 0.5, 0.0))
    assert [len(halves[k]) for k in ("train", "val", "test")] == [6, 6, 0]
    loader = torch.utils.data.DataLoader(sa["train"], batch_size=4, shuffle=True)
    assert next(iter(loader)).shape == (4, 4, 8, 8)


def test_split_counts():
    assert split_counts(32, (0.8, 0.1, 0.1)) == (26, 3, 3)
    assert split_counts(5, (0.8, 0.1, 0.1)) == (3, 1, 1)
    assert split_counts(2, (0.8, 0.1, 0.1)) == (2, 0, 0)
    assert split_counts(7, (1.0, 0.0, 0.0)) == (7, 0, 0)
    for n in range(40):
        assert sum(split_counts(n, (0.7, 0.2, 0.1))) == n


@pytest.mark.parametrize("kwargs", [
    dict(resolution=0), dict(margin=0.5), dict(background="black"), dict(splits=(0.5, 0.2, 0.2)),
    dict(split="holdout"), dict(crop="centre"), dict(threshold=1.0), dict(erode=-1),
    dict(erode=1.5), dict(margin=-0.1), dict(seed=True)])
def test_invalid_options(tmp_path, kwargs):
    save(blob(0), tmp_path / "x.png")
    with pytest.raises(ValueError):
        PhotoCollection(tmp_path, **kwargs)


def test_decode_rejections_name_the_file(tmp_path):
    from mitsuba_platonic.data.photos import ImageRejected

    (tmp_path / "empty.png").write_bytes(b"")
    with pytest.raises(ImageRejected, match="empty.png") as err:
        decode_image(tmp_path / "empty.png")
    assert err.value.reason == "corrupt"
    gif = io.BytesIO()
    Image.new("P", (4, 4)).save(gif, format="GIF")
    with pytest.raises(ImageRejected, match="GIF") as err:
        decode_image(gif.getvalue(), name="thing.png")    # by content, not by name
    assert err.value.reason == "unsupported_format"


# --------------------------------------------------------------------------------------------
# 16-bit PNGs (pypng), EXIF orientation
# --------------------------------------------------------------------------------------------


def _exif_bytes(orientation: int) -> bytes:
    """Raw EXIF (TIFF) bytes with an orientation tag, as a PNG eXIf chunk stores them."""
    exif = Image.Exif()
    exif[0x0112] = orientation
    data = exif.tobytes()
    return data[6:] if data.startswith(b"Exif\0\0") else data


@pytest.mark.parametrize("orientation", range(1, 9))
def test_exif_orientation_8_and_16_bit_match_pillow(tmp_path, orientation):
    rng = np.random.default_rng(orientation)
    arr = rng.integers(1, 256, (3, 5, 4)).astype(np.uint8)       # asymmetric: every flip shows
    exif = Image.Exif()
    exif[0x0112] = orientation
    save(rgba(arr), tmp_path / "o8.png", exif=exif)
    from PIL import ImageOps

    expect = np.asarray(ImageOps.exif_transpose(Image.open(tmp_path / "o8.png")).convert("RGBA"))
    d8 = decode_image(tmp_path / "o8.png")
    assert np.array_equal(d8.pixels, expect)
    (tmp_path / "o16.png").write_bytes(png16(arr.astype(np.uint16) * 257, 6,
                                             exif=_exif_bytes(orientation)))
    d16 = decode_image(tmp_path / "o16.png")
    assert d16.bit_depth == 16 and np.array_equal(d16.pixels, expect.astype(np.uint16) * 257)


def test_png16_grey_key_and_corrupt_data(tmp_path):
    arr = np.array([[1000, 1001], [65535, 1000]], np.uint16)
    (tmp_path / "g.png").write_bytes(png16(arr, 0, trns=(1000,)))
    d = decode_image(tmp_path / "g.png")
    assert d.has_alpha and d.mode == "I;16" and d.bit_depth == 16
    assert d.pixels[..., 3].tolist() == [[0, 65535], [65535, 0]]
    assert d.pixels[0, 1, :3].tolist() == [1001] * 3
    data = bytearray(png16(np.full((8, 8, 3), 40000, np.uint16), 2))
    idat = data.index(b"IDAT")
    data[idat + 6] ^= 0xFF                       # a flipped byte in the compressed data
    with pytest.raises(ImageRejected, match="bad.png") as err:
        decode_image(bytes(data), name="bad.png")
    assert err.value.reason == "corrupt"
    with pytest.raises(ImageRejected) as err:   # truncated inside IDAT
        decode_image(bytes(data[:idat + 20]), name="short.png")
    assert err.value.reason == "corrupt"


# --------------------------------------------------------------------------------------------
# sRGB: one owner (mitsuba_platonic.images), colour-science's curve bit for bit
# --------------------------------------------------------------------------------------------


def test_srgb_curves_are_colour_sciences_bit_for_bit_and_have_one_owner():
    """images.srgb_to_linear / linear_to_srgb compute colour-science's sRGB curves in numpy (the
    package no longer imports colour-science, about 2 s with its matplotlib, to decode a photo):
    every 16-bit code and dense samples about both knees equal ``cctf_decoding`` / ``cctf_encoding``
    exactly; the photo decoding table and the shapes' colours are that one decoder's values."""
    import colour

    from mitsuba_platonic import images
    from mitsuba_platonic.data.shapes.colour import hsv

    codes = np.arange(1 << 16, dtype=np.float64) / ((1 << 16) - 1)
    x = np.concatenate([codes, np.linspace(0.0403, 0.0406, 20001), np.linspace(0.0030, 0.0032, 20001),
                        [0.040449936, 0.0031308, -0.5, 1.5]])
    clipped = np.clip(x, 0.0, 1.0)
    assert np.array_equal(images.srgb_to_linear(x), np.asarray(colour.cctf_decoding(clipped, "sRGB")))
    assert np.array_equal(images.linear_to_srgb(x), np.asarray(colour.cctf_encoding(clipped, "sRGB")))
    srgb_decoding_table.cache_clear()
    assert np.array_equal(srgb_decoding_table(16), np.clip(images.srgb_to_linear(codes), 0, 1).astype(np.float32))
    assert hsv(0.0, 0.0, 0.5) == (float(images.srgb_to_linear(0.5)),) * 3            # grey 0.5
    assert srgb_decoding_table(8)[51] == pytest.approx(lin(51), abs=1e-7)


# --------------------------------------------------------------------------------------------
# Options: every PhotoCollection option is reachable from the config
# --------------------------------------------------------------------------------------------


def test_every_collection_option_is_in_the_data_config(tmp_path):
    import inspect

    from mitsuba_platonic.config import ConfigError, load_config

    options = {name for name, p in inspect.signature(PhotoCollection).parameters.items()
               if p.kind is p.KEYWORD_ONLY}
    cfg = load_config(None, ["data.source=folder", f"data.path={tmp_path}", "data.margin=0.1",
                             "data.clean=false", "data.fill_holes=true", "data.erode=2",
                             "data.split=0.6"])
    kwargs = cfg.data.photo_options()
    # alpha_only follows the renderer's image formation (render.model), not a data key
    assert options == set(kwargs) | {"alpha_only"}
    assert kwargs["margin"] == 0.1 and kwargs["clean"] is False and kwargs["erode"] == 2
    assert kwargs["fill_holes"] is True and kwargs["splits"] == pytest.approx((0.6, 0.2, 0.2))
    for bad in ("data.margin=0.5", "data.erode=-1", "data.threshold=1.0", "data.clean=2"):
        with pytest.raises(ConfigError, match=bad.split("=")[0]):
            load_config(None, ["data.source=folder", f"data.path={tmp_path}", bad])
    save(blob(3), tmp_path / "x.png")
    c = PhotoCollection(tmp_path, 8, "all", **cfg.data.photo_options())
    assert c.options.margin == 0.1 and c.options.erode == 2 and not c.options.clean


@pytest.mark.parametrize("removed", [dict(filter="lanczos"), dict(regions="largest"),
                                     dict(soften=False), dict(workers=1)])
def test_removed_options_are_refused(tmp_path, removed):
    save(blob(0), tmp_path / "x.png")
    with pytest.raises(TypeError):
        PhotoCollection(tmp_path, 8, "all", **removed)


def _on(colour, border, name, folder):
    """A JPEG photo of a ``colour`` box on a ``border``-coloured background."""
    arr = np.full((48, 64, 3), border, np.uint8)
    arr[12:36, 16:48] = colour
    save(Image.fromarray(arr), folder / name, quality=95)


def test_photos_without_transparency_are_named_and_a_background_that_is_not_white_is_told(tmp_path):
    """``data.background: white`` on photos on black (JPEGs, and PNGs whose alpha is opaque everywhere)
    trained without a word, every mask the whole frame: one warning names the photos without
    transparency (counts and examples) and those whose border is not white."""
    for i in range(5):
        _on((200, 80 + 20 * i, 40), 0, f"black_{i}.jpg", tmp_path)          # distinct: no duplicates
    _on((30, 60, 150), 255, "white_0.jpg", tmp_path)
    opaque = np.zeros((48, 64, 4), np.uint8)
    opaque[..., 3] = 255
    opaque[12:36, 16:48, :3] = 90
    save(rgba(opaque), tmp_path / "opaque.png")
    cut = np.zeros((48, 64, 4), np.uint8)
    cut[12:36, 16:48] = (90, 90, 90, 255)
    save(rgba(cut), tmp_path / "cut_out.png")                       # real transparency: not named
    with pytest.warns(PhotoCollectionWarning) as caught:
        c = PhotoCollection(tmp_path, 16, "all", background="white")
    lines = [str(w.message) for w in caught]
    assert len(lines) == 1, lines
    line = lines[0]
    assert line.startswith("7 of 8 usable photo(s) have no transparency and were masked as photos on a white "
                           "background (data.background: white): black_0.jpg, black_1.jpg, black_2.jpg and 4 more; "
                           "but 6 of them do not show a white background around the object (6 on black: black_0.jpg, "
                           "black_1.jpg, black_2.jpg and 3 more)"), line
    assert "white_0.jpg" not in line.split("; but")[1] and "cut_out.png" not in line
    assert len(c) == 8
    assert border_background(np.full((4, 4, 3), 250, np.uint8), 255) == "white"
    assert border_background(np.full((4, 4, 3), 5, np.uint8), 255) == "black"
    assert border_background(np.full((4, 4, 3), 128, np.uint8), 255) == "other"
