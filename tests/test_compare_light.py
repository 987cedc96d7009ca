"""`platonic compare --light` (bench/compare_light.py): single scattering against volpath at depth 2."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch
from scipy.stats import t as student_t

from cli_runner import run_cli
from mitsuba_platonic.bench.compare import comparison_views
from mitsuba_platonic.bench.compare_light import block_z, compare_light, light_cases
from mitsuba_platonic.volume import test_volume

EXTREMES = ("opaque voxels (a cube of 1s in 0s)", "empty volume", "sun at the horizon", "sun behind the camera",
            "sun behind the object", "sky alone")


def test_the_cases_are_the_views_then_the_extremes():
    volume = test_volume(8, "figure", "ea")
    views = comparison_views(2, 0)
    cases = light_cases(volume, views)
    assert [c.name for c in cases] == ["view 0, random daylight", "view 1, random daylight", *EXTREMES]
    by = {c.name: c for c in cases}
    cube = by[EXTREMES[0]].volume[0, 3]
    assert set(cube.unique().tolist()) == {0.0, 1.0}                   # exact 1s beside exact 0s
    assert torch.equal(by["empty volume"].volume, torch.zeros(1, 4, 8, 8, 8))
    front = by["sun behind the camera"].view[0].double()
    assert np.allclose(by["sun behind the camera"].light.sun_direction, front)        # towards the sun = to the camera
    assert np.allclose(by["sun behind the object"].light.sun_direction, -front)
    assert by["sun at the horizon"].light.sun_direction[1] == 0.0                    # y is up
    assert max(by["sky alone"].light.sun_irradiance) == 0.0 and min(by["sky alone"].light.sky_radiance) > 0.0


def test_block_z_of_an_exact_image_follows_student_t():
    """Were the formation exact, z per block is t-distributed with R − 1 degrees of freedom: its
    mean square (R − 1)/(R − 3) and its share beyond ±3 as the t law says, on 8 renders of noise
    about a known image (6,144 blocks)."""
    g = torch.Generator().manual_seed(0)
    truth = 0.2 + torch.rand(3, 128, 128, generator=g)
    renders = truth + 0.05 * torch.randn(8, 3, 128, 128, generator=g, dtype=torch.float32)
    z = block_z(truth, renders.double())
    assert z.shape == (3, 32, 32)
    dof = 7
    assert abs(float((z ** 2).mean()) - dof / (dof - 2)) < 0.1 * dof / (dof - 2)
    assert abs(float((z.abs() > 3).double().mean()) - 2 * student_t.sf(3.0, dof)) < 0.01


def test_block_z_sees_a_one_percent_bias_that_the_noise_hides_per_pixel():
    g = torch.Generator().manual_seed(1)
    truth = 0.5 + 0.1 * torch.rand(3, 64, 64, generator=g)
    renders = truth + 0.05 * torch.randn(16, 3, 64, 64, generator=g)
    z = block_z(1.01 * truth, renders.double())
    assert float((z ** 2).mean()) > 4.0


@pytest.fixture(scope="module")
def small_comparison():
    cases = light_cases(test_volume(16, "figure", "ea"), comparison_views(1, 0))
    return {r["case"]: r for r in compare_light(cases, spp=16, renders=4, progress=False)}


def test_an_empty_volume_agrees_exactly_and_has_finite_gradients(small_comparison):
    r = small_comparison["empty volume"]
    assert r["rel_total"] == 0.0 and r["max_abs"] == 0.0 and r["z2"] == 0.0
    assert r["grad_finite"] and r["grad_fd_rel"] < 1e-2


@pytest.mark.parametrize("case", ["view 0, random daylight", *EXTREMES[:1], *EXTREMES[2:]])
def test_every_case_has_gradients_that_agree_with_finite_differences(small_comparison, case):
    r = small_comparison[case]
    assert r["grad_finite"] and math.isfinite(r["grad_fd"]) and abs(r["grad_fd"]) > 0
    assert r["grad_fd_rel"] < 1e-2, r


@pytest.mark.parametrize("case", ["view 0, random daylight", *EXTREMES[:1], *EXTREMES[2:]])
def test_every_lit_case_is_near_volpath_in_total(small_comparison, case):
    """At 16³ (coarser than any trained volume; docs/rendering.md has the figures at 32³): within 25 %."""
    r = small_comparison[case]
    assert abs(r["rel_total"]) < 0.25, r


def test_the_cli_writes_the_table_the_figure_and_the_summary(tmp_path):
    code, stdout, stderr = run_cli(["compare", "--light", "--resolution", "8", "--views", "1", "--ref-spp", "8",
                                    "--ref-renders", "4", "--out", str(tmp_path)])
    assert code == 0, stderr
    assert "volpath at max_depth 2 (4 renders of 8 spp)" in stdout
    for name in EXTREMES:
        assert name in stdout
    summary = json.loads((tmp_path / "compare_light.json").read_text())
    assert [r["case"] for r in summary["results"]] == ["view 0, random daylight", *EXTREMES]
    assert summary["settings"]["ref_renders"] == 4 and summary["results"][0]["resolution"] == 8
    assert (tmp_path / "compare_light.png").stat().st_size > 10_000


@pytest.mark.parametrize("argv, message", [
    (["--steps-per-voxel", "1"], "--steps-per-voxel: expected an int ≥ 2"),
    (["--ref-renders", "3"], "--ref-renders: expected an int ≥ 4"),
    (["--step", "2"], "--light: --step, --jitter and --filter set the EA marcher"),
    (["--spp", "2"], "--spp: single scattering's rays per pixel: expected a square number"),
])
def test_bad_light_arguments_exit_2(tmp_path, argv, message):
    code, stdout, stderr = run_cli(["compare", "--light", "--resolution", "8", "--views", "1", "--ref-spp", "4",
                                    "--ref-renders", "4", "--out", str(tmp_path / "out")] + argv)
    assert code == 2 and message in stderr and "Traceback" not in stderr, stderr


def test_a_density_only_volume_is_refused_with_light(tmp_path):
    path = tmp_path / "density.npz"
    np.savez(path, volume=np.zeros((1, 8, 8, 8), dtype=np.float32))
    code, _, stderr = run_cli(["compare", "--light", "--volume", str(path), "--out", str(tmp_path / "out")])
    assert code == 2 and "needs colour" in stderr, stderr
