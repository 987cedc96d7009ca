"""One owner for renderer settings: render(), configs and training all use RenderSettings."""

import pytest
import torch

from mitsuba_platonic import render, render_with
from mitsuba_platonic import views as V
from mitsuba_platonic.config import ConfigError, load_config
from mitsuba_platonic.render import RenderSettings
from mitsuba_platonic.train.renderer import make_renderer
from mitsuba_platonic.volume import test_volume


def test_the_config_render_section_is_the_renderers_settings():
    cfg = load_config(None, ["render.backend=mitsuba", "render.termination=0.01", "render.step=0.5",
                             "render.model=ea", "data.formation=ea"])
    assert isinstance(cfg.render, RenderSettings)
    assert (cfg.render.termination, cfg.render.step) == (0.01, 0.5)
    for bad, match in [("render.termination=1.5", r"render\.termination"), ("render.spp=3", r"render\.spp"),
                       ("render.step=0", r"render\.step"), ("render.backend=optix", r"render\.backend")]:
        with pytest.raises(ConfigError, match=match):
            load_config(None, [bad])


@pytest.mark.parametrize("backend, options", [("closed_form", {"filter": "nearest"}),
                                              ("mitsuba", {"step": 0.5, "termination": 1e-3, "jitter": True, "spp": 2})])
def test_render_training_and_settings_give_the_same_images(backend, options):
    """render(**options), render_with(settings) and the trainer's renderer are one code path."""
    vol = test_volume(16, "figure", "ea").expand(2, -1, -1, -1, -1).contiguous()
    views = V.sample_views(2, seed=3)
    a = render(vol, views, "ea", backend, seed=5, **options)
    settings = RenderSettings(backend=backend, model="ea", **options)
    b = render_with(vol, views, settings, seed=5)
    c = make_renderer(settings)(vol, views, 5)
    assert torch.equal(a, b) and torch.equal(a, c)


def test_physical_backend_through_render():
    vol = test_volume(8, "figure", "ea")
    out = render(vol, V.front_view(1), "ea", "physical", seed=1, physical_spp=1, max_depth=2)
    assert out.shape == (1, 4, 8, 8) and torch.isfinite(out).all()
    with pytest.raises(ValueError, match="unknown option"):
        render(vol, V.front_view(1), "ea", "physical", step=2)
    with pytest.raises(ValueError, match="model"):
        render(vol[:, 3:], V.front_view(1), "ao", "physical")
