"""The perspective (pinhole) camera: both renderers agree, and both match the pinhole's geometry
and path lengths computed here independently; the orthographic camera stays the default."""

import math

import pytest
import torch

from mitsuba_platonic import render
from mitsuba_platonic import views as V
from mitsuba_platonic.errors import UserError
from mitsuba_platonic.volume import test_volume

MODELS = ["vh", "ao", "ea"]
FILTERS = ["nearest", "trilinear"]
OBLIQUE = V.from_angles(torch.tensor([37.0, -128.0, 75.0]), torch.tensor([23.0, -41.0, 8.0]))
PINHOLE = dict(camera="perspective", fov=50.0)


def _vol(model, n, kind="figure", batch=1):
    return test_volume(n, kind, model).expand(batch, -1, -1, -1, -1).contiguous()


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("filter", FILTERS)
@pytest.mark.parametrize("lens", [dict(fov=50.0), dict(fov=30.0, distance=2.5)], ids=["fov50", "fov30-d2.5"])
def test_closed_form_and_marcher_agree(model, filter, lens):
    vol = _vol(model, 32, batch=4)
    views = torch.cat([V.front_view(1), OBLIQUE])
    a = render(vol, views, model, "closed_form", filter=filter, camera="perspective", **lens)
    b = render(vol, views, model, "mitsuba", filter=filter, camera="perspective", **lens)
    assert a.shape == b.shape and a.abs().max() > 0.1
    assert (a - b).abs().max() <= 1e-4


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("n", [16, 32])
def test_gradients_agree(model, n):
    vol = _vol(model, n, "cloud", batch=2)
    views = torch.cat([V.front_view(1), OBLIQUE[:1]])
    w = torch.rand(2, 4 if model == "ea" else 1, n, n)
    grads = []
    for backend in ("closed_form", "mitsuba"):
        x = vol.clone().requires_grad_()
        (render(x, views, model, backend, **PINHOLE) * w).sum().backward()
        grads.append(x.grad)
    assert (grads[0] - grads[1]).norm() / grads[0].norm() <= 1e-3


@pytest.mark.parametrize("backend", ["closed_form", "mitsuba"])
@pytest.mark.parametrize("model", ["vh", "ao"])
def test_a_uniform_cube_matches_the_pinholes_path_lengths(backend, model):
    """Inside a cube of uniform density v, the ray of pixel (x, y) crosses all N planes along a
    path of N ℓ voxels, ℓ = √(1 + tan²(F/2)(x² + y²)): ρ = 1 − exp(−N ℓ v) (VH), 1 − (1 − v)^{N ℓ} (AO).
    Checked on the pixels whose ray stays inside the cube from front to back."""
    n, v, fov = 16, 0.05, 50.0
    vol = torch.full((1, 1, n, n, n), v)
    img = render(vol, V.front_view(1), model, backend, filter="nearest", camera="perspective", fov=fov)[0, 0]
    t = math.tan(math.radians(fov) / 2)
    d = 1.0 / t
    c = -1.0 + (torch.arange(n, dtype=torch.float64) + 0.5) * (2.0 / n)
    x, y = c[None, :], -c[:, None]
    ell = torch.sqrt(1.0 + t * t * (x * x + y * y))
    want = 1.0 - (torch.exp(-n * ell * v) if model == "vh" else (1.0 - v) ** (n * ell))
    # the ray's widest point is at the back plane z = −1: S(−1) = (D + 1) t; stay a voxel inside
    inside = (torch.maximum(x.abs(), y.abs()) * (d + 1.0) * t <= 1.0 - 2.0 / n).expand(n, n)
    assert inside.sum() >= 16
    assert (img.double() - want)[inside].abs().max() <= 1e-5


@pytest.mark.parametrize("backend", ["closed_form", "mitsuba"])
def test_a_point_projects_where_the_pinhole_puts_it(backend):
    """A small blob at world (0.5, 0.25, z) shows at image x = 0.5 / S(z), y = 0.25 / S(z), with
    S(z) = (D − z) tan(F/2): nearer blobs look further from the centre."""
    n, fov, dist = 64, 40.0, 3.0
    t = math.tan(math.radians(fov) / 2)
    for z in (0.6, -0.6):
        vol = _grid_blob(n, (0.5, 0.25, z), 0.06)[None, None]
        img = render(vol, V.front_view(1), "ao", backend, camera="perspective", fov=fov, distance=dist)[0, 0].double()
        w = img / img.sum()
        c = -1.0 + (torch.arange(n, dtype=torch.float64) + 0.5) * (2.0 / n)
        x_seen, y_seen = float((w.sum(0) * c).sum()), float((w.sum(1) * -c).sum())
        s = (dist - z) * t
        assert x_seen == pytest.approx(0.5 / s, abs=0.02), z
        assert y_seen == pytest.approx(0.25 / s, abs=0.02), z


def _grid_blob(n, centre, radius):
    """A ball of density 1 around the world point ``centre``, in the volume's [d, h, w] layout
    (w along +x, h along −y, d along −z: docs/conventions.md)."""
    c = -1.0 + (torch.arange(n, dtype=torch.float64) + 0.5) * (2.0 / n)
    d, h, w = torch.meshgrid(c, c, c, indexing="ij")
    x, y, z = w, -h, -d
    return ((((x - centre[0]) ** 2 + (y - centre[1]) ** 2 + (z - centre[2]) ** 2) <= radius ** 2)).float()


@pytest.mark.parametrize("backend", ["closed_form", "mitsuba"])
def test_a_far_narrow_pinhole_approaches_the_orthographic_camera(backend):
    vol = _vol("ea", 32, batch=3)
    ortho = render(vol, OBLIQUE, "ea", backend)
    far = render(vol, OBLIQUE, "ea", backend, camera="perspective", fov=0.02)       # D = 1 / tan(0.01°)
    assert (ortho - far).abs().max() <= 2e-3


def test_the_default_camera_is_orthographic():
    vol = _vol("ea", 16, batch=3)
    assert torch.equal(render(vol, OBLIQUE, "ea", "mitsuba"),
                       render(vol, OBLIQUE, "ea", "mitsuba", camera="orthographic", fov=10.0))


@pytest.mark.parametrize("options, match", [
    (dict(camera="fisheye"), "camera: expected one of"),
    (dict(camera="perspective", fov=0.0), "fov: expected"),
    (dict(camera="perspective", fov=180.0), "fov: expected"),
    (dict(camera="perspective", fov=40.0, distance=1.0), "distance: expected"),
    (dict(camera="perspective", fov=40.0, distance=float("inf")), "distance: expected"),
])
def test_bad_camera_settings_are_one_line_errors(options, match):
    with pytest.raises(UserError, match=match):
        render(_vol("vh", 8), V.front_view(1), "vh", "mitsuba", **options)


def test_the_path_tracer_refuses_a_camera_option():
    with pytest.raises(UserError, match="unknown option"):
        render(_vol("ea", 8), V.front_view(1), "ea", "physical", camera="perspective")


def test_training_data_is_rendered_with_the_training_camera(tmp_path):
    """A run that trains through a pinhole learns from a collection rendered through the same
    pinhole: the config's camera reaches the collection spec, and the cache keeps it apart from
    the orthographic collection of the same settings."""
    from mitsuba_platonic.config import load_config
    from mitsuba_platonic.data.render_collection import load_manifest
    from mitsuba_platonic.train.data import collection_folder, load_training_data

    base = [f"data.cache={tmp_path}", "data.n_shapes=2", "data.views_per_shape=1", "model.resolution=16",
            "render.backend=closed_form"]
    ortho = load_config("configs/quickstart.yaml", base)
    pinhole = load_config("configs/quickstart.yaml", base + ["render.camera=perspective", "render.fov=50"])
    assert collection_folder(ortho) != collection_folder(pinhole)
    load_training_data(pinhole, progress=False)
    spec = load_manifest(collection_folder(pinhole))["spec"]
    assert (spec["camera"], spec["fov"], spec["distance"]) == ("perspective", 50.0, None)
