"""The mirror frame (train/mirror.py): planes found where they are, views drawn about them."""

import math

import pytest
import torch

from mitsuba_platonic.evaluate.photo_truth import silhouette_widths
from mitsuba_platonic.train.mirror import (asymmetry, centroid, fold_to_normal, mirror_frame_views, mirror_loss,
                                           mirror_planes, mirrored)
from mitsuba_platonic.views import from_angles, to_angles
from mitsuba_platonic.volume import voxel_centres

N = 32


def animal(ψ_deg: float, n: int = N, offset=(0.0, 0.0)) -> torch.Tensor:
    """An RGBA volume ``(4, n, n, n)``: a body long along the horizontal direction at azimuth ψ + 90°
    (semi-axes 0.6 along it, 0.22 across, 0.25 up) with a head (radius 0.2) at one end: mirror-symmetric
    about the vertical plane with normal n(ψ) through (x, z) = ``offset``, about no other (soft-edged, so that resampling it is smooth)."""
    p = voxel_centres(n)
    ψ = math.radians(ψ_deg)
    normal = torch.tensor([math.sin(ψ), 0.0, math.cos(ψ)], dtype=torch.float64)
    along = torch.tensor([math.sin(ψ + math.pi / 2), 0.0, math.cos(ψ + math.pi / 2)], dtype=torch.float64)
    q = p - torch.tensor([offset[0], 0.0, offset[1]], dtype=torch.float64)
    a, c, y = q @ along, q @ normal, q[..., 1]
    body = torch.sqrt((a / 0.6) ** 2 + (c / 0.22) ** 2 + (y / 0.25) ** 2) - 1.0
    head = torch.sqrt((a - 0.6) ** 2 + c ** 2 + (y - 0.15) ** 2) / 0.2 - 1.0
    α = torch.sigmoid(-torch.minimum(body, head) / 0.1)                  # soft edges, as G's volumes have
    return torch.cat([0.5 * α[None].expand(3, -1, -1, -1), α[None]]).float()


def test_mirror_about_the_front_plane_and_the_side_plane_flips_depth_and_width_exactly():
    v = torch.rand(2, 4, N, N, N)
    zero = torch.zeros(2)
    assert torch.allclose(mirrored(v, zero, torch.zeros(2, 2)), v.flip(2), atol=1e-6)
    assert torch.allclose(mirrored(v, zero + math.pi / 2, torch.zeros(2, 2)), v.flip(4), atol=1e-4)   # cos(π/2) in float32 is 4e-8, not 0


def test_mirror_is_its_own_inverse_away_from_the_cube_edges():
    v = animal(30.0)[None]
    ψ, c = torch.tensor([0.7]), torch.tensor([[0.05, -0.1]])
    twice = mirrored(mirrored(v, ψ, c), ψ, c)
    assert (twice - v).abs().sum() / v.sum() < 0.15          # two trilinear resamples blur the edge voxels only


def test_centroid_is_where_the_matter_is_in_world_x_and_z():
    c = centroid(animal(0.0, offset=(0.25, -0.2))[None, -1:])
    # the body is symmetric about its offset along the normal; the head shifts it along the body's axis (x at ψ=0)
    assert c[0, 1] == pytest.approx(-0.2, abs=0.02)
    assert c[0, 0] > 0.25


@pytest.mark.parametrize("ψ_deg", [0.0, 20.0, 55.0, 90.0, 130.0, 165.0])
def test_planes_are_found_at_the_one_plane_the_volume_is_symmetric_about(ψ_deg):
    planes = mirror_planes(animal(ψ_deg, offset=(0.1, -0.05))[None])
    err = (math.degrees(float(planes.ψ[0])) - ψ_deg + 90.0) % 180.0 - 90.0
    assert abs(err) < 4.0, (math.degrees(float(planes.ψ[0])), ψ_deg)
    assert float(planes.asymmetry[0]) < 0.1
    # about the perpendicular plane (head against tail) it is far from symmetric
    across = asymmetry(animal(ψ_deg, offset=(0.1, -0.05))[None], planes.ψ + math.pi / 2, planes.centre)
    assert float(across[0]) > 3 * float(planes.asymmetry[0])


def test_a_camera_at_the_planes_azimuth_sees_the_long_side():
    """The plane's normal is the view at azimuth ψ in the renderer's own convention: from there the body is
    broad, from ψ + 90° (along the plane) narrow."""
    v = animal(35.0)
    ψ = float(mirror_planes(v[None]).ψ[0])
    views = from_angles(torch.tensor([math.degrees(ψ), math.degrees(ψ) + 90.0]), 0.0)
    side, end = silhouette_widths(v, views, (0.0, 1.0, 0.0))
    assert side > 2.0 * end


def test_fold_gives_the_input_cameras_angle_to_the_normal_in_0_to_90_degrees():
    ψ = torch.deg2rad(torch.tensor([0.0, 10.0, 80.0, 90.0, 100.0, 170.0, 179.0]))
    β = torch.rad2deg(fold_to_normal(ψ))
    assert torch.allclose(β, torch.tensor([0.0, 10.0, 80.0, 90.0, 80.0, 10.0, 1.0]), atol=1e-4)


def test_views_of_a_side_photographed_batch_stay_at_the_sides_and_keep_their_elevation():
    g = torch.Generator().manual_seed(0)
    ψ = torch.deg2rad(torch.tensor([5.0, -8.0, 12.0, 3.0])) % math.pi      # every photo within 12° of its plane's normal
    views = from_angles(torch.rand(4 * 50) * 360.0, torch.rand(4 * 50) * 50.0 - 10.0)
    out = mirror_frame_views(views, ψ, g)
    φ, θ = to_angles(out)
    assert torch.allclose(θ, to_angles(views)[1], atol=1e-3)
    i = torch.arange(200) // 50
    rel = (φ - torch.rad2deg(ψ.double())[i] + 90.0) % 180.0 - 90.0        # angle to volume i's normal, either side
    assert rel.abs().max() <= 12.0 + 1e-3
    assert (rel > 0).any() and (rel < 0).any()                               # both mirror images
    front = ((φ - torch.rad2deg(ψ.double())[i]) % 360.0 - 180.0).abs() > 90.0
    assert 0.3 < front.double().mean() < 0.7                                  # both sides of the plane


def test_views_of_a_batch_at_every_angle_to_its_planes_cover_every_azimuth():
    g = torch.Generator().manual_seed(1)
    ψ = torch.linspace(0.0, math.pi, 64 + 1)[:-1]
    out = mirror_frame_views(from_angles(torch.zeros(64 * 16), torch.zeros(64 * 16)), ψ, g)
    φ = to_angles(out)[0] % 360.0
    counts = torch.histc(φ.float(), bins=8, min=0.0, max=360.0)
    assert counts.min() > 0.6 * counts.mean()


def test_mirror_loss_is_zero_on_a_symmetric_volume_and_pulls_an_asymmetric_one_towards_its_plane():
    v = animal(0.0)[None]
    planes = mirror_planes(v)
    assert float(mirror_loss(v, planes)) < 0.02
    w = v.clone()
    w[0, 3, :N // 2] = 0.0                               # cut the front half: no longer symmetric about z = 0
    w.requires_grad_(True)
    planes = mirror_planes(w)
    loss = mirror_loss(w, planes)
    assert float(loss) > 0.05
    loss.backward()
    assert w.grad[0, 3].abs().sum() > 0


def test_bad_shapes_are_refused_with_what_was_expected():
    with pytest.raises(ValueError, match="upright volumes"):
        mirror_planes(torch.zeros(1, 4, 8, 8, 6))
    with pytest.raises(ValueError, match="views"):
        mirror_frame_views(torch.zeros(5, 3), torch.zeros(2), torch.Generator())
