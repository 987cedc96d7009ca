"""Numerical extremes of both renderers, each against an independent value.

Densities 0, 1 and denormal-small; transmittance underflow on long rays at 128³; steps from 4
voxels down to 1/16 against Beer–Lambert; the closed form in float32 against float64; gradients at
a saturated generator's outputs; non-finite input rejected, never rendered.
"""

import math

import pytest
import torch

from mitsuba_platonic import render
from mitsuba_platonic import views as V

MODELS = ["vh", "ao", "ea"]
BACKENDS = ["closed_form", "mitsuba"]


def _volume(density: torch.Tensor, model: str) -> torch.Tensor:
    if model != "ea":
        return density
    colour = torch.tensor([0.2, 0.5, 0.8]).view(1, 3, 1, 1, 1).expand(density.shape[0], 3, *density.shape[2:])
    return torch.cat([colour, density], dim=1)


def _expected_alpha(model: str, v: float, length: int) -> float:
    """Opacity of ``length`` voxels of density v seen head-on."""
    return 1.0 - math.exp(-v * length) if model == "vh" else 1.0 - (1.0 - v) ** length


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("v", [0.0, 1e-40, 1.0])
def test_constant_volumes_at_exact_and_denormal_densities(backend, model, v):
    """A constant N³ volume seen head-on: every pixel has opacity 1 − (1 − v)^N (VH: 1 − e^{−vN})."""
    n = 16
    vol = _volume(torch.full((1, 1, n, n, n), v), model).requires_grad_()
    out = render(vol, V.front_view(1), model, backend, filter="nearest")
    want = _expected_alpha(model, v, n)
    assert torch.allclose(out[:, -1], torch.full_like(out[:, -1], want), atol=1e-7, rtol=0)
    out.sum().backward()
    assert torch.isfinite(vol.grad).all()


@pytest.mark.parametrize("model", MODELS)
def test_long_rays_at_128_underflow_to_exact_opacity_without_nan(model):
    """128 voxels of density 0.5: T = 0.5^128 ≈ 3e-39 (denormal in float32) for AO/EA, e^{−64} for VH."""
    n = 128
    vol = _volume(torch.full((1, 1, n, n, n), 0.5), model)
    views = V.front_view(1)
    want = _expected_alpha(model, 0.5, n)
    grads = []
    for backend in BACKENDS:
        x = vol.clone().requires_grad_()
        out = render(x, views, model, backend, filter="nearest")
        assert torch.isfinite(out).all()
        assert torch.allclose(out[:, -1], torch.full_like(out[:, -1], want), atol=1e-7, rtol=0)
        out[:, -1].sum().backward()
        assert torch.isfinite(x.grad).all()
        grads.append(x.grad[0, -1, :, 64, 64].double())       # one ray's gradient along depth
    # ∂α/∂v_k = Π_{j≠k} (1 − v_j) = 0.5^127 ≈ 5.9e-39 for AO/EA, e^{−64} ≈ 1.6e-28 for VH. Dr.Jit's CPU
    # kernels flush denormals to zero, torch keeps them: the two agree to float32's smallest normal
    tiny = torch.finfo(torch.float32).tiny
    assert torch.allclose(grads[0], grads[1], rtol=1e-3, atol=tiny)
    if model == "vh":
        assert torch.allclose(grads[1], torch.full_like(grads[1], math.exp(-64.0)), rtol=1e-4)


@pytest.mark.parametrize("step", [4.0, 2.0, 1.0, 0.5, 0.25, 0.0625])
@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("v", [0.05, 0.3, 0.9])
def test_steps_from_4_voxels_to_a_sixteenth_match_beer_lambert(step, model, v):
    """A slab of L = 8 voxels of density v, head-on, aligned with every step's segments:
    T = exp(−σ L Δ) = (1 − v)^L (VH: e^{−vL}), C = c (1 − T)."""
    n, first, L = 32, 8, 8
    density = torch.zeros(1, 1, n, n, n)
    density[:, :, first:first + L] = v
    out = render(_volume(density, model), V.front_view(1), model, "mitsuba", filter="nearest", step=step)
    want = _expected_alpha(model, v, L)
    centre = out[0, -1, 8:24, 8:24]
    assert torch.allclose(centre, torch.full_like(centre, want), atol=2e-6, rtol=0), (step, float(centre[0, 0]))
    if model == "ea":                                           # C = c (1 − T) for a uniform slab
        rgb = out[0, :3, 16, 16]
        assert torch.allclose(rgb, torch.tensor([0.2, 0.5, 0.8]) * want, atol=2e-6)


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("filter", ["nearest", "trilinear"])
def test_closed_form_float32_agrees_with_float64(model, filter):
    g = torch.Generator().manual_seed(3)
    c = 4 if model == "ea" else 1
    vol = torch.rand(2, c, 16, 16, 16, generator=g, dtype=torch.float64)
    vol[:, -1] = (vol[:, -1] > 0.6).double() * vol[:, -1]          # exact zeros too
    views = V.sample_views(2, seed=5).double()
    a = render(vol, views, model, "closed_form", filter=filter)
    b = render(vol.float(), views.float(), model, "closed_form", filter=filter)
    assert a.dtype == torch.float64 and b.dtype == torch.float32
    assert (a - b.double()).abs().max() <= 1e-5


@pytest.mark.parametrize("model", MODELS)
def test_gradients_at_a_saturated_generator_output_agree(model):
    """A sigmoid that saturates to exactly 1.0 in float32 (logit ≥ 17): both renderers give the same,
    finite gradient w.r.t. the logits (zero where the sigmoid is flat, as autograd computes it)."""
    g = torch.Generator().manual_seed(4)
    c = 4 if model == "ea" else 1
    logits = torch.randn(1, c, 16, 16, 16, generator=g) * 4.0
    logits[:, -1, 4:12, 4:12, 4:12] = 30.0                         # σ(30) == 1.0 exactly in float32
    assert bool((torch.sigmoid(logits) == 1.0).any())
    views = V.from_angles(torch.tensor([33.0]), torch.tensor([-21.0]))
    weights = torch.rand(1, c, 16, 16, generator=g)
    grads = []
    for backend in BACKENDS:
        x = logits.clone().requires_grad_()
        (render(torch.sigmoid(x), views, model, backend) * weights).sum().backward()
        assert torch.isfinite(x.grad).all()
        grads.append(x.grad.flatten().double())
    rel = float((grads[0] - grads[1]).norm() / grads[0].norm())
    assert rel <= 1e-3, rel


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("bad, match", [(float("nan"), "NaN"), (float("inf"), r"\[0, 1\]"),
                                        (float("-inf"), r"\[0, 1\]")])
def test_non_finite_volumes_are_rejected_not_rendered(backend, bad, match):
    vol = torch.rand(1, 4, 8, 8, 8)
    vol[0, 3, 4, 4, 4] = bad
    with pytest.raises(ValueError, match=match):
        render(vol, V.front_view(1), "ea", backend)
