"""3D truth for photo runs (evaluate/photo_truth.py): the loader's framing, the truth brought into the
photo's frame, the turntable about the object's true axis, and the scores end to end."""

import json
import math

import numpy as np
import pytest
import torch

from mitsuba_platonic.config import load_config
from mitsuba_platonic.data.render_collection import CollectionSpec, make_collection
from mitsuba_platonic.data.photos import decode_image
from mitsuba_platonic.data.photos.frame import frame_and_resample, framing
from mitsuba_platonic.data.photos.prepare import photo_framing
from mitsuba_platonic.evaluate.metrics import volume_iou
from mitsuba_platonic.evaluate.photo_truth import (framed_truth, score_against_truth, silhouette_widths, thickness,
                                                  turntable_in_camera, view_scores, width_ratio)
from mitsuba_platonic.evaluate.photos import photo_splits
from mitsuba_platonic.evaluate.protocol import billboard
from mitsuba_platonic.render import render
from mitsuba_platonic.views import from_angles, front_view
from mitsuba_platonic.volume import voxel_centres


def _sphere(n, centre, radius, density=1.0, colour=(0.8, 0.3, 0.2)):
    """An anti-aliased sphere (opacity ``density`` inside, a one-voxel ramp) as a (4, N, N, N) volume."""
    d = (voxel_centres(n) - torch.tensor(centre, dtype=torch.float64)).norm(dim=-1)
    a = ((radius - d) / (2.0 / n) + 0.5).clamp(0.0, 1.0) * density
    rgb = torch.tensor(colour, dtype=torch.float64)[:, None, None, None].expand(3, n, n, n)
    return torch.cat([rgb, a[None]]).float()


def _centroid(density):
    w = density.double()
    return (voxel_centres(density.shape[-1]) * w[..., None]).sum((0, 1, 2)) / w.sum()


def test_framing_square_says_where_frame_and_resample_puts_a_pixel():
    image = np.zeros((30, 40, 4), np.float32)
    image[5:15, 10:30, 3] = 1.0                                  # the object: rows 5-14, columns 10-29
    image[8, 14, 0] = 1.0                                        # one red pixel inside it
    f = framing(image[..., 3], "bbox", 0.1)
    assert (f.row, f.col, f.height, f.width) == (5, 10, 10, 20)
    assert f.side == 25 and (f.top, f.left) == (7, 2)
    r = 50
    out = frame_and_resample(image, r, crop="bbox", margin=0.1)
    red = torch.from_numpy(out[0]).double()
    m = torch.arange(r, dtype=torch.float64) + 0.5
    row_at, col_at = float((red.sum(1) * m).sum() / red.sum()), float((red.sum(0) * m).sum() / red.sum())
    row_c, col_c, side = f.square()
    assert row_at == pytest.approx(((8 + 0.5 - row_c) / side + 0.5) * r, abs=1e-3)
    assert col_at == pytest.approx(((14 + 0.5 - col_c) / side + 0.5) * r, abs=1e-3)


def _photo_of(truth, view, margin=0.1):
    photo = render(truth[None], view[None], "ea")[0]
    alpha = photo[3].numpy()
    return photo, framing(alpha, "bbox", margin).square()


def test_framed_truth_of_an_off_centre_sphere_fills_the_square_centred_at_the_matched_depth():
    view = from_angles(30.0, 20.0)
    truth = _sphere(64, (0.2, -0.1, 0.3), 0.4)
    _, square = _photo_of(truth, view)
    side = square[2]
    # the bounding box of α > 0 spans the diameter, 25.6 pixels, and at most two pixels of soft edge;
    # margin 0.1 pads it to a square 1 / 0.8 times as wide
    assert math.ceil(25.6 / 0.8) <= side <= math.ceil(29.6 / 0.8)
    rec = _sphere(32, (0.0, 0.0, 0.25), 0.5)                      # any volume: it sets the depth only
    t = framed_truth(truth, view.tolist(), square, 64, rec)
    occupied = float((t[3] >= 0.5).sum()) * (2.0 / 32) ** 3
    radius = (3.0 * occupied / (4.0 * math.pi)) ** (1.0 / 3.0)
    assert radius == pytest.approx(0.4 * 64 / side, abs=0.03)     # the square spans [-1, 1]: scale 64 / side
    cx, cy, cz = _centroid(t[3]).tolist()
    assert abs(cx) < 2.0 / 32 and abs(cy) < 2.0 / 32                 # centred by the crop, to a voxel
    assert cz == pytest.approx(float(_centroid(rec[3])[2]), abs=0.01)


def test_framed_truth_keeps_the_opacity_of_a_ray_through_a_hazy_sphere():
    view = from_angles(-50.0, 10.0)
    truth = _sphere(64, (0.1, 0.2, -0.2), 0.4, density=0.05)
    _, square = _photo_of(truth, view)
    t = framed_truth(truth, view.tolist(), square, 64, _sphere(32, (0.0, 0.0, 0.0), 0.5))
    front = render(t[None], front_view(1), "ea")[0, 3]
    # the centre ray crosses a chord of 0.8 world units, 25.6 of the truth's voxels of opacity 0.05
    assert float(front.max()) == pytest.approx(1.0 - 0.95 ** 25.6, abs=0.03)


def test_turntable_in_camera_turns_about_the_objects_axis():
    θ = 30.0
    views = turntable_in_camera(θ, [0.0, 90.0, -90.0, 180.0, 45.0])
    assert views[0].tolist() == pytest.approx([0.0, 0.0, 1.0], abs=1e-6)
    c, s = math.cos(math.radians(θ)), math.sin(math.radians(θ))
    assert views[1].tolist() == pytest.approx([c, s * c, s * s], abs=1e-6)
    up = torch.tensor([0.0, c, s])                                  # the object's vertical axis, camera frame
    assert (views @ up).tolist() == pytest.approx([s] * 5, abs=1e-6)
    flat = turntable_in_camera(0.0, [20.0, 110.0])
    assert torch.allclose(flat, from_angles(torch.tensor([20.0, 110.0]), torch.zeros(2)), atol=1e-6)


class _Fixed:
    """A stand-in model whose reconstructions are given."""

    def __init__(self, volumes):
        self.volumes = volumes

    def reconstruct(self, photos):
        assert len(photos) == len(self.volumes)
        return torch.stack(self.volumes)


def test_scores_end_to_end_the_truth_scores_one_and_a_billboard_only_from_the_front(tmp_path):
    spec = CollectionSpec("mushroom", n_shapes=10, views_per_shape=1, resolution=32, formation="ea",
                          views="band", elevation=(0.0, 40.0), seed=3)
    make_collection(tmp_path / "c", spec, progress=False)
    cfg = load_config("photos", [f"data.path={tmp_path / 'c' / 'images'}", "model.resolution=16"])
    _, photos, files = photo_splits(cfg)
    records = {r["image"]: r for r in json.loads((tmp_path / "c" / "manifest.json").read_text())["images"]}
    truths = []
    for f in files:
        rec = records[f"images/{f.name}"]
        decoded = decode_image(f)
        square = photo_framing(decoded, **cfg.data.image_kwargs()).square()
        truth = torch.from_numpy(np.load(tmp_path / "c" / rec["volume"])["volume"]).float()
        truths.append(framed_truth(truth, rec["view"], square, decoded.size[0], torch.zeros(4, 16, 16, 16)))
    exact = score_against_truth(_Fixed(truths), cfg)
    assert [str(f) for f in files] == exact.files
    means = exact.means()
    # the truth framed once more for scoring is matched in depth to itself framed at depth 0: the same
    # volume up to the resampling of that small shift (a file paired with another's truth scores far lower)
    assert min(means["truth_front_iou"], means["truth_side_iou"], means["truth_back_iou"]) > 0.95
    assert means["truth_volume_iou"] > 0.9 and means["truth_side_mae"] < 0.01
    # the width ratio at ±90°: the truth's own, the reconstruction's (the truth once more) within a pixel's
    # rounding of it; each photo's error is the size of the two's difference
    assert exact.width_ratio_error == pytest.approx([abs(a - b) for a, b in zip(exact.width_ratio,
                                                                                exact.width_ratio_truth)])
    assert means["truth_width_ratio_error"] < 0.1
    # the billboard (the photo drawn through the cube's depth) is the truth from the photo's own view, which
    # holds only where the truth was framed as the loader framed the photo; from the side it is a prism
    billboards = score_against_truth(_Fixed([billboard(p) for p in photos]), cfg).means()
    assert billboards["truth_front_iou"] > 0.9
    assert billboards["truth_side_iou"] < 0.6 and billboards["truth_volume_iou"] < 0.5
    # the billboard reaches through the cube's whole depth: wide from the side whatever the mushroom's ratio
    assert billboards["truth_width_ratio"] > means["truth_width_ratio"] + 0.3
    assert billboards["truth_width_ratio_truth"] == pytest.approx(exact.means()["truth_width_ratio_truth"])


def test_score_against_truth_needs_a_rendered_collection(tmp_path):
    from PIL import Image
    from mitsuba_platonic.errors import UserError

    for i in range(6):
        a = np.zeros((20, 20, 4), np.uint8)
        a[4 + i % 3:15, 5:14] = (200, 50 + 20 * i, 30, 255)
        Image.fromarray(a).save(tmp_path / f"{i}.png")
    cfg = load_config("photos", [f"data.path={tmp_path}", "model.resolution=16"])
    with pytest.raises(UserError, match="manifest.json"):
        score_against_truth(_Fixed([]), cfg)


def test_thickness_is_one_for_the_truth_and_the_share_of_a_shell_that_fills_the_photo():
    n = 32
    ball = _sphere(n, (0.0, 0.0, 0.0), 0.6)
    ball[3] = (ball[3] >= 0.5).float()                          # opaque or empty: nothing shows behind a voxel
    assert thickness(ball, ball) == pytest.approx(1.0)
    # the ball's front shell, 3 voxels deep behind its surface along each input ray (dim 1: depth)
    solid = ball[3] >= 0.5
    first = solid.double().cumsum(0)
    shell = ball.clone()
    shell[3] = torch.where(first <= 3, ball[3], torch.zeros(()))
    per_ray = solid.sum(0)
    covered = (1.0 - torch.prod(1.0 - ball[3].double(), dim=0)) >= 0.5
    expected = float(per_ray.clamp(max=3)[covered].sum() / per_ray[covered].sum())
    assert thickness(shell, ball) == pytest.approx(expected)
    assert thickness(shell, ball) < 0.4                          # a ball 19 voxels across, a shell of 3
    # its EA render from the input view is the ball's own: the photo cannot tell them apart
    front = front_view(1)
    a, b = render(shell[None], front, "ea")[0, 3], render(ball[None], front, "ea")[0, 3]
    assert torch.allclose(a, b, atol=1e-6)
    assert math.isnan(thickness(ball, torch.zeros_like(ball)))
    with pytest.raises(ValueError, match="one shape"):
        thickness(ball, ball[:, :16])


def test_the_oblique_score_tells_a_four_armed_cross_from_the_cylinder_that_the_side_cannot():
    # a vertical cylinder of radius r and a cross of two slabs whose arms reach r: the same silhouette at 0°
    # and at ±90° (a quarter turn leaves the cross unchanged), its arms foreshortened at ±45°
    n, r, w, h = 32, 0.6, 0.1, 0.7
    c = voxel_centres(n)
    x, y, z = c[..., 0].abs(), c[..., 1].abs(), c[..., 2].abs()
    upright = y <= h
    cylinder = upright & (c[..., 0] ** 2 + c[..., 2] ** 2 <= r * r)
    cross = upright & (((x <= r) & (z <= w)) | ((z <= r) & (x <= w)))

    def volume(solid):
        rgb = torch.tensor([0.3, 0.6, 0.2], dtype=torch.float64)[:, None, None, None].expand(3, n, n, n)
        return torch.cat([rgb, solid.double()[None]]).float()

    truth, star = volume(cylinder), volume(cross)
    assert view_scores(truth, truth, 0.0)["oblique_iou"] == pytest.approx(1.0)
    scores = view_scores(star, truth, 0.0)
    assert scores["front_iou"] > 0.95 and scores["side_iou"] > 0.95
    # seen at 45° an arm spans u = (x ∓ z)/√2 up to (r + w)/√2 from the axis, inside the cylinder's r: the
    # IoU is at most the ratio of the widths (0.825), give or take a voxel's soft edge on each side
    assert scores["oblique_iou"] <= (r + w) / (math.sqrt(2.0) * r) + 2.0 / n
    assert scores["oblique_iou"] < scores["side_iou"] - 0.15


def _solid(mask, colour=(0.7, 0.5, 0.3)):
    n = mask.shape[-1]
    rgb = torch.tensor(colour, dtype=torch.float64)[:, None, None, None].expand(3, n, n, n)
    return torch.cat([rgb, mask.double()[None]]).float()


def test_width_ratio_of_a_box_is_its_depth_over_its_width_exactly_and_of_a_cylinder_one():
    n = 32
    c = voxel_centres(n)
    x, y, z = c[..., 0].abs(), c[..., 1].abs(), c[..., 2].abs()
    # a box on whole voxels: 20 voxels across (x, the photo's width), 8 deep (z, along the photo's rays)
    box = _solid((x < 20 / n) & (y < 12 / n) & (z < 8 / n))
    front, side, other = silhouette_widths(box, turntable_in_camera(0.0, [0.0, 90.0, -90.0]), (0.0, 1.0, 0.0))
    assert (front, side, other) == (pytest.approx(40 / n), pytest.approx(16 / n), pytest.approx(16 / n))
    assert width_ratio(box, 0.0) == 8 / 20
    cylinder = _solid((c[..., 0] ** 2 + c[..., 2] ** 2 <= 0.5 ** 2) & (y < 0.6))
    assert width_ratio(cylinder, 0.0) == pytest.approx(1.0)
    assert math.isnan(width_ratio(torch.zeros(4, n, n, n), 0.0))


def test_width_ratio_follows_the_objects_axis_at_an_elevation():
    """Seen from θ = 30°, the turntable's images at ±90° are rolled about ω; the width across the object's
    own vertical still gives a tilted cylinder 1 and a tilted box its depth over its width, to 2.5 pixels
    (measured: 2 wider at ±90°, the tilted voxels' staircase and the bins' offset; exact at 0°)."""
    n, θ = 48, 30.0
    s, co = math.sin(math.radians(θ)), math.cos(math.radians(θ))
    c = voxel_centres(n).to(torch.float64)
    # the object's axes in the input camera's frame: across x, vertical u, depth d (module docstring)
    u, d = torch.tensor([0.0, co, s], dtype=torch.float64), torch.tensor([0.0, -s, co], dtype=torch.float64)
    a, h, w = c[..., 0], c @ u, c @ d
    cylinder = _solid((a ** 2 + w ** 2 <= 0.45 ** 2) & (h.abs() <= 0.4))
    pixel = 2.0 / n
    assert width_ratio(cylinder, θ) == pytest.approx(1.0, abs=2.5 * pixel / 0.9)          # 0.9 across
    box = _solid((a.abs() <= 0.6) & (h.abs() <= 0.3) & (w.abs() <= 0.25))
    assert width_ratio(box, θ) == pytest.approx(0.25 / 0.6, abs=2.5 * pixel / 1.2)         # 1.2 across
    # the column count alone, which the roll mixes with the height, does not
    alpha = render(box[None].expand(3, -1, -1, -1, -1).contiguous(), turntable_in_camera(θ, [0.0, 90.0, -90.0]),
                   "ea")[:, 3]
    columns = (alpha >= 0.5).any(dim=1).sum(dim=1).double()
    assert float(columns[1:].mean() / columns[0]) > 0.25 / 0.6 + 0.1


def test_silhouette_widths_refuses_a_view_along_the_axis_and_bad_inputs():
    box = _solid(voxel_centres(16)[..., 0].abs() < 0.5)
    with pytest.raises(ValueError, match="along the axis"):
        silhouette_widths(box, from_angles(0.0, 90.0)[None], (0.0, 1.0, 0.0))
    with pytest.raises(ValueError, match=r"\(4, R, R, R\)"):
        silhouette_widths(box[3], front_view(1), (0.0, 1.0, 0.0))
    with pytest.raises(ValueError, match="non-zero 3-vector"):
        silhouette_widths(box, front_view(1), (0.0, 0.0, 0.0))
