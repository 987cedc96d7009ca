"""The Mitsuba scene files in scenes/: each loads and renders with Mitsuba alone, a user's render
of a file is the project's, the path tracer's differentiable scene keeps its fixed majorant, and
the skies baked from ``sunsky`` are lat-long EXRs with the sun where it was asked for."""

import math
from pathlib import Path

import numpy as np
import pytest
import torch

from mitsuba_platonic import render
from mitsuba_platonic import views as V
from mitsuba_platonic.render.mitsuba import sky
from mitsuba_platonic.render.mitsuba.physical import Lighting, _medium_grids, render_physical
from mitsuba_platonic.render.mitsuba.scenes import SCENES, load_scene, write_scene_grids
from mitsuba_platonic.render.variant import ensure_variant
from mitsuba_platonic.volume import test_volume

N = 8
OBLIQUE = V.from_angles(torch.tensor([37.0, -128.0]), torch.tensor([23.0, -41.0]))


def _mi():
    mi = ensure_variant()
    import mitsuba_platonic.render.mitsuba.integrator  # noqa: F401  (the project's integrator, for raymarch*.xml)
    return mi


def _volume():
    """An 8³ RGBA cloud: density up to ~0.9 and a colour that varies across the cube."""
    vol = test_volume(N, "cloud", "ea")[0]
    vol[:3] = torch.linspace(0.2, 0.9, N)[None, :, None, None].expand(3, N, N, N).clone()
    vol[1] = vol[1].flip(1)
    return vol


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """Grid files of the test volume (as a user writes them) and a tiny baked sky."""
    folder = tmp_path_factory.mktemp("scene_inputs")
    grids = write_scene_grids(_volume(), folder)
    grids["envmap"] = sky.bake_sky(folder / "sky.exr", elevation=40.0, turbidity=3.0, width=32)
    return {k: str(v) for k, v in grids.items()}


def _render_alone(mi, path, params):
    """What a user does: ``mi.load_file`` with string parameters, then ``mi.render``."""
    obj = mi.load_file(str(path), **{k: str(v) for k, v in params.items()})
    camera = {"type": "perspective", "fov": 60, "film": {"type": "hdrfilm", "width": N, "height": N}}
    if isinstance(obj, mi.Emitter):                 # an emitter file: seen by a tiny camera
        obj = mi.load_dict({"type": "scene", "emitter": obj, "integrator": {"type": "path"}, "sensor": camera})
    elif not obj.sensors() or obj.integrator() is None:    # a file of emitters only (sun_and_sky.xml)
        parts = {f"emitter_{i}": e for i, e in enumerate(obj.emitters())}
        obj = mi.load_dict({"type": "scene", **parts, "integrator": {"type": "path"}, "sensor": camera})
    return np.array(mi.render(obj, seed=0))


def _file_params(files):
    """Each scene file with the parameters of one tiny render (several for physical.xml's skies)."""
    raymarch = dict(density=files["density"], resolution=N, scale=N / 2, spp=1)
    physical = dict(sigma_t=files["sigma_t"], albedo=files["albedo"], resolution=N, spp=4, max_depth=3)
    return {
        "raymarch.xml": [dict(raymarch, model="ao"), dict(raymarch, model="vh", step=0.5)],
        "raymarch_ea.xml": [dict(raymarch, albedo=files["albedo"])],
        "physical.xml": [physical, dict(physical, integrator="prbvolpath", sun_direction="0, 0.5, 0.8"),
                         dict(physical, lighting="envmap", envmap=files["envmap"], rotation=30),
                         dict(physical, lighting="sun_and_sky", max_depth=2, sunlight_direction="0, -0.6, -0.8")],
        "emitters/sunsky.xml": [dict(turbidity=5)],
        "emitters/envmap.xml": [dict(envmap=files["envmap"])],
        "emitters/sun_and_sky.xml": [dict(sky_radiance="0.2, 0.3, 0.4")],
    }


def test_every_scene_file_loads_and_renders_with_mitsuba_alone(files):
    mi = _mi()
    table = _file_params(files)
    found = sorted(str(p.relative_to(SCENES)) for p in SCENES.rglob("*.xml"))
    assert found == sorted(table)                    # a new file needs its row here
    for name, runs in table.items():
        for params in runs:
            image = _render_alone(mi, SCENES / name, params)
            assert image.shape[:2] == (N, N) and np.isfinite(image).all(), (name, params)
            assert image[..., :3].max() > 0, (name, params)


@pytest.mark.parametrize("model", ["ao", "ea"])
def test_a_users_raymarch_render_is_the_projects(files, model):
    """``raymarch*.xml`` loaded with Mitsuba alone from the .vol files renders the front view as
    the renderer does (the batched marcher)."""
    mi = _mi()
    vol = _volume() if model == "ea" else _volume()[3:]
    params = dict(density=files["density"], resolution=N, scale=N / 2, spp=1)
    if model == "ea":
        image = _render_alone(mi, SCENES / "raymarch_ea.xml", dict(params, albedo=files["albedo"]))
    else:
        image = _render_alone(mi, SCENES / "raymarch.xml", dict(params, model=model))
    ours = render(vol[None], V.front_view(1), model, "mitsuba")[0].permute(1, 2, 0).numpy()
    if model == "ea":
        assert np.abs(image[..., :4] - ours).max() <= 1e-5
    else:
        assert np.abs(image[..., :3] - ours).max() <= 1e-5


def test_a_users_physical_render_is_the_projects(files):
    """``physical.xml`` loaded with Mitsuba alone (string parameters, .vol grids) renders the
    image ``render_physical`` makes of the same volume, view, sky and seed."""
    mi = _mi()
    view = OBLIQUE[:1]
    _, up, w = V.camera_frames(view)
    light = Lighting(sun_direction=(0.5, 0.6, -0.3), turbidity=4.0)
    fmt = lambda v: ", ".join(repr(float(x)) for x in v)      # noqa: E731
    mine = _render_alone(mi, SCENES / "physical.xml", dict(
        sigma_t=files["sigma_t"], albedo=files["albedo"], resolution=N, spp=4, max_depth=8,
        origin=fmt(3.0 * w[0]), up=fmt(up[0]), sun_direction=fmt(light.sun_direction), turbidity=4.0))
    theirs, _ = render_physical(_volume()[None], view, [light], spp=4, seed=0, exposure="none")
    assert np.abs(mine - theirs[0, :3].permute(1, 2, 0).numpy()).max() <= 1e-6 * np.abs(mine).max()


# -- the path tracer's differentiable scene ------------------------------------------------------

def test_the_ad_scene_keeps_its_fixed_majorant_when_grids_are_bound():
    """render_physical_ad's scene (scenes/physical.xml) bounds σ_t by a fixed majorant, headroom ×
    the largest σ_t a density below V_MAX_PHYSICAL gives, not by the maximum of the grid bound to it
    (which changes every step)."""
    import drjit as dr

    from mitsuba_platonic.render.mitsuba.physical import MAJORANT_HEADROOM, V_MAX_PHYSICAL, _ad_scene

    mi = _mi()
    σ_max = MAJORANT_HEADROOM * -math.log(1.0 - V_MAX_PHYSICAL) / (2.0 / N)
    scene, _ = _ad_scene(N, 4, 4, "trilinear")
    σ, albedo = _medium_grids(_volume())
    params = mi.traverse(scene)
    params["volume.interior_medium.sigma_t.data"] = mi.TensorXf(σ)
    params["volume.interior_medium.albedo.data"] = mi.TensorXf(albedo)
    params.update()
    assert float(σ.max()) < σ_max
    majorant = scene.shapes()[0].interior_medium().get_majorant(dr.zeros(mi.MediumInteraction3f))
    assert np.isclose(float(majorant[0][0]), σ_max, rtol=1e-6)


# -- baked skies ----------------------------------------------------------------------------

def _pixel_direction(image, index):
    j, i = index
    h, w = image.shape[:2]
    return sky.latlong_direction(np.array((i + 0.5) / w), np.array((j + 0.5) / h))


@pytest.mark.parametrize("elevation, azimuth, turbidity", [(35.0, 0.0, 3.0), (20.0, 120.0, 6.0),
                                                           (65.0, -75.0, 2.0)])
def test_a_baked_sky_is_a_latlong_exr_with_the_sun_where_asked(tmp_path, elevation, azimuth, turbidity):
    from mitsuba_platonic.data.render_collection import check_envmap
    from mitsuba_platonic.images import exr_channel_names

    mi = _mi()
    path = sky.bake_sky(tmp_path / "sky.exr", elevation, turbidity, azimuth=azimuth, width=64)
    check_envmap(path)                                   # what envmap lighting accepts
    assert set("RGB") <= set(exr_channel_names(path))
    bitmap = mi.Bitmap(str(path))
    assert bitmap.component_format() == mi.Struct.Type.Float32    # the sun is far above half's range
    image = np.array(bitmap, dtype=np.float64)
    assert image.shape == (32, 64, 3) and np.isfinite(image).all() and image.min() >= 0
    sun = np.array(sky.sun_direction(elevation, azimuth))
    # the brightest pixel holds the sun: within a pixel of it
    brightest = np.unravel_index(np.argmax(image.sum(-1)), image.shape[:2])
    assert math.degrees(math.acos(_pixel_direction(image, brightest) @ sun)) <= math.hypot(180 / 32, 360 / 64)
    # the brightest region sits at the sun: the sunward hemisphere holds most of the light
    h, w = image.shape[:2]
    jj, ii = np.meshgrid(np.arange(h), np.arange(w), indexing="ij")
    d = sky.latlong_direction((ii + 0.5) / w, (jj + 0.5) / h)
    dω = (2 * np.pi / w) * (np.pi / h) * np.sin(np.pi * (jj + 0.5) / h)
    power = image.sum(-1) * dω
    assert power[d @ sun > 0].sum() > 2 * power[d @ sun <= 0].sum()
    # Mitsuba's envmap, given the file, sends the most light from (within a pixel of) the sun
    emitter = load_scene("emitters/envmap", envmap=path)
    radiance = sky._radiance(emitter, d.reshape(-1, 3)).sum(-1)
    assert math.degrees(math.acos(d.reshape(-1, 3)[np.argmax(radiance)] @ sun)) <= math.hypot(180 / 32, 360 / 64)
    # the sun's power is the disk's: its radiance times its solid angle (within a few per cent)
    disk = math.pi * math.radians(sky.SUN_APERTURE / 2) ** 2
    sun_only = load_scene("emitters/sunsky", sun_direction=tuple(sun), turbidity=turbidity)
    params = mi.traverse(sun_only)
    params["sky_scale"] = 0.0
    params.update()
    expected = sky._radiance(sun_only, sun[None])[0] * disk
    sky_only = sky._radiance(load_scene("emitters/sunsky", sun_direction=tuple(sun), turbidity=turbidity),
                             d.reshape(-1, 3)).reshape(h, w, 3)
    hot = (image - sky_only).sum(-1) > 1.0                        # where the sun adds to the sky
    measured = ((image - sky_only) * dω[..., None])[hot].sum(0)
    assert np.allclose(measured, expected, rtol=0.05)


def test_baked_envmaps_bake_once_and_light_a_render(tmp_path):
    paths = sky.baked_envmaps(tmp_path, skies=((30.0, 3.0),), width=32)
    assert [Path(p).name for p in paths] == ["sunsky_elev30_turb3.exr"]
    stamp = Path(paths[0]).stat().st_mtime_ns
    assert sky.baked_envmaps(tmp_path, skies=((30.0, 3.0),), width=32) == paths
    assert Path(paths[0]).stat().st_mtime_ns == stamp                    # found, not baked again
    light = Lighting("envmap", envmap=paths[0], rotation=90.0)
    images, exposures = render_physical(_volume()[None], V.front_view(1), [light], spp=4, max_depth=3)
    assert images.shape == (1, 4, N, N) and torch.isfinite(images).all() and images[:, :3].max() > 0
    # the default sky of scenes/emitters/envmap.xml is one of the baked ones
    default = (SCENES / "emitters" / "envmap.xml").read_text()
    assert any(f"envmaps/{sky.sky_name(e, t)}" in default for e, t in sky.SKIES)
