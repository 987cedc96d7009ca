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
