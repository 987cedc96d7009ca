"""Gradients of the Mitsuba marcher at exact 0s and 1s, against the closed form.

An opaque sample (v = 1, τ = 0) hides what lies behind it from the image but not from the
gradient: ∂α/∂v_k = T_k Π_{j>k} τ_j depends on every sample behind k. These volumes are made of
exact 0s and 1s (and, for the partial voxel, a value in between), so every model, filter and view
meets τ = 0 on its rays.
"""

import pytest
import torch

from mitsuba_platonic import render
from mitsuba_platonic import views as V

N = 16
MODELS = ["vh", "ao", "ea"]
FILTERS = ["nearest", "trilinear"]
VIEWS = {"front": V.front_view(1),
         "oblique": V.from_angles(torch.tensor([37.0]), torch.tensor([23.0]))}


def _with_colour(density: torch.Tensor, model: str, seed: int) -> torch.Tensor:
    """(1, C, N, N, N): the density, with a random colour in front of it for EA."""
    if model != "ea":
        return density[None, None]
    g = torch.Generator().manual_seed(seed)
    return torch.cat([torch.rand(3, N, N, N, generator=g), density[None]])[None]


def random_binary(seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return (torch.rand(N, N, N, generator=g) < 0.3).float()


def solid_box() -> torch.Tensor:
    d = torch.zeros(N, N, N)
    d[3:13, 4:12, 2:14] = 1.0
    return d


def opaque_before_partial() -> torch.Tensor:
    """Columns of one opaque voxel with a 0.4 voxel right behind it (d grows away from the front)."""
    d = torch.zeros(N, N, N)
    d[5, 2:14, 2:14] = 1.0
    d[6, 2:14, 2:14] = 0.4
    return d


VOLUMES = {"random_binary": random_binary, "solid_box": solid_box, "opaque_before_partial": opaque_before_partial}


def _grad(vol, view, model, backend, filter, weights):
    x = vol.clone().requires_grad_()
    (render(x, view, model, backend, filter=filter) * weights).sum().backward()
    return x.grad.flatten().double()


@pytest.mark.parametrize("volume", sorted(VOLUMES))
@pytest.mark.parametrize("view", sorted(VIEWS))
@pytest.mark.parametrize("filter", FILTERS)
@pytest.mark.parametrize("model", MODELS)
def test_gradients_at_exact_zeros_and_ones_agree_with_closed_form(model, filter, view, volume):
    vol = _with_colour(VOLUMES[volume](), model, seed=1)
    weights = torch.rand(1, 4 if model == "ea" else 1, N, N, generator=torch.Generator().manual_seed(2))
    want = _grad(vol, VIEWS[view], model, "closed_form", filter, weights)
    got = _grad(vol, VIEWS[view], model, "mitsuba", filter, weights)
    assert want.norm() > 0
    cosine = float(want @ got / (want.norm() * got.norm()))
    relative = float((want - got).norm() / want.norm())
    assert cosine >= 0.99999 and relative <= 1e-3, (cosine, relative)


@pytest.mark.parametrize("model", ["ao", "ea"])
def test_opaque_voxel_gradient_sees_the_voxel_behind(model):
    """α = 1 − (1 − v₁)(1 − v₂) with v₁ = 1, v₂ = 0.4: ∂α/∂v₁ = 1 − v₂ = 0.6 exactly."""
    vol = _with_colour(opaque_before_partial(), model, seed=3)
    x = vol.clone().requires_grad_()
    out = render(x, V.front_view(1), model, "mitsuba", filter="nearest")
    out[0, -1, 8, 8].backward()                      # one pixel's alpha
    assert torch.allclose(x.grad[0, -1, 5, 8, 8], torch.tensor(0.6), atol=1e-6)
    assert torch.allclose(x.grad[0, -1, 6, 8, 8], torch.tensor(0.0), atol=1e-7)   # hidden: T = 0 there
