"""Procedural shape classes: registry API, volume validity, variation, placement, SDF helpers."""

import math

import numpy as np
import pytest
import torch

from mitsuba_platonic.data import shapes
from mitsuba_platonic.data.shapes import sdf as S
from mitsuba_platonic.volume import validate_volume, voxel_centres, voxel_size

BUILTIN = ["airplane", "animal", "chair", "lathe", "mushroom", "tree"]
SEEDS = (0, 1, 2)


@pytest.fixture(scope="module")
def volumes():
    """Cache: (name, seed, n) → volume, so each is generated once per test session."""
    cache = {}

    def get(name, seed, n):
        key = (name, seed, n)
        if key not in cache:
            cache[key] = shapes.generate(name, seed, n)
        return cache[key]
    return get


def _centroid(density, n):
    p = voxel_centres(n).to(torch.float32)
    return (density[..., None] * p).sum((0, 1, 2)) / density.sum()


def test_builtin_classes_are_registered():
    assert set(BUILTIN) <= set(shapes.list_classes())
    assert shapes.list_classes() == sorted(shapes.list_classes())
    for name in BUILTIN:
        assert callable(shapes.get_class(name))


@pytest.mark.parametrize("n", [16, 64])
@pytest.mark.parametrize("name", BUILTIN)
def test_volume_is_valid_and_nontrivial(volumes, name, n):
    for seed in SEEDS:
        v = volumes(name, seed, n)
        assert v.shape == (4, n, n, n) and v.dtype == torch.float32 and v.is_contiguous()
        assert float(v.min()) >= 0.0 and float(v.max()) <= 1.0 and torch.isfinite(v).all()
        validate_volume(v[None], "ea")
        occ = float((v[3] > 0.5).float().mean())
        assert 0.003 < occ < 0.5, f"{name} seed {seed} n={n}: occupancy {occ:.4f}"
        # colours of the occupied voxels: not black, not all one colour
        rgb = v[:3][:, v[3] > 0.5]
        assert float(rgb.max(dim=0).values.mean()) > 0.15
        assert float(rgb.std(dim=1).max()) > 0.01 or name == "lathe"


@pytest.mark.parametrize("n", [16, 64])
@pytest.mark.parametrize("name", BUILTIN)
def test_inside_the_unit_ball_and_centred(volumes, name, n):
    r = voxel_centres(n).norm(dim=-1)
    for seed in SEEDS:
        d = volumes(name, seed, n)[3]
        assert float(d[r > 0.97].max()) < 0.05
        c = _centroid(d, n)
        assert abs(float(c[0])) < 0.25 and abs(float(c[2])) < 0.25, f"{name} seed {seed}: centroid {c.tolist()}"
        assert abs(float(c[1])) < 0.5


@pytest.mark.parametrize("name", BUILTIN)
def test_deterministic_and_seeds_differ(volumes, name):
    a = volumes(name, 0, 32)
    assert torch.equal(a, shapes.generate(name, 0, 32))
    assert torch.equal(a, shapes.generate(name, np.int64(0), 32))
    b = volumes(name, 1, 32)
    assert float((a[3] - b[3]).abs().mean()) > 0.002
    assert float((a[:3] - b[:3]).abs().max()) > 0.1  # colours vary too


@pytest.mark.parametrize("name", ["chair", "tree", "animal"])
def test_a_seed_is_the_same_object_at_every_resolution(volumes, name):
    c32 = _centroid(volumes(name, 0, 32)[3], 32)
    c64 = _centroid(volumes(name, 0, 64)[3], 64)
    assert float((c32 - c64).norm()) < 0.06


def test_lathe_is_a_solid_of_revolution_about_y(volumes):
    for seed in SEEDS:
        v = volumes("lathe", seed, 32)
        swapped = v.flip(1).flip(3).transpose(1, 3)  # (x, y, z) → (z, y, x)
        assert torch.allclose(v, swapped, atol=1e-4)
        assert torch.allclose(v, v.flip(3), atol=1e-4)  # x → −x


def test_airplane_is_mirror_symmetric_and_flat(volumes):
    for seed in SEEDS:
        v = volumes("airplane", seed, 64)
        assert torch.allclose(v, v.flip(3), atol=1e-4)  # x → −x (w is the x axis)
        d = v[3] > 0.5
        z_extent = d.any(dim=(1, 2)).sum()   # along d (z): the fuselage
        y_extent = d.any(dim=(0, 2)).sum()   # along h (y): fin height
        assert z_extent > 2 * y_extent


@pytest.mark.parametrize("name", ["tree", "mushroom"])
def test_grows_from_the_ground_up(volumes, name):
    """Upright: the lowest occupied layer is a narrow trunk/stem under a wider top."""
    for seed in SEEDS:
        d = volumes(name, seed, 64)[3] > 0.5
        rows = d.any(dim=(0, 2)).nonzero().flatten()
        bottom, top = int(rows.max()), int(rows.min())  # h grows downwards
        width = d.sum(dim=(0, 2)).float()
        upper = width[top: (top + bottom) // 2 + 1].max()
        assert width[bottom] < 0.5 * upper


def test_chair_faces_the_front_camera(volumes):
    """The back (the top of the chair) lies at −z, the seat's front edge at +z."""
    for seed in SEEDS:
        d = volumes("chair", seed, 64)[3]
        first = int((d > 0.5).any(dim=(0, 2)).nonzero()[0])
        top = d[:, first:first + 8]  # the highest occupied rows (h grows downwards): the back rest
        c = (top.sum(dim=(1, 2)) * voxel_centres(64)[:, 0, 0, 2]).sum() / top.sum()
        assert float(c) < -0.1


def _silhouette_columns(volume, azimuth):
    """How many image columns the closed-form EA silhouette (α ≥ ½) covers, seen level from ``azimuth``."""
    from mitsuba_platonic.render import render
    from mitsuba_platonic.views import from_angles

    alpha = render(volume[None], from_angles(float(azimuth), 0.0)[None], "ea")[0, 3]
    return int((alpha >= 0.5).any(dim=0).sum())


def test_animal_is_narrow_end_on_and_long_from_the_side(volumes):
    """Length along z (the head at +z): seen end-on (azimuth 0°) the silhouette is a third to a half as
    wide as from the side views (±90°), where the length shows broadside; the drawn ratio is in
    [0.34, 0.48] (animal.WIDTH_RATIO), give or take a voxel's rounding on each of the widths."""
    from mitsuba_platonic.data.shapes.animal import WIDTH_RATIO

    ratios = []
    for seed in range(6):
        v = volumes("animal", seed, 64)
        end_on = _silhouette_columns(v, 0.0)
        side = _silhouette_columns(v, 90.0)
        assert side == _silhouette_columns(v, -90.0)               # mirror symmetric about x = 0
        ratios.append(end_on / side)
    assert min(ratios) >= WIDTH_RATIO[0] - 0.03 and max(ratios) <= WIDTH_RATIO[1] + 0.03, ratios
    assert max(ratios) - min(ratios) > 0.05                          # and it varies with the seed


def test_animal_stands_on_four_legs_with_its_head_forward_and_its_tail_behind(volumes):
    for seed in SEEDS:
        v = volumes("animal", seed, 64)
        assert torch.allclose(v[3], v[3].flip(2), atol=1e-4)          # the shape is mirror symmetric in x
        d = v[3] > 0.5
        rows = d.any(dim=(0, 2)).nonzero().flatten()
        bottom, top = int(rows.max()), int(rows.min())                 # h grows downwards
        # the feet: the lowest layer is four separate blobs, in the four quadrants of (x, z)
        foot = d[:, bottom - 1]                                        # (z, x), one layer above the soles
        c = voxel_centres(64)[:, bottom - 1]
        zs, xs = c[..., 2][foot], c[..., 0][foot]
        quadrants = {(bool(z > 0), bool(x > 0)) for z, x in zip(zs.tolist(), xs.tolist())}
        assert quadrants == {(False, False), (False, True), (True, False), (True, True)}
        assert not foot[:, 31:33].any() and not foot[31:33].any()     # nothing under the middle
        # the head and neck rise ahead (+z): the front half reaches at least as high as the back half
        p = voxel_centres(64)
        z, y = p[..., 2], p[..., 1]
        assert float(y[d & (z > 0)].max()) >= float(y[d & (z < 0)].max())
        # the body is long: its upper half (above the legs) reaches far both ways along z, not along x
        upper = d & (y > float(y[d].min() + y[d].max()) / 2)
        assert float(z[upper].min()) < -0.5 and float(z[upper].max()) > 0.5
        assert float(p[..., 0][upper].abs().max()) < 0.5 * float(z[upper].max() - z[upper].min())


# ------------------------------------------------------------------ errors and registration

def test_unknown_class_lists_the_known_ones():
    with pytest.raises(ValueError, match="unknown shape class 'sofa'.*airplane.*chair"):
        shapes.generate("sofa", 0, 32)
    with pytest.raises(ValueError, match="known classes"):
        shapes.get_class("sofa")


@pytest.mark.parametrize("n", [8, 15, 129, 256, 64.0, "64", True])
def test_bad_resolution(n):
    with pytest.raises(ValueError, match="n must be"):
        shapes.generate("chair", 0, n)


@pytest.mark.parametrize("seed", [1.5, "3", None, -1, False])
def test_bad_seed(seed):
    with pytest.raises(ValueError, match="seed must be"):
        shapes.generate("chair", seed, 32)


def test_register_a_custom_class_and_unregister_it():
    def ball(rng, n):
        r = rng.uniform(0.3, 0.6)
        return [S.sphere_part((0.0, 0.0, 0.0), r, (0.8, 0.2, 0.1)),
                S.capsule_part((0.0, 0.0, 0.0), (0.0, 1.5 * r, 0.0), 0.05 * r, (0.1, 0.7, 0.2))]

    assert "ball" not in shapes.list_classes()
    with shapes.registered("ball", ball):
        assert "ball" in shapes.list_classes() and shapes.get_class("ball") is ball
        v = shapes.generate("ball", 3, 32)
        assert v.shape == (4, 32, 32, 32) and float(v[3].max()) > 0.99
        assert torch.equal(v, shapes.generate("ball", 3, 32))
        with pytest.raises(ValueError, match="already registered"):
            shapes.register("ball", ball)
    assert "ball" not in shapes.list_classes()
    with pytest.raises(ValueError, match="unknown shape class 'ball'"):
        shapes.generate("ball", 0, 32)

    @shapes.register("cube_test")
    class Cube:
        def __call__(self, rng, n):
            return S.composite([S.box_part((0, 0, 0), (0.5, 0.5, 0.5), (0.5, 0.5, 0.9))], n)
    try:
        assert shapes.get_class("cube_test") is Cube
        v = shapes.generate("cube_test", 0, 16)
        assert float((v[3] > 0.5).float().mean()) > 0.05
    finally:
        shapes.unregister("cube_test")
    with pytest.raises(ValueError):
        shapes.unregister("cube_test")


def test_malformed_class_output_is_reported():
    with shapes.registered("broken_test", lambda rng, n: torch.zeros(4, 8, 8, 8)):
        with pytest.raises(RuntimeError, match="returned shape"):
            shapes.generate("broken_test", 0, 16)


# ------------------------------------------------------------------ SDF helpers

def test_grid_points_match_voxel_centres():
    n = 12
    full = voxel_centres(n).to(torch.float32)
    assert torch.allclose(S.grid_points(n), full)
    assert torch.allclose(S.grid_points(n, slice(2, 5), slice(0, 3), slice(7, 12)), full[2:5, 0:3, 7:12])


def test_occupancy_ramp_is_one_voxel_wide():
    n = 32
    h = voxel_size(n)
    d = torch.tensor([-h, -0.5 * h, -0.25 * h, 0.0, 0.25 * h, 0.5 * h, h])
    o = S.occupancy(d, n)
    assert o[0] == 1 and o[1] == 1 and o[-1] == 0 and o[-2] == 0
    assert abs(float(o[3]) - 0.5) < 1e-6
    assert torch.allclose(o[2] + o[4], torch.tensor(1.0))  # symmetric about the surface
    assert torch.all(o[1:] <= o[:-1])


def test_primitives_are_exact_where_documented():
    p = torch.tensor([[2.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 1.0, 0.0]])
    assert torch.allclose(S.sphere(p, (0, 0, 0), 1.0), torch.tensor([1.0, -1.0, math.sqrt(2) - 1]))
    assert torch.allclose(S.box(p, (0, 0, 0), (0.5, 0.5, 0.5)),
                          torch.tensor([1.5, -0.5, math.sqrt(0.5)]))
    assert torch.allclose(S.capsule(p, (0, -1, 0), (0, 1, 0), 0.25), torch.tensor([1.75, -0.25, 0.75]))
    assert torch.allclose(S.cylinder(p, (0, 0, 0), 0.5, 2.0), torch.tensor([1.5, -0.5, 0.5]))
    assert torch.allclose(S.torus(p, (0, 0, 0), 1.0, 0.25), torch.tensor([0.75, 0.75, 0.75]))
    # ellipsoid: zero on the surface, right sign
    e = S.ellipsoid(torch.tensor([[0.5, 0, 0], [0, 0.2, 0], [0, 0, 0.0], [1.0, 1.0, 1.0]]),
                    (0, 0, 0), (0.5, 0.2, 0.3))
    assert abs(float(e[0])) < 1e-6 and abs(float(e[1])) < 1e-6 and e[2] < 0 and e[3] > 0


def test_polygon_is_exact_at_sharp_corners():
    verts = [(0.0, 0.0), (1.0, 0.0), (1.0, 0.2)]  # a sharp wedge, counter-clockwise
    u, v = torch.tensor([2.0, 0.5, 1.5]), torch.tensor([0.2, 0.01, 0.0])
    d = S.polygon2d(u, v, verts)
    assert torch.allclose(d[0], torch.tensor(1.0))
    assert d[1] < 0 and torch.allclose(d[2], torch.tensor(0.5))


def _brute_profile(r, y, yt, rt):
    pts = [(0.0, yt[0])] + list(zip(rt, yt)) + [(0.0, yt[-1])]
    best = np.full(r.shape, np.inf)
    for (ar, ay), (br, by) in zip(pts[:-1], pts[1:]):
        er, ey = br - ar, by - ay
        h = np.clip(((r - ar) * er + (y - ay) * ey) / max(er * er + ey * ey, 1e-20), 0, 1)
        best = np.minimum(best, np.hypot(r - ar - h * er, y - ay - h * ey))
    inside = (y >= yt[0]) & (y <= yt[-1]) & (r <= np.interp(y, yt, rt))
    return np.where(inside, -best, best)


def test_profile_sdf_is_exact_even_at_steps():
    # a goblet-like profile with a near-horizontal step (where a first-order estimate fails)
    yt, rt = S.smooth_profile([0.0, 0.05, 0.08, 0.6, 1.0], [0.5, 0.5, 0.08, 0.1, 0.4], samples=96)
    g = torch.Generator().manual_seed(0)
    r = torch.rand(4000, generator=g, dtype=torch.float64) * 0.8
    y = torch.rand(4000, generator=g, dtype=torch.float64) * 1.4 - 0.2
    ref = _brute_profile(r.numpy(), y.numpy(), yt, rt)
    exact = S.profile_sdf(r, y, yt, rt).numpy()
    assert np.allclose(exact, ref, atol=1e-9)
    band = 0.05
    banded = S.profile_sdf(r, y, yt, rt, band=band).numpy()
    near = np.abs(ref) <= band
    assert np.allclose(banded[near], ref[near], atol=1e-9)
    assert np.all(np.sign(banded) == np.sign(ref)) and np.all(np.abs(banded[~near]) >= band)


def test_composite_fits_centres_and_keeps_thin_parts():
    # a thin rod far off-centre: after the fit it is centred, inside radius 0.82 + Δ, and
    # at n = 16 still present although far thinner than a voxel
    rod = S.capsule_part((3.0, 1.0, 0.0), (3.0, 5.0, 0.0), 0.001, (0.9, 0.5, 0.1))
    for n in (16, 48):
        v = S.composite([rod], n)
        d = v[3]
        # the thickness floor (1.5 voxels) keeps every cross-section above 0.5, even when
        # the rod's axis falls between four voxel centres
        prof = d.amax(dim=(0, 2))
        rows = (prof > 0.01).nonzero().flatten()
        assert float(prof[rows[2]:rows[-2]].min()) > 0.45
        r = voxel_centres(n).norm(dim=-1)
        assert float(d[r > 0.82 + 1.25 * voxel_size(n)].max()) == 0.0
        c = _centroid(d, n)
        assert float(c.norm()) < 0.05
        # the colour is the part's, also in empty voxels next to it (no dark fringe)
        near = (d > 0) & (d < 0.5)
        assert torch.allclose(v[:3][:, near], torch.tensor([0.9, 0.5, 0.1])[:, None], atol=1e-5)


def test_composite_blends_part_colours_by_occupancy():
    red = S.box_part((-0.5, 0, 0), (0.5, 0.5, 0.5), (1.0, 0.0, 0.0))
    blue = S.box_part((0.5, 0, 0), (0.5, 0.5, 0.5), (0.0, 0.0, 1.0))
    v = S.composite([red, blue], 32, fit_radius=None)
    x = voxel_centres(32)[..., 0]
    inside = v[3] > 0.99
    assert torch.all(v[0][inside & (x < -0.1)] > 0.99) and torch.all(v[2][inside & (x > 0.1)] > 0.99)
    assert float(v[3].max()) <= 1.0
