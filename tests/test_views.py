import math

import pytest
import torch

from mitsuba_platonic import views as V
from reference import frame_from_angles


def test_front_view_and_its_frame():
    w = V.front_view(2)
    assert w.shape == (2, 3) and torch.equal(w[0], torch.tensor([0.0, 0.0, 1.0]))
    r, u, ww = V.camera_frames(w)
    assert torch.allclose(r, torch.tensor([[1.0, 0, 0]] * 2, dtype=torch.float64))
    assert torch.allclose(u, torch.tensor([[0.0, 1, 0]] * 2, dtype=torch.float64))


@pytest.mark.parametrize("az,el", [(0, 0), (30, 10), (-120, 45), (200, -60), (90, 89.9)])
def test_frames_match_angles_and_are_orthonormal(az, el):
    w = V.from_angles(az, el)[None]
    r, u, ww = V.camera_frames(w)
    ω, right, up = frame_from_angles(az, el)
    assert torch.allclose(r[0], torch.tensor(right), atol=1e-6)
    assert torch.allclose(u[0], torch.tensor(up), atol=1e-6)
    m = torch.stack([r[0], u[0], ww[0]])
    assert torch.allclose(m @ m.T, torch.eye(3, dtype=torch.float64), atol=1e-12)
    assert torch.allclose(torch.linalg.cross(r[0], u[0], dim=0), ww[0], atol=1e-12)  # right-handed


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_poles_are_defined_and_continuous_along_the_front_meridian(sign):
    pole = torch.tensor([[0.0, sign, 0.0]])
    r, u, w = V.camera_frames(pole)
    assert torch.isfinite(r).all() and torch.isfinite(u).all()
    assert torch.allclose(r[0], torch.tensor([1.0, 0, 0], dtype=torch.float64))
    assert torch.allclose(u[0], torch.tensor([0.0, 0, -sign], dtype=torch.float64))
    # approaching the pole along φ = 0, the frame converges to the pole's frame
    for eps in [1e-2, 1e-4, 1e-6]:
        near = V.from_angles(0.0, sign * (90.0 - eps))[None]
        rn, un, _ = V.camera_frames(near)
        assert (rn - r).abs().max() < 1e-12 + 1e-3
        assert (un - u).abs().max() < 2 * math.radians(eps) + 1e-6


def test_sphere_sampling_is_uniform_and_deterministic():
    a = V.sample_views(20000, "sphere", seed=1)
    b = V.sample_views(20000, "sphere", seed=1)
    c = V.sample_views(20000, "sphere", seed=2)
    assert torch.equal(a, b) and not torch.equal(a, c)
    assert torch.allclose(a.norm(dim=1), torch.ones(20000), atol=1e-6)
    # uniform on S²: each coordinate is uniform on [-1, 1] (mean 0, variance 1/3)
    assert a.mean(0).abs().max() < 0.02
    assert ((a ** 2).mean(0) - 1 / 3).abs().max() < 0.01
    # hemisphere and octant balance
    assert abs(float((a[:, 1] > 0).float().mean()) - 0.5) < 0.015


def test_band_and_ring():
    band = V.sample_views(5000, "band", seed=0, elevation=(10.0, 40.0))
    _, el = V.to_angles(band)
    assert el.min() >= 10.0 - 1e-3 and el.max() <= 40.0 + 1e-3
    y = band[:, 1]  # uniform by area: y uniform on [sin 10°, sin 40°]
    lo, hi = math.sin(math.radians(10)), math.sin(math.radians(40))
    assert abs(float(y.mean()) - (lo + hi) / 2) < 0.01
    ring = V.sample_views(1000, "ring", seed=0, elevation=20.0)
    _, el = V.to_angles(ring)
    assert torch.allclose(el, torch.full_like(el, 20.0), atol=1e-4)
    az, _ = V.to_angles(ring)
    assert az.min() < -170 and az.max() > 170


def test_turntable_and_angles_round_trip():
    t = V.turntable(8, elevation=15.0)
    az, el = V.to_angles(t)
    assert torch.allclose(el, torch.full((8,), 15.0, dtype=torch.float64), atol=1e-4)
    assert torch.allclose(torch.remainder(az, 360.0), torch.arange(8, dtype=torch.float64) * 45.0, atol=1e-4)


def test_bad_input():
    with pytest.raises(ValueError, match="distribution"):
        V.sample_views(3, "cube")
    with pytest.raises(ValueError, match="elevation"):
        V.sample_views(3, "band", elevation=(50.0, 10.0))
    with pytest.raises(ValueError, match="single elevation"):
        V.sample_views(3, "ring", elevation=(0.0, 10.0))
    with pytest.raises(ValueError, match="unit"):
        V.validate_views(torch.tensor([[0.0, 0.0, 2.0]]))
    with pytest.raises(ValueError, match=r"\(B, 3\)"):
        V.validate_views(torch.zeros(3))
    with pytest.raises(ValueError, match="NaN"):
        V.validate_views(torch.tensor([[float("nan"), 0.0, 1.0]]))


@pytest.mark.parametrize("width", [30.0, 10.0, 90.0])
def test_sides_draws_azimuths_uniformly_within_w_of_the_two_side_views(width):
    n = 20000
    v = V.sample_views(n, "sides", seed=3, elevation=(-10.0, 40.0), side_width=width)
    assert torch.allclose(v.norm(dim=1), torch.ones(n), atol=1e-6)
    az, el = V.to_angles(v)
    assert el.min() >= -10.0 - 1e-3 and el.max() <= 40.0 + 1e-3
    y = v[:, 1].double()                              # as the band's: y uniform on [sin θ_lo, sin θ_hi]
    lo, hi = math.sin(math.radians(-10.0)), math.sin(math.radians(40.0))
    assert abs(float(y.mean()) - (lo + hi) / 2) < 0.01
    # the distance from the nearer side view, and which side: every azimuth within W, half on each side
    off_plus, off_minus = (torch.remainder(az - s + 180.0, 360.0) - 180.0 for s in V.SIDE_AZIMUTHS)
    near = torch.minimum(off_plus.abs(), off_minus.abs())
    assert float(near.max()) <= width + 1e-3
    plus = off_plus.abs() <= off_minus.abs()
    assert abs(float(plus.float().mean()) - 0.5) < 4 * math.sqrt(0.25 / n)
    # uniform within each window: the offsets' histogram in 10 bins, each count within 5 σ of n / 20
    for offsets in (off_plus[plus], off_minus[~plus]):
        counts = torch.histc(offsets, bins=10, min=-width, max=width)
        expected = len(offsets) / 10
        assert float((counts - expected).abs().max()) < 5 * math.sqrt(expected)
    if width == 90.0:                                 # the two windows cover the circle: uniform
        assert az.min() < -179.0 and az.max() > 179.0 and float(az.abs().min()) < 0.1


def test_sides_is_deterministic_its_default_width_is_30_and_other_distributions_keep_their_draws():
    a = V.sample_views(500, "sides", seed=7, elevation=(0.0, 20.0))
    assert torch.equal(a, V.sample_views(500, "sides", seed=7, elevation=(0.0, 20.0), side_width=30.0))
    assert not torch.equal(a, V.sample_views(500, "sides", seed=8, elevation=(0.0, 20.0)))
    assert V.DEFAULT_SIDE_WIDTH == 30.0 and V.DEFAULT_ELEVATION["sides"] == V.DEFAULT_ELEVATION["band"]
    # 'band' draws φ = 2π u, y from the next uniforms, as before 'sides' existed
    g = torch.Generator().manual_seed(7)
    u = torch.rand(500, generator=g, dtype=torch.float64)
    y = math.sin(0.0) + (math.sin(math.radians(20.0)) - math.sin(0.0)) * torch.rand(500, generator=g, dtype=torch.float64)
    r = torch.sqrt(1.0 - y * y)
    expected = torch.stack([r * torch.sin(2 * math.pi * u), y, r * torch.cos(2 * math.pi * u)], dim=-1).float()
    assert torch.equal(V.sample_views(500, "band", seed=7, elevation=(0.0, 20.0)), expected)
    assert "sides" in V.COLLECTION_DISTRIBUTIONS and "sides" not in V.DISTRIBUTIONS   # collections only


@pytest.mark.parametrize("width", [0.0, -5.0, 90.5, float("nan"), float("inf"), True, "30"])
def test_sides_refuses_a_bad_width(width):
    with pytest.raises(ValueError, match=r"side_width.*0 < W <= 90"):
        V.sample_views(3, "sides", elevation=(0.0, 30.0), side_width=width)


def test_sides_needs_a_band_and_only_sides_reads_a_width():
    with pytest.raises(ValueError, match=r"'sides' needs elevation=\(low, high\)"):
        V.sample_views(3, "sides", elevation=20.0)
    with pytest.raises(ValueError, match="'sides' needs elevation"):
        V.sample_views(3, "sides", elevation=(40.0, 10.0))
    for other in ("sphere", "band", "ring"):
        with pytest.raises(ValueError, match="side_width is read by the 'sides' distribution only"):
            V.sample_views(3, other, elevation=20.0 if other == "ring" else (0.0, 30.0), side_width=30.0)
