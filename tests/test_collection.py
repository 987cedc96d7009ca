"""Rendered collections: promised files, a manifest that matches them, resume, bad settings."""


import json

import numpy as np
import pytest
import torch
from PIL import Image

from mitsuba_platonic import render
from mitsuba_platonic.data import shapes
from mitsuba_platonic.data import render_collection as C
from mitsuba_platonic.data.render_collection import CollectionSpec, load_manifest, make_collection
from mitsuba_platonic.images import load_exr, save_exr

CLASS = shapes.list_classes()[0]


def _spec(**kw):
    base = dict(shape_class=CLASS, n_shapes=2, views_per_shape=3, resolution=16, seed=5)
    base.update(kw)
    return CollectionSpec(**base)


def _check_collection(folder, spec):
    m = load_manifest(folder)
    assert m["spec"] == spec.to_dict()
    images = m["images"]
    assert len(images) == spec.n_shapes * spec.views_per_shape
    assert len({r["id"] for r in images}) == len(images)
    assert sorted(p.name for p in (folder / "images").iterdir()) == sorted(r["image"].split("/")[1] for r in images)
    assert sorted(p.name for p in (folder / "exr").iterdir()) == sorted(r["exr"].split("/")[1] for r in images)
    for r in images:
        png = np.asarray(Image.open(folder / r["image"]))
        assert png.dtype == np.uint8 and png.shape == (spec.resolution, spec.resolution, 4)
        exr = load_exr(folder / r["exr"])
        assert exr.shape[-1] in (2, 4)
        assert np.abs(png[..., 3] / 255.0 - exr[..., -1]).max() <= 0.5 / 255 + 1e-6  # same alpha
        assert exr[..., -1].max() > 0.05                                          # the shape is in view
        i, k = r["shape"], int(r["id"].split("_")[1])
        assert torch.allclose(torch.tensor(r["view"]), spec.view(i, k))
        vol = np.load(folder / r["volume"])["volume"]
        assert vol.shape == (4, spec.resolution, spec.resolution, spec.resolution)
        assert torch.equal(torch.from_numpy(vol), shapes.generate(spec.shape_class, r["shape_seed"], spec.resolution))
    return m


@pytest.mark.parametrize("formation,renderer", [("vh", "closed_form"), ("ao", "mitsuba"), ("ea", "closed_form"),
                                                ("ea", "mitsuba"), ("physical", "mitsuba")])
def test_collection_has_the_promised_files(tmp_path, formation, renderer):
    spec = _spec(formation=formation, renderer=renderer, spp=4)
    make_collection(tmp_path, spec, progress=False)
    m = _check_collection(tmp_path, spec)
    vols = sorted((tmp_path / "volumes").glob("*.vol"))
    assert len(vols) == spec.n_shapes
    from mitsuba_platonic.render.variant import ensure_variant
    mi = ensure_variant()                  # a closed-form collection writes its .vol files without Mitsuba
    grid = np.array(mi.VolumeGrid(str(vols[0])))
    assert grid.shape == (16, 16, 16, 4)
    if formation == "physical":
        assert all("lighting" in r and r["exposure"] > 0 for r in m["images"])
        assert len({tuple(r["lighting"]["sun_direction"]) for r in m["images"]}) == len(m["images"])
        # metered: each image's factor is its light's, 1 / (the sky's mean luminance)
        from mitsuba_platonic.render.mitsuba.physical import Lighting, metered_exposure
        for r in m["images"]:
            light = Lighting(**{k: tuple(v) if isinstance(v, list) else v for k, v in r["lighting"].items()})
            assert r["exposure"] == metered_exposure(light)


@pytest.mark.parametrize("formation", ["ao", "ea"])
def test_perspective_collections_render_through_the_pinhole(tmp_path, formation):
    """A perspective collection's EXR images are the shape rendered by the closed form with the
    spec's pinhole from the recorded views (the marcher agrees to 1e-4, tests/test_perspective.py),
    and differ from the orthographic images of the same views; old collection.json files (no
    camera keys) read as orthographic, so their collections are reused, not refused."""
    spec = _spec(formation=formation, camera="perspective", fov=50.0, distance=2.5, n_shapes=1, views_per_shape=2)
    make_collection(tmp_path, spec, progress=False)
    m = _check_collection(tmp_path, spec)
    vol = shapes.generate(spec.shape_class, spec.shape_seed(0), spec.resolution)
    vol = vol if formation == "ea" else vol[3:]
    views = torch.tensor([r["view"] for r in m["images"]])
    pinhole = render(vol[None].expand(2, -1, -1, -1, -1).contiguous(), views, formation, "closed_form",
                     camera="perspective", fov=50.0, distance=2.5)
    ortho = render(vol[None].expand(2, -1, -1, -1, -1).contiguous(), views, formation, "closed_form")
    for j, r in enumerate(m["images"]):
        exr = torch.from_numpy(load_exr(tmp_path / r["exr"])).permute(2, 0, 1)
        assert (exr - pinhole[j]).abs().max() < 1e-5
        assert (exr - ortho[j]).abs().max() > 0.1
    old = _spec().to_dict()
    for key in ("camera", "fov", "distance"):
        del old[key]
    assert CollectionSpec.from_dict(old) == _spec()
    make_collection(tmp_path / "o", _spec(n_shapes=1, views_per_shape=1), progress=False)
    spec_file = tmp_path / "o" / "collection.json"
    spec_file.write_text(json.dumps(old | {"n_shapes": 1, "views_per_shape": 1}))
    make_collection(tmp_path / "o", _spec(n_shapes=1, views_per_shape=1), progress=False)   # no "other settings"


def test_collections_from_before_metering_read_as_auto_exposed():
    """A collection.json written before the ``exposure`` setting existed was auto-exposed per image;
    it reads back as such (so it is not mistaken for a metered one and reused by training)."""
    old = _spec(formation="physical").to_dict()
    del old["exposure"]
    assert CollectionSpec.from_dict(old).exposure == "auto"
    assert CollectionSpec.from_dict(_spec(formation="physical").to_dict()).exposure == "metered"


def test_views_and_seeds_are_deterministic_and_spread():
    spec = _spec(n_shapes=20, views_per_shape=5)
    views = torch.stack([spec.view(i, k) for i in range(20) for k in range(5)])
    assert torch.allclose(views.norm(dim=1), torch.ones(100), atol=1e-5)
    assert len({tuple(v.tolist()) for v in views}) == 100           # one random view per image
    assert torch.equal(views[7], _spec(n_shapes=3).view(1, 2))       # independent of the collection size
    band = _spec(views="band", elevation=(10.0, 30.0))
    y = torch.stack([band.view(0, k) for k in range(50)])[:, 1]
    assert y.min() >= np.sin(np.radians(10)) - 1e-5 and y.max() <= np.sin(np.radians(30)) + 1e-5


def test_a_sides_collection_draws_its_views_within_w_of_the_side_views_at_the_bands_elevations():
    spec = _spec(n_shapes=40, views_per_shape=5, views="sides", elevation=(-10.0, 40.0), side_width=20.0).validate()
    views = torch.stack([spec.view(i, k) for i in range(40) for k in range(5)])
    az = torch.rad2deg(torch.atan2(views[:, 0], views[:, 2])).double()
    near = torch.minimum((az - 90.0).abs(), (az + 90.0).abs())
    assert float(near.max()) <= 20.0 + 1e-3
    assert 60 < int((az > 0).sum()) < 140                        # both sides, about half each (200 views)
    el = torch.rad2deg(torch.asin(views[:, 1].double()))
    assert el.min() >= -10.0 - 1e-3 and el.max() <= 40.0 + 1e-3
    default = _spec(views="sides")                               # no width, no elevation: 30°, the band's
    v = torch.stack([default.view(i, 0) for i in range(2)] + [default.view(0, k) for k in range(3)])
    az = torch.rad2deg(torch.atan2(v[:, 0], v[:, 2])).double()
    assert float(torch.minimum((az - 90.0).abs(), (az + 90.0).abs()).max()) <= 30.0 + 1e-3
    # the spec round-trips, and one made before the setting existed reads as no width
    assert CollectionSpec.from_dict(spec.to_dict()) == spec
    old = _spec().to_dict()
    del old["side_width"]
    assert CollectionSpec.from_dict(old) == _spec()


@pytest.mark.parametrize("bad,match", [
    (dict(views="band", side_width=30.0), "side_width: only views 'sides' reads it"),
    (dict(views="sides", side_width=0.0), "0 < W <= 90"), (dict(views="sides", side_width=120.0), "0 < W <= 90"),
    (dict(views="sides", elevation=20.0), r"'sides' needs elevation=\(low, high\)"),
])
def test_bad_sides_specs(bad, match):
    with pytest.raises(ValueError, match=match):
        _spec(**bad).validate()


def test_cli_make_dataset_sides_and_its_refusals(tmp_path, capsys):
    from mitsuba_platonic.cli import main
    assert main(["make-dataset", "--class", CLASS, "--shapes", "2", "--views", "2", "--resolution", "16",
                 "--view-dist", "sides", "--elevation", "0,20", "--side-width", "15",
                 "--out", str(tmp_path / "d"), "--quiet"]) == 0
    m = load_manifest(tmp_path / "d")
    assert m["spec"]["views"] == "sides" and m["spec"]["side_width"] == 15.0
    az = np.degrees(np.arctan2([r["view"][0] for r in m["images"]], [r["view"][2] for r in m["images"]]))
    assert np.all(np.minimum(np.abs(az - 90.0), np.abs(az + 90.0)) <= 15.0 + 1e-3)
    capsys.readouterr()
    assert main(["make-dataset", "--class", CLASS, "--side-width", "15", "--view-dist", "band",
                 "--out", str(tmp_path / "x")]) == 2
    assert "--side-width: only --view-dist sides reads it" in capsys.readouterr().err
    assert main(["make-dataset", "--class", CLASS, "--view-dist", "sides", "--side-width", "95", "--shapes", "1",
                 "--views", "1", "--resolution", "16", "--out", str(tmp_path / "y")]) == 2
    assert "0 < W <= 90" in capsys.readouterr().err
    assert not (tmp_path / "x").exists() and not (tmp_path / "y" / "images").exists()


@pytest.mark.parametrize("flags, message", [
    (["--formation", "physical", "--renderer", "mitsuba"],
     "--renderer mitsuba: --formation physical always path-traces with Mitsuba and would ignore it; drop it, or "
     "use --formation vh, ao or ea"),
    (["--fov", "60"], "--fov: only --camera perspective reads it, and --camera orthographic would ignore it; "
                      "drop it or add --camera perspective"),
    (["--camera", "orthographic", "--fov", "60", "--distance", "3"],
     "--fov, --distance: only --camera perspective reads them, and --camera orthographic would ignore them"),
])
def test_cli_make_dataset_refuses_flags_its_formation_or_camera_would_ignore(tmp_path, capsys, flags, message):
    """A flag the chosen formation or camera never reads is refused in one line before anything is written."""
    from mitsuba_platonic.cli import main
    out = tmp_path / "d"
    assert main(["make-dataset", "--class", CLASS, "--shapes", "1", "--views", "1", "--resolution", "16",
                 *flags, "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"platonic make-dataset: error: {message}" in err, err
    assert not out.exists()


def test_cli_make_dataset_perspective_takes_fov_and_defaults_the_renderer(tmp_path):
    from mitsuba_platonic.cli import main
    assert main(["make-dataset", "--class", CLASS, "--shapes", "1", "--views", "1", "--resolution", "16",
                 "--camera", "perspective", "--fov", "50", "--out", str(tmp_path / "d"), "--quiet"]) == 0
    spec = load_manifest(tmp_path / "d")["spec"]
    assert spec["fov"] == 50.0 and spec["camera"] == "perspective" and spec["renderer"] == "closed_form"


def test_resume_finishes_without_rerendering(tmp_path, monkeypatch):
    spec = _spec(n_shapes=3, views_per_shape=2)
    calls = []
    real = C._render_shape

    def crash_after_first_shape(spec_, vol, views, lights, *offset):
        calls.append(len(views))
        if len(calls) == 2:
            raise KeyboardInterrupt("simulated crash")
        return real(spec_, vol, views, lights, *offset)

    monkeypatch.setattr(C, "_render_shape", crash_after_first_shape)
    with pytest.raises(KeyboardInterrupt):
        make_collection(tmp_path, spec, progress=False)
    assert not (tmp_path / "manifest.json").exists()
    done = sorted((tmp_path / "images").glob("*.png"))
    assert [p.name for p in done] == ["00000_00.png", "00000_01.png"]
    stamps = {p.name: p.stat().st_mtime_ns for p in done}
    # a torn half-written record and a stray temporary file, as a kill could leave them
    with open(tmp_path / "records.jsonl", "a") as f:
        f.write('{"id": "00001_00", "ima')
    (tmp_path / "images" / ".00001_01.tmp123.png").write_bytes(b"partial")
    (tmp_path / "exr" / "00001_00.exr").unlink(missing_ok=True)

    calls.clear()
    monkeypatch.setattr(C, "_render_shape", lambda *a: (calls.append(len(a[2])), real(*a))[1])
    make_collection(tmp_path, spec, progress=False)
    assert calls == [2, 2]                                      # shapes 1 and 2 only, not shape 0
    assert {p.name: p.stat().st_mtime_ns for p in (tmp_path / "images").glob("0000[0]_*.png")} == stamps
    _check_collection(tmp_path, spec)
    # a finished collection re-run renders nothing
    calls.clear()
    make_collection(tmp_path, spec, progress=False)
    assert calls == []


def test_other_settings_in_the_same_folder_are_refused(tmp_path):
    make_collection(tmp_path, _spec(), progress=False)
    with pytest.raises(ValueError, match="other settings.*resolution"):
        make_collection(tmp_path, _spec(resolution=32), progress=False)
    make_collection(tmp_path, _spec(n_shapes=1, views_per_shape=1), overwrite=True, progress=False)
    assert len(load_manifest(tmp_path)["images"]) == 1
    assert len(list((tmp_path / "images").glob("*.png"))) == 1


def test_envmap_lighting(tmp_path):
    h, w = 16, 32
    sky = np.zeros((h, w, 3), np.float32)
    sky[: h // 2] = [0.6, 0.7, 1.0]          # a blue upper hemisphere
    sky[2, 5] = [500.0, 450.0, 400.0]        # a small bright sun
    env = save_exr(tmp_path / "env.exr", sky)
    spec = _spec(formation="physical", lighting="envmap", envmaps=(str(env),), n_shapes=1, views_per_shape=2, spp=4)
    make_collection(tmp_path / "c", spec, progress=False)
    m = _check_collection(tmp_path / "c", spec)
    assert all(r["lighting"]["kind"] == "envmap" for r in m["images"])


@pytest.mark.parametrize("bad,match", [
    (dict(shape_class="teapot"), "shape_class"), (dict(n_shapes=0), "n_shapes"), (dict(resolution=8), "resolution"),
    (dict(formation="xray"), "formation"), (dict(views="cube"), "views"), (dict(views="band", elevation=(50, 10)), "elevation"),
    (dict(formation="physical", lighting="envmap"), "environment map"), (dict(envmaps=("/nope.exr",)), "does not exist"),
    (dict(exposure="camera"), "exposure"), (dict(camera="fisheye"), "camera"),
    (dict(camera="perspective", fov=180.0), "fov"), (dict(formation="physical", camera="perspective"), "orthographic"),
])
def test_bad_specs(tmp_path, bad, match):
    with pytest.raises(ValueError, match=match):
        make_collection(tmp_path, _spec(**bad), progress=False)


def test_cli_make_dataset_and_preview(tmp_path):
    from mitsuba_platonic.cli import main
    assert main(["make-dataset", "--class", CLASS, "--shapes", "1", "--views", "2", "--resolution", "16",
                 "--out", str(tmp_path / "d"), "--quiet"]) == 0
    assert len(load_manifest(tmp_path / "d")["images"]) == 2
    assert main(["make-dataset", "--preview", "--class", CLASS, "--preview-shapes", "2", "--resolution", "16",
                 "--out", str(tmp_path / "p")]) == 0
    assert (tmp_path / "p" / f"preview_{CLASS}.png").exists()
    assert main(["make-dataset", "--class", "teapot", "--out", str(tmp_path / "x")]) == 2
