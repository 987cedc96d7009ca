"""Closed-form layers against an independent per-ray loop, finite differences and extremes."""

import numpy as np
import pytest
import torch

from mitsuba_platonic import render
from mitsuba_platonic import views as V
from mitsuba_platonic.render.pytorch.closed_form import render_closed_form
from mitsuba_platonic.volume import test_volume
from reference import render_ray_loop

ANGLES = [(0.0, 0.0), (33.0, 21.0), (-140.0, -52.0), (90.0, 0.0)]


def _volume(model, n, kind="random"):
    if kind == "random":
        c = 4 if model == "ea" else 1
        return torch.rand(1, c, n, n, n)
    return test_volume(n, kind, model)


@pytest.mark.parametrize("model", ["vh", "ao", "ea"])
@pytest.mark.parametrize("filter", ["nearest", "trilinear"])
@pytest.mark.parametrize("kind", ["random", "figure"])
def test_matches_independent_ray_loop(model, filter, kind):
    n = 8 if kind == "random" else 12
    vol = _volume(model, n, kind)
    if kind == "random" and model != "vh":
        vol[:, -1] *= 0.4  # keep some light coming through
    for az, el in ANGLES:
        w = V.from_angles(az, el)[None]
        got = render(vol, w, model, "closed_form", filter=filter)[0].double().numpy()
        want = render_ray_loop(vol[0].numpy(), az, el, model, filter)
        assert np.abs(got - want).max() < 2e-6, (az, el)


def test_front_view_is_a_plain_reduction_along_depth():
    vol = torch.rand(2, 1, 6, 6, 6)
    out = render(vol, V.front_view(2), "ao", "closed_form", filter="nearest")
    assert torch.allclose(out[:, 0], 1 - torch.prod(1 - vol[:, 0], dim=1), atol=1e-6)
    out = render(vol, V.front_view(2), "vh", "closed_form", filter="trilinear")
    assert torch.allclose(out[:, 0], 1 - torch.exp(-vol[:, 0].sum(1)), atol=1e-6)


@pytest.mark.parametrize("model", ["vh", "ao", "ea"])
@pytest.mark.parametrize("filter", ["nearest", "trilinear"])
def test_gradients_match_finite_differences(model, filter):
    c = 4 if model == "ea" else 1
    vol = (0.05 + 0.9 * torch.rand(2, c, 5, 5, 5, dtype=torch.float64)).requires_grad_()
    w = torch.cat([V.from_angles(30.0, 20.0)[None], V.front_view(1)]).double()
    assert torch.autograd.gradcheck(lambda x: render(x, w, model, "closed_form", filter=filter),
                                    (vol,), eps=1e-6, atol=1e-6, rtol=1e-4)


@pytest.mark.parametrize("model", ["ao", "ea"])
def test_gradients_exact_at_density_zero_and_one(model):
    """The product form needs no clamp: at v ∈ {0, 1} the gradient is still −Π_{j≠i}(1 − v_j)."""
    c = 4 if model == "ea" else 1
    vol = torch.rand(1, c, 4, 4, 4, dtype=torch.float64)
    d = vol[:, -1]
    d[d < 0.3] = 0.0
    d[d > 0.7] = 1.0
    vol.requires_grad_()
    w = V.front_view(1).double()
    # finite differences step outside [0, 1] here, so call the layer behind the validation
    assert torch.autograd.gradcheck(lambda x: render_closed_form(x, w, model, "nearest"),
                                    (vol,), eps=1e-7, atol=1e-6, rtol=1e-4)
    # the analytic AO gradient at a solid voxel
    if model == "ao":
        x = vol.detach().clone().requires_grad_()
        render(x, w, "ao", "closed_form", filter="nearest")[0, 0, 1, 2].backward()
        col = 1 - x.detach()[0, 0, :, 1, 2]
        for k in range(4):
            want = torch.prod(torch.cat([col[:k], col[k + 1:]]))
            assert torch.allclose(x.grad[0, 0, k, 1, 2], want)
