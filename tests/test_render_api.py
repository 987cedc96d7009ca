"""The public entry point: validation at the boundary, shapes, both backends."""

import pytest
import torch

import mitsuba_platonic as mp
from mitsuba_platonic import views as V


@pytest.mark.parametrize("backend", ["closed_form", "mitsuba"])
@pytest.mark.parametrize("model,c_in,c_out", [("vh", 1, 1), ("ao", 1, 1), ("ea", 4, 4)])
def test_shapes(backend, model, c_in, c_out):
    vol = torch.rand(2, c_in, 8, 8, 8) * 0.5
    out = mp.render(vol, V.sample_views(2, seed=0), model=model, backend=backend)
    assert out.shape == (2, c_out, 8, 8) and out.dtype == torch.float32


@pytest.mark.parametrize("backend", ["closed_form", "mitsuba"])
def test_bad_input_messages(backend):
    good = torch.rand(2, 4, 8, 8, 8)
    views = V.sample_views(2, seed=0)
    cases = [
        (good[0], views, "ea", "rank 5"),
        (good, views, "vh", "needs 1 channel"),
        (good[:, :1], views, "ea", "needs 4 channel"),
        (good * 2, views, "ea", r"\[0, 1\]"),
        (good.clone().fill_(float("nan")), views, "ea", "NaN"),
        (good, views * 2, "ea", "unit vectors"),
        (good, views[:1], "ea", "batch"),
        (good, views, "xray", "model: expected one of"),
        (good[:, :, :, :, :4], views, "ea", "cubic"),
        (good.to(torch.int64), views, "ea", "floating-point"),
    ]
    for vol, w, model, match in cases:
        with pytest.raises(ValueError, match=match):
            mp.render(vol, w, model=model, backend=backend)


def test_unknown_backend_and_option():
    vol = torch.rand(1, 1, 8, 8, 8)
    with pytest.raises(ValueError, match="backend"):
        mp.render(vol, V.front_view(1), "vh", backend="optix")
    with pytest.raises(ValueError, match="unknown option"):
        mp.render(vol, V.front_view(1), "vh", backend="closed_form", step=2)
