"""The orthographic camera's window (zoom and pan, render/window.py) in every renderer the viewer offers.

Each renderer is checked three ways, on 16³ volumes made here:

- zoom: a 2× window is the centre of the unzoomed frame, enlarged: against the unzoomed frame
  upsampled 2× (bilinear: the upsampled pixel centres are the zoomed pixel centres exactly) and
  cropped to its centre, within a tolerance per renderer (below) on a smooth volume; and, where
  the same rays exist without a window, against them: the marcher's 2N² frame (its sub-pixel rays
  kept apart, :func:`~mitsuba_platonic.render.drjit.marcher.march_pixels`) cropped, to float round-off;
- pan: a window moved by k whole pixels shows the unmoved frame shifted by k pixels (the same
  rays), and a window moved by (c_x, c_y) moves a small object's centroid by −(c_x, c_y) m N/2
  pixels (columns; rows the other way, row 0 at the top);
- independently: the closed form of a volume whose content is scaled and moved here (sampled
  from its formula) against the zoomed and panned closed form of the original; the marcher
  against the closed form under the same window (images and gradients); single scattering's
  zoom against its torch reference (tests/scatter_reference.py) with the frame scaled; the path
  tracer's sensor rays against the window's formula.

Tolerances, each measured and then given a margin (measured values in the tests' comments):
upsampling the unzoomed frame interpolates the *image* where the zoomed frame samples the *volume*,
so they differ by the image's curvature: a smooth Gaussian blob keeps that small. The path tracer is
compared on a low-noise measure (its radiance centroid and spread), as its pixels are Monte Carlo.
"""

from __future__ import annotations

import math

import pytest
import torch
import torch.nn.functional as F

from mitsuba_platonic.errors import UserError
from mitsuba_platonic.render import RenderSettings, Window, render_with
from mitsuba_platonic.render.pytorch.closed_form import render_closed_form
from mitsuba_platonic.render.window import window_or_none
from mitsuba_platonic.views import camera_frames, from_angles
from mitsuba_platonic.volume import voxel_centres

N = 16
OBLIQUE = from_angles(30.0, 20.0)[None].float()                 # (1, 3)
FRONT = torch.tensor([[0.0, 0.0, 1.0]])


def blob(n: int = N, centre=(0.0, 0.0, 0.0), sigma: float = 0.3, peak: float = 0.35,
         transform=None) -> torch.Tensor:
    """An RGBA ``(1, 4, N, N, N)`` Gaussian blob of density ``peak`` exp(−|p − centre|²/2σ²), a colour
    varying across it; ``transform`` maps voxel centres q to the point p of the formula read there."""
    q = voxel_centres(n)
    p = q if transform is None else transform(q)
    r2 = ((p - torch.tensor(centre, dtype=torch.float64)) ** 2).sum(-1)
    density = peak * torch.exp(-r2 / (2 * sigma ** 2))
    colour = torch.stack([0.6 + 0.3 * torch.tanh(p[..., 0]), 0.5 + 0.3 * torch.tanh(p[..., 1]),
                          0.5 + 0.3 * torch.tanh(p[..., 2])])
    return torch.cat([colour, density[None]]).float()[None].clamp(0.0, 1.0)


def settings(backend: str, model: str = "ea", **options) -> RenderSettings:
    return RenderSettings.for_call(backend, model, **options)


def crop_of_upsampled(image: torch.Tensor) -> torch.Tensor:
    """The centre half of a ``(B, C, N, N)`` frame upsampled 2× (bilinear, pixel centres): pixel j
    of the result sits at x = (−1 + (j + ½)Δ)/2, a 2× window's pixel j."""
    n = image.shape[-1]
    big = F.interpolate(image, scale_factor=2, mode="bilinear", align_corners=False)
    return big[..., n // 2:n // 2 + n, n // 2:n // 2 + n]


def centroid(weight: torch.Tensor) -> torch.Tensor:
    """(row, column) centroid of a non-negative ``(H, W)`` weight, in pixels."""
    h, w = weight.shape
    total = weight.sum()
    rows = (weight.sum(1) * torch.arange(h, dtype=weight.dtype)).sum() / total
    cols = (weight.sum(0) * torch.arange(w, dtype=weight.dtype)).sum() / total
    return torch.stack([rows, cols])


def expected_shift(window: Window, n: int = N) -> torch.Tensor:
    """(rows, columns) a window's pan moves the picture by: (+c_y, −c_x) m N/2 (module docstring)."""
    cx, cy = window.centre
    return torch.tensor([cy, -cx], dtype=torch.float64) * window.zoom * n / 2


# --------------------------------------------------------------------------- the window itself


@pytest.mark.parametrize("zoom", [0.0, -2.0, math.nan, math.inf, -math.inf, True, "2", None])
def test_a_zoom_that_is_not_a_finite_positive_number_is_a_clear_value_error(zoom):
    with pytest.raises(ValueError, match=r"zoom: expected a finite magnification > 0, got"):
        Window(zoom)


@pytest.mark.parametrize("centre", [(math.nan, 0.0), (0.0, math.inf), (1.0,), "ab", (0.0, 0.0, 0.0), None])
def test_a_centre_that_is_not_two_finite_numbers_is_a_clear_value_error(centre):
    with pytest.raises(ValueError, match=r"centre"):
        Window(2.0, centre)


def test_the_full_window_is_no_window_and_others_are_refused_where_they_cannot_be_drawn():
    assert window_or_none(None) is None and window_or_none(Window()) is None
    assert window_or_none(Window(1, (0, 0))) is None and window_or_none(Window(2.0)) == Window(2.0)
    assert Window(4.0).half_width == 0.25 and Window(2.0, (0.5, 0.0)).image_point((0.5, 0.25)) == (0.0, 0.5)
    with pytest.raises(ValueError, match="window: expected a Window"):
        window_or_none((2.0, 0.0, 0.0))
    v = blob()
    with pytest.raises(UserError, match="orthographic"):
        render_with(v, FRONT, settings("closed_form", camera="perspective"), window=Window(2.0))
    with pytest.raises(UserError, match="single_scatter backend renders the whole cross-section"):
        render_with(v, FRONT, settings("single_scatter"), window=Window(2.0))
    a = render_with(v, OBLIQUE, settings("closed_form"))
    assert torch.equal(render_with(v, OBLIQUE, settings("closed_form"), window=Window()), a)


# --------------------------------------------------------------------------- the closed form


def _window_map(window: Window, view: torch.Tensor):
    """The map q → L(q) = o + h (q·right) right + h (q·up) up + (q·ω) ω: the closed form of the volume
    sampled at L(voxel centres), with no window, is the closed form of the original under ``window``."""
    right, up, w = (f[0] for f in camera_frames(view))
    _, _, o = window.frames(right, up)
    h = window.half_width

    def transform(q: torch.Tensor) -> torch.Tensor:
        return (o + h * (q @ right)[..., None] * right + h * (q @ up)[..., None] * up + (q @ w)[..., None] * w)
    return transform


@pytest.mark.parametrize("view", [FRONT, OBLIQUE], ids=["front", "oblique"])
@pytest.mark.parametrize("zoom, offset", [(2.0, (0.0, 0.0)), (2.0, (0.06, -0.04)), (3.0, (-0.03, 0.02)),
                                          (0.5, (0.2, 0.1))])
def test_the_closed_form_in_a_window_is_the_closed_form_of_the_volume_scaled_and_moved(view, zoom, offset):
    """Independent of the renderer's window: the content of a 32³ blob scaled by m and moved by −o
    across the camera's axis, sampled here from its formula, and rendered whole, against the blob
    rendered through the window. The window is centred near the blob (the point P), so that the
    scaled blob stays inside the cube (outside it the whole render sees nothing: zero padding). The
    two differ by their trilinear reads of two different grids: measured max 0.022, mean 0.0041
    (3×, the narrowest grid blob: 1.9 voxels); tolerances 0.04 and 0.008."""
    n, P = 32, torch.tensor([0.15, -0.2, 0.1], dtype=torch.float64)
    right, up, _ = (f[0] for f in camera_frames(view.double()))
    window = Window(zoom, (float(P @ right) + offset[0], float(P @ up) + offset[1]))
    sigma = 0.12 if zoom >= 1 else 0.25                            # ≥ 2 voxels in both grids
    shape = dict(centre=tuple(P.tolist()), sigma=sigma, peak=0.35)
    ours = render_closed_form(blob(n, **shape), view, "ea", window=window)
    theirs = render_closed_form(blob(n, transform=_window_map(window, view.double()), **shape), view, "ea")
    d = (ours - theirs).abs()
    assert float(d.max()) < 0.04 and float(d.mean()) < 0.008, (float(d.max()), float(d.mean()))
    assert float(theirs[:, 3].max()) > 0.5                          # the blob is in the frame
    whole = render_closed_form(blob(n, **shape), view, "ea")
    assert float((whole - theirs).abs().max()) > 0.2                 # and the window changed it


# --------------------------------------------------------------------------- every deterministic renderer

#: The renderers whose frames are deterministic: their backends.
DETERMINISTIC = ["closed_form", "mitsuba", "scatter_march"]


@pytest.mark.parametrize("backend", DETERMINISTIC)
def test_a_2x_zoom_is_the_centre_of_the_unzoomed_frame_upsampled(backend):
    """Measured on the 16³ blob (σ = 2.4 voxels): max 0.015, mean 0.0057 (the image's curvature,
    which bilinear upsampling does not follow); tolerances 0.03 and 0.01. The unzoomed frame itself
    is 0.19 or more from the crop on average (the check sees the zoom; asserted > 0.05)."""
    v = blob()
    for view in (FRONT, OBLIQUE):
        whole = render_with(v, view, settings(backend))
        zoomed = render_with(v, view, settings(backend), window=Window(2.0))
        d = (zoomed - crop_of_upsampled(whole)).abs()
        assert float(d.max()) < 0.03 and float(d.mean()) < 0.01, (float(d.max()), float(d.mean()))
        assert float((whole - crop_of_upsampled(whole)).abs().mean()) > 0.05


@pytest.mark.parametrize("backend", DETERMINISTIC)
def test_a_pan_by_whole_pixels_shifts_the_frame_by_them(backend):
    """A 2× window moved 3 pixels right and 2 down (c = (3, −2) Δ/m) shows the 2× frame moved 3 pixels
    left and 2 up: the same rays, so equal but for float32 round-off of the ray positions
    (measured ≤ 1.8e-7; tolerance 1e-5)."""
    v = blob()
    step = (2.0 / N) / 2.0                                          # a pixel of the 2× window, in world units
    window = Window(2.0, (3 * step, -2 * step))
    assert expected_shift(window).tolist() == [-2.0, -3.0]
    for view in (FRONT, OBLIQUE):
        zoomed = render_with(v, view, settings(backend), window=Window(2.0))
        panned = render_with(v, view, settings(backend), window=window)
        d = (panned[..., :N - 2, :N - 3] - zoomed[..., 2:, 3:]).abs()
        assert float(d.max()) < 1e-5, float(d.max())
        assert float((panned - zoomed).abs().max()) > 0.1


@pytest.mark.parametrize("backend", DETERMINISTIC)
@pytest.mark.parametrize("window", [Window(1.0, (0.23, -0.11)), Window(2.0, (0.13, 0.07)), Window(0.75, (-0.4, 0.3))],
                         ids=["pan", "zoom+pan", "zoom-out+pan"])
def test_a_pan_moves_a_small_objects_centroid_the_other_way(backend, window):
    """A blob of σ = 1 voxel at the centre: its alpha centroid under the window minus under the same
    zoom unpanned is (+c_y, −c_x) m N/2 pixels (rows, columns). Trilinear reads keep a faint
    object's centroid shift exact (they reproduce linear functions); the opacity's curvature
    costs a little: measured ≤ 0.021 pixel; tolerance 0.05 pixel (the shifts: 0.9 to 2.4 pixels)."""
    v = blob(sigma=0.12, peak=0.6)
    for view in (FRONT, OBLIQUE):
        still = centroid(render_with(v, view, settings(backend), window=Window(window.zoom))[0, 3].double())
        moved = centroid(render_with(v, view, settings(backend), window=window)[0, 3].double())
        err = (moved - still - expected_shift(window)).abs().max()
        assert float(err) < 0.05, ((moved - still).tolist(), expected_shift(window).tolist())


# --------------------------------------------------------------------------- the marcher


def test_the_marchers_2x_window_is_the_centre_of_its_2x_finer_frame():
    """Without interpolation: the marcher's 2N² frame keeps its sub-pixel rays apart
    (:func:`march_pixels`), and its central N² are the rays of the 2× window exactly; so are the
    central 2N² of its 4N² frame those of a 2× window at 2N² (here with a pan)."""
    from mitsuba_platonic.render.drjit.marcher import march_pixels

    v = blob()
    for view in (FRONT, OBLIQUE):
        fine = march_pixels(v, view, settings("mitsuba"), 2)
        zoomed = render_with(v, view, settings("mitsuba"), window=Window(2.0))
        assert float((zoomed - fine[..., N // 2:N // 2 + N, N // 2:N // 2 + N]).abs().max()) < 1e-6
        pan = (0.1, 0.05)
        finer = march_pixels(v, view, settings("mitsuba"), 4, window=Window(1.0, pan))
        zoomed = march_pixels(v, view, settings("mitsuba"), 2, window=Window(2.0, pan))
        assert float((zoomed - finer[..., N:3 * N, N:3 * N]).abs().max()) < 1e-6


@pytest.mark.parametrize("model", ["vh", "ao", "ea"])
def test_the_marcher_in_a_window_matches_the_closed_form_in_images_and_gradients(model):
    """The two renderers, each with its own window code (sample positions; the kernels' 12-float
    frames, the tiled backward included), at step 1: the same planes. Measured ≤ 2.4e-7 (images),
    ≤ 1.5e-6 of the gradient's scale; tolerances 1e-5 and 1e-4 × scale."""
    from mitsuba_platonic.render.drjit.marcher import march

    v = blob(sigma=0.25, peak=0.7)
    v = v if model == "ea" else v[:, 3:]
    for view in (FRONT, OBLIQUE):
        for window in (Window(2.0, (0.2, -0.1)), Window(0.6, (0.3, 0.4))):
            a, b = v.clone().requires_grad_(), v.clone().requires_grad_()
            ours = march(b, view, settings("mitsuba", model), 0, window)
            theirs = render_closed_form(a, view, model, window=window)
            assert float((ours - theirs).detach().abs().max()) < 1e-5
            g = torch.randn(theirs.shape, generator=torch.Generator().manual_seed(0))
            (theirs * g).sum().backward()
            (ours * g).sum().backward()
            scale = float(a.grad.abs().max())
            assert scale > 0 and float((a.grad - b.grad).abs().max()) < 1e-4 * scale


# --------------------------------------------------------------------------- single scattering


@pytest.mark.parametrize("zoom", [2.5, 1.3])
def test_single_scattering_zoomed_matches_its_torch_reference_with_the_frame_scaled(monkeypatch, zoom):
    """The Dr.Jit camera pass through a window (no pan) against tests/scatter_reference.py, whose
    camera frame is scaled here by h = 1/m (p = x (h right) + y (h up) + z ω), in image and gradient,
    on test_scatter_march.py's random case and with its tolerances (2e-6; 2e-5 of the scale).
    (Random volumes: a symmetric blob puts samples where ∇σ·ω_k = 0 exactly, the local light's
    kink, where float32 and float64 take different branches of its derivative.)"""
    import scatter_reference
    from test_scatter_march import _random_case

    from mitsuba_platonic.render.drjit.scatter_march import _ScatterMarch, light_packet
    from mitsuba_platonic.render.variant import variant_device

    window = Window(zoom)
    volume, lights, views, light = _random_case()
    packet = light_packet(volume, lights).detach()
    ours_in = packet.to(variant_device(), copy=True).requires_grad_()
    ours = _ScatterMarch.apply(ours_in, views, light, 2, 1, 2.0, window)
    frames = scatter_reference.camera_frames
    monkeypatch.setattr(scatter_reference, "camera_frames",
                        lambda w: (lambda r, u, o: window.frames(r, u)[:2] + (o,))(*frames(w)))
    ref_in = packet.double().requires_grad_()
    ref = scatter_reference.reference_scatter_march(ref_in, views, light, 2, 1, 2.0)
    assert float((ours.detach().double().cpu() - ref).abs().max()) < 2e-6
    whole = _ScatterMarch.apply(packet.to(variant_device()), views, light, 2, 1, 2.0, None)
    assert float((whole.double().cpu() - ref).abs().max()) > 0.01              # the window changed the image
    weights = torch.randn(ref.shape, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    (ours * weights.float().to(ours.device)).sum().backward()
    (ref * weights).sum().backward()
    for c in range(7):                                                # the unused eighth channel has none
        scale = float(ref_in.grad[..., c].abs().max())
        assert scale > 0 and float((ours_in.grad[..., c].double().cpu() - ref_in.grad[..., c]).abs().max()) < 2e-5 * scale


# --------------------------------------------------------------------------- the path tracer


def test_the_path_tracers_sensor_rays_start_in_the_window():
    """The sensor's to_world through a window: the ray through film point (u, v) starts at lateral
    coordinates (c_x + h x, c_y + h y), x = 2u − 1, y = 1 − 2v, and runs along −ω (float32 maths)."""
    from mitsuba_platonic.render.mitsuba.physical import _window_transform
    from mitsuba_platonic.render.variant import ensure_variant

    mi = ensure_variant()
    window = Window(2.5, (0.3, -0.2))
    us, vs = [0.5, 0.75, 0.5, 0.0, 1.0], [0.5, 0.5, 0.25, 1.0, 0.0]
    for view in (FRONT, OBLIQUE):
        right, up, w = (f[0] for f in camera_frames(view.double()))
        sensor = mi.load_dict({"type": "orthographic", "to_world": _window_transform(mi, right, up, w, window),
                               "film": {"type": "hdrfilm", "width": N, "height": N, "rfilter": {"type": "box"}}})
        ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(us, vs), mi.Point2f(0.5, 0.5))
        o = torch.tensor([[float(ray.o[k][i]) for k in range(3)] for i in range(len(us))], dtype=torch.float64)
        d = torch.tensor([[float(ray.d[k][i]) for k in range(3)] for i in range(len(us))], dtype=torch.float64)
        x, y = torch.tensor(us, dtype=torch.float64) * 2 - 1, 1 - 2 * torch.tensor(vs, dtype=torch.float64)
        h, (cx, cy) = window.half_width, window.centre
        torch.testing.assert_close(o @ right, cx + h * x, atol=1e-6, rtol=0)
        torch.testing.assert_close(o @ up, cy + h * y, atol=1e-6, rtol=0)
        torch.testing.assert_close(d @ w, -torch.ones(len(us), dtype=torch.float64), atol=1e-6, rtol=0)


def test_the_path_tracer_zooms_and_pans_its_radiance_and_alpha():
    """Monte Carlo frames (spp 64, oblique view): the alpha (the marcher's, through the window) as the
    deterministic renderers; the radiance of the 2× window against the centre of the unzoomed
    frame upsampled, on average over pixels (measured 0.028: noise, which halves at 4× the spp)
    and over 4×4 blocks (measured ≤ 0.032), tolerances 0.05 and 0.06, where the unzoomed frame
    itself is ≥ 0.1 away on average; and a pan by (0.23, −0.11) moves the radiance's centroid by
    (−0.88, −1.84) pixels: measured within 0.06 (noise, and the frame's edge clipping the wide
    blob's tail, which moves the alpha's centroid 0.052 from the shift); tolerances 0.25 and 0.1."""
    s = settings("physical", physical_spp=64)
    v = blob()
    whole = render_with(v, OBLIQUE, s)
    zoomed = render_with(v, OBLIQUE, s, window=Window(2.0))
    crop = crop_of_upsampled(whole)
    assert float((zoomed[:, 3] - crop[:, 3]).abs().max()) < 0.03
    d = (zoomed - crop)[:, :3]
    assert float(d.abs().mean()) < 0.05 and float(F.avg_pool2d(d, 4).abs().max()) < 0.06, \
        (float(d.abs().mean()), float(F.avg_pool2d(d, 4).abs().max()))
    assert float((whole - crop)[:, :3].abs().mean()) > 0.1
    window = Window(1.0, (0.23, -0.11))
    panned = render_with(v, OBLIQUE, s, window=window)
    moved = centroid(panned[0, :3].sum(0).double()) - centroid(whole[0, :3].sum(0).double())
    assert float((moved - expected_shift(window)).abs().max()) < 0.25, (moved.tolist(), expected_shift(window).tolist())
    alpha = centroid(panned[0, 3].double()) - centroid(whole[0, 3].double())
    assert float((alpha - expected_shift(window)).abs().max()) < 0.1
