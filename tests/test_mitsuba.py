"""The Mitsuba ray marcher against the closed form, finite differences and analytic cases."""

import numpy as np
import pytest
import torch

from mitsuba_platonic import render
from mitsuba_platonic.render.settings import RenderSettings
from mitsuba_platonic import views as V
from mitsuba_platonic.volume import test_volume

MODELS = ["vh", "ao", "ea"]
FILTERS = ["nearest", "trilinear"]
OBLIQUE = V.from_angles(torch.tensor([37.0, -128.0, 75.0]), torch.tensor([23.0, -41.0, 8.0]))


def _pair(model, n=16, kind="figure", batch=1):
    vol = test_volume(n, kind, model).expand(batch, -1, -1, -1, -1).contiguous()
    return vol


def _both(vol, views, model, filter, **options):
    a = render(vol, views, model, "closed_form", filter=filter)
    b = render(vol, views, model, "mitsuba", filter=filter, **options)
    return a, b


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("filter", FILTERS)
@pytest.mark.parametrize("kind", ["figure", "cloud"])
def test_front_view_agrees_with_closed_form(model, filter, kind):
    vol = _pair(model, 32, kind)
    a, b = _both(vol, V.front_view(1), model, filter)
    assert a.shape == b.shape
    assert (a - b).abs().max() <= 1e-5


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("filter", FILTERS)
def test_oblique_views_agree_with_closed_form(model, filter):
    vol = _pair(model, 32, "figure", batch=3)
    a, b = _both(vol, OBLIQUE, model, filter)
    assert (a - b).abs().max() <= 1e-4


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("filter", FILTERS)
@pytest.mark.parametrize("n", [16, 32])                      # 32: the tiled, atomic-free backward
def test_gradients_agree_with_closed_form(model, filter, n):
    vol = _pair(model, n, "cloud", batch=2)
    views = torch.cat([V.front_view(1), OBLIQUE[:1]])
    weights = torch.rand(2, 4 if model == "ea" else 1, n, n)
    grads = []
    for backend in ["closed_form", "mitsuba"]:
        x = vol.clone().requires_grad_()
        (render(x, views, model, backend, filter=filter) * weights).sum().backward()
        grads.append(x.grad)
    rel = (grads[0] - grads[1]).norm() / grads[0].norm()
    assert rel <= 1e-3


@pytest.mark.parametrize("model", ["ao", "ea"])
@pytest.mark.parametrize("step", [0.5, 1.5])
def test_gradients_at_other_steps_match_finite_differences(model, step):
    """The log-domain path (step != 1) has no closed form to compare with: check it against FD."""
    vol = _pair(model, 8, "cloud")
    view = OBLIQUE[:1]
    weights = torch.rand(1, 4 if model == "ea" else 1, 8, 8)

    def f(x):
        return float((render(x, view, model, "mitsuba", step=step) * weights).double().sum())

    x = vol.clone().requires_grad_()
    (render(x, view, model, "mitsuba", step=step) * weights).sum().backward()
    direction = torch.randn_like(vol) * (vol > 0.02)
    ε = 2e-3
    fd = (f((vol + ε * direction).clamp(0, 1)) - f((vol - ε * direction).clamp(0, 1))) / (2 * ε)
    analytic = float((x.grad * direction).sum())
    assert abs(fd - analytic) <= 1e-2 * abs(analytic) + 1e-4


@pytest.mark.parametrize("model", ["ao", "ea"])
def test_error_against_fine_step_reference_falls_monotonically(model):
    vol = _pair(model, 16, "cloud")
    view = OBLIQUE[:1]
    reference = render(vol, view, model, "mitsuba", step=1 / 16)
    errors = [float((render(vol, view, model, "mitsuba", step=s) - reference).abs().mean())
              for s in [4.0, 2.0, 1.0, 0.5]]
    assert all(a > b for a, b in zip(errors, errors[1:])), errors


DENSITIES = [0.0, 1e-8, 0.5, 1 - 1e-7, 1.0]


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("n", [8, 64])
def test_numerical_extremes_stay_finite_and_in_range(model, n):
    c = 4 if model == "ea" else 1
    vols = []
    for d in DENSITIES:  # constant volumes at each extreme density
        x = torch.rand(1, c, n, n, n)
        x[:, -1] = d
        vols.append(x)
    mixed = torch.rand(1, c, n, n, n)
    mixed[:, -1] = torch.tensor(DENSITIES)[torch.randint(0, 5, (n, n, n))]
    vols.append(mixed)
    vol = torch.cat(vols)
    b = vol.shape[0]
    views = torch.tensor([[0.0, 1.0, 0.0], [0.0, -1.0, 0.0]]).repeat(b, 1)[:b]
    views[0] = torch.tensor([0.0, 0.0, 1.0])
    backends = [("closed_form", {}), ("mitsuba", {"step": 1.0}), ("mitsuba", {"step": 0.5, "jitter": True})]
    for backend, opts in backends:
        x = vol.clone().requires_grad_()
        out = render(x, views, model, backend, **opts)
        assert torch.isfinite(out).all() and out.min() >= 0 and out.max() <= 1 + 1e-6, backend
        out.sum().backward()
        assert torch.isfinite(x.grad).all(), (backend, opts)
    # empty → transparent, solid → opaque
    empty = torch.zeros(1, c, n, n, n)
    solid = torch.ones(1, c, n, n, n)
    for backend in ["closed_form", "mitsuba"]:
        assert render(empty, V.front_view(1), model, backend).abs().max() == 0
        full = render(solid, V.front_view(1), model, backend)
        if model == "vh":
            assert torch.allclose(full, torch.full_like(full, 1 - np.exp(-n)), atol=1e-6)
        else:
            assert torch.allclose(full, torch.ones_like(full), atol=1e-6)


@pytest.mark.parametrize("model", MODELS)
def test_poles_agree_with_closed_form(model):
    vol = _pair(model, 16, "figure", batch=2)
    poles = torch.tensor([[0.0, 1.0, 0.0], [0.0, -1.0, 0.0]])
    a, b = _both(vol, poles, model, "trilinear")
    assert (a - b).abs().max() <= 1e-4


def test_each_pair_of_a_batch_renders_and_differentiates_on_its_own():
    """Two renders of one volume in one graph (Algorithm 1's input and random views)."""
    vol = _pair("ea", 16, "figure")
    w1, w2 = V.front_view(1), OBLIQUE[1:2]
    x = vol.clone().requires_grad_()
    (render(x, w1, "ea", "mitsuba").sum() + 2 * render(x, w2, "ea", "mitsuba").sum()).backward()
    y = vol.clone().requires_grad_()
    (render(y, w1, "ea", "closed_form").sum() + 2 * render(y, w2, "ea", "closed_form").sum()).backward()
    assert (x.grad - y.grad).norm() / y.grad.norm() <= 1e-3
    batch = render(torch.cat([vol, vol.flip(2)]), torch.cat([w1, w2]), "ea", "mitsuba")
    alone = render(vol.flip(2), w2, "ea", "mitsuba")
    assert torch.allclose(batch[1:], alone, atol=1e-6)


def test_supersampling_and_jitter():
    vol = _pair("ea", 16, "figure")
    view = OBLIQUE[:1]
    reference = render(vol, view, "ea", "mitsuba", spp=64, step=0.25)
    a = render(vol, view, "ea", "mitsuba", jitter=True, spp=4, seed=1)
    b = render(vol, view, "ea", "mitsuba", jitter=True, spp=4, seed=1)
    c = render(vol, view, "ea", "mitsuba", jitter=True, spp=4, seed=2)
    assert torch.equal(a, b) and not torch.equal(a, c)
    errors = [float((render(vol, view, "ea", "mitsuba", jitter=True, spp=s, seed=3) - reference).abs().mean())
              for s in [1, 16, 256]]
    assert errors[0] > errors[1] > errors[2], errors
    # a regular sub-pixel grid converges to the same image
    assert float((render(vol, view, "ea", "mitsuba", spp=16, step=0.25) - reference).abs().mean()) < errors[0]


def test_early_termination_bias_is_bounded_by_its_threshold():
    vol = _pair("ea", 32, "figure")
    view = OBLIQUE[:1]
    exact = render(vol, view, "ea", "mitsuba")
    for eps in [1e-3, 1e-2]:
        fast = render(vol, view, "ea", "mitsuba", termination=eps)
        assert (fast - exact).abs().max() <= eps + 1e-6


def test_vh_and_ao_read_one_channel_ea_reads_rgba_packets(monkeypatch):
    """The batched marcher gathers from the volume it is given: 1 float per voxel for VH/AO, 4 for EA."""
    import importlib
    M = importlib.import_module("mitsuba_platonic.render.drjit.marcher")
    seen = []
    original = M._Batch.__init__

    def spy(self, data, frames, b, c, n, settings, seed, **kw):
        seen.append((settings.model, c, dr_width(data), b * n ** 3))
        original(self, data, frames, b, c, n, settings, seed, **kw)

    monkeypatch.setattr(M._Batch, "__init__", spy)
    monkeypatch.setattr(M, "FREEZE", False)                  # trace, so the spy sees every call
    for model in MODELS:
        render(_pair(model, 8), V.front_view(1), model, "mitsuba")
    assert [(m, c) for m, c, _, _ in seen] == [("vh", 1), ("ao", 1), ("ea", 4)]
    assert all(width == c * voxels for _, c, width, voxels in seen)


def dr_width(x):
    import drjit as dr
    return dr.width(x)


@pytest.mark.parametrize("model", MODELS)
def test_batched_marcher_equals_the_per_pair_mitsuba_integrator(model):
    """The Mitsuba-scene path (one ``mi.render`` of the ``platonic_raymarch`` integrator per pair)
    and the batched marcher render, and differentiate, the same images."""
    from mitsuba_platonic.render.mitsuba.per_pair import render_mitsuba
    vol = _pair(model, 16, "cloud", batch=3)
    x, y = vol.clone().requires_grad_(), vol.clone().requires_grad_()
    w = torch.rand(3, 4 if model == "ea" else 1, 16, 16)
    a = render_mitsuba(x, OBLIQUE, model)
    b = render(y, OBLIQUE, model, "mitsuba")
    assert (a - b).abs().max() <= 1e-5
    (a * w).sum().backward()
    (b * w).sum().backward()
    assert (x.grad - y.grad).norm() / x.grad.norm() <= 1e-4


@pytest.mark.parametrize("bad, match", [
    ({"step": 0}, "step"), ({"spp": 3}, "perfect square"), ({"spp": 0}, "spp"),
    ({"filter": "cubic"}, "filter"), ({"termination": 1.5}, "termination"), ({"colour": 1}, "unknown option"),
])
def test_bad_options(bad, match):
    vol = _pair("vh", 8)
    with pytest.raises(ValueError, match=match):
        render(vol, V.front_view(1), "vh", "mitsuba", **bad)


def test_nearest_agrees_except_where_a_sample_sits_on_a_voxel_face():
    """Nearest lookups are discontinuous at voxel faces: a sample within float round-off of a face
    may pick either neighbour in either backend. Everywhere else the two agree to round-off;
    such ties are rare (random views, 32³)."""
    from mitsuba_platonic.render.pytorch.closed_form import camera_space_points
    n, b = 32, 8
    vol = _pair("ea", n, "figure", batch=b)
    views = V.sample_views(b, seed=11)
    a, m = _both(vol, views, "ea", "nearest")
    p = camera_space_points(views, n, torch.float64)                  # (B, K, H, W, 3)
    q = (p + 1.0) * (n / 2.0)                                         # voxel faces at integers
    near_face = ((q - q.round()).abs() < 1e-5) & (p.abs() <= 1.0)        # float32 positions err ~2e-6
    tie = near_face.any(-1).any(1)                                    # (B, H, W)
    err = (a - m).abs().amax(1)
    assert err[~tie].max() <= 1e-5
    assert tie.float().mean() < 0.01, float(tie.float().mean())


def test_steady_state_replays_recorded_kernels_without_retracing():
    """A second call with new volumes, views and jitter seed (same batch, resolution and settings)
    replays the frozen passes: no new recording, and the same images as a freshly traced call."""
    import importlib
    M = importlib.import_module("mitsuba_platonic.render.drjit.marcher")
    if not M.FREEZE:
        pytest.skip("MITSUBA_PLATONIC_FREEZE=0")
    opts = dict(jitter=True, spp=2, step=0.75)                 # a configuration no other test uses
    x = _pair("ea", 16, "cloud", batch=2).requires_grad_()
    render(x, OBLIQUE[:2], "ea", "mitsuba", seed=1, **opts).sum().backward()
    fwd, bwd = M._frozen_forward.n_recordings, M._frozen_backward.n_recordings
    y = _pair("ea", 16, "figure", batch=2).requires_grad_()
    w = torch.rand(2, 4, 16, 16)
    replayed = render(y, OBLIQUE[1:], "ea", "mitsuba", seed=7, **opts)
    (replayed * w).sum().backward()
    assert (M._frozen_forward.n_recordings, M._frozen_backward.n_recordings) == (fwd, bwd)
    M.FREEZE = False
    try:
        z = y.detach().clone().requires_grad_()
        traced = render(z, OBLIQUE[1:], "ea", "mitsuba", seed=7, **opts)
        (traced * w).sum().backward()
    finally:
        M.FREEZE = True
    # the same kernels, up to the order of the gradient's per-thread partial sums
    assert torch.equal(replayed, traced)
    assert torch.allclose(y.grad, z.grad, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("model, n", [("ea", 16), ("ea", 32), ("ao", 32)])   # 32: the tiled backward
def test_a_new_thread_count_records_anew_and_stays_exact(model, n):
    """Kernels recorded under one Dr.Jit thread count are not replayed under another (the backward's
    per-thread gradient copies are sized when recorded): gradients stay equal to the closed form's,
    also with one thread (what training at 32³ uses: every launch on the calling thread alone)."""
    import drjit as dr
    vol = _pair(model, n, "cloud", batch=2)
    views = torch.cat([V.front_view(1), OBLIQUE[:1]])
    w = torch.rand(2, 4 if model == "ea" else 1, n, n)
    before = dr.thread_count()
    grads = {}
    try:
        for threads in (1, before + 1, before):
            dr.set_thread_count(threads)
            for backend in ("closed_form", "mitsuba"):
                x = vol.clone().requires_grad_()
                (render(x, views, model, backend) * w).sum().backward()
                grads[backend] = x.grad
            rel = (grads["closed_form"] - grads["mitsuba"]).norm() / grads["closed_form"].norm()
            assert rel <= 1e-3, (threads, float(rel))
    finally:
        dr.set_thread_count(before)


@pytest.mark.parametrize("model", MODELS)
def test_two_backward_passes_from_one_forward_are_each_right(model):
    """retain_graph: a gradient of the colour, then one of the alpha, from the same render."""
    vol = _pair(model, 16, "cloud", batch=2)
    grads = {}
    for backend in ["closed_form", "mitsuba"]:
        x = vol.clone().requires_grad_()
        out = render(x, OBLIQUE[:2], model, backend)
        first = torch.autograd.grad(out[:, 0].sum(), x, retain_graph=True)[0]
        second = torch.autograd.grad((out[:, -1] * torch.linspace(0, 1, 16)).sum(), x)[0]
        grads[backend] = (first, second)
    for want, got in zip(grads["closed_form"], grads["mitsuba"]):
        assert (want - got).norm() / want.norm() <= 1e-3


def _marcher():
    import importlib
    return importlib.import_module("mitsuba_platonic.render.drjit.marcher")


@pytest.mark.parametrize("n, spp", [(32, 1), (32, 4), (64, 1)])
def test_tiled_lane_order_puts_a_packets_rays_far_apart(n, spp):
    """Every ray once; the 16 lanes of an aligned packet belong to one pair and are ≥ N/4 pixels
    apart along a row or a column (decoded here with numpy, independently of the marcher)."""
    M = _marcher()
    b = 2
    lanes = M.mi.UInt32(np.arange(b * n * n * spp, dtype=np.uint32))
    ray = np.asarray(M.tiled_ray(lanes, n, spp), dtype=np.int64)
    assert np.array_equal(np.sort(ray), np.arange(b * n * n * spp))
    pixel, sub = np.divmod(ray, spp)
    pair, ij = np.divmod(pixel, n * n)
    i, j = np.divmod(ij, n)
    packets = lambda a: a.reshape(-1, 16)                            # noqa: E731
    assert (packets(pair) == packets(pair)[:, :1]).all()
    di = np.abs(packets(i)[:, :, None] - packets(i)[:, None, :])
    dj = np.abs(packets(j)[:, :, None] - packets(j)[:, None, :])
    apart = np.maximum(di, dj) + np.eye(16, dtype=np.int64)[None] * n   # a lane and itself: excluded
    assert apart.min() >= n // 4


@pytest.mark.parametrize("n, spp", [(16, 1), (32, 4), (64, 1)])
def test_tiled_lane_is_the_inverse_of_tiled_ray(n, spp):
    """The forward pass writes ray r's records where lane tiled_lane(r) of the tiled backward reads
    them: tiled_lane ∘ tiled_ray is the identity on every lane of 3 pairs."""
    M = _marcher()
    lanes = np.arange(3 * n * n * spp, dtype=np.uint32)
    ray = M.tiled_ray(M.mi.UInt32(lanes), n, spp)
    assert np.array_equal(np.asarray(M.tiled_lane(ray, n, spp), dtype=np.int64), lanes.astype(np.int64))


@pytest.mark.parametrize("model", ["vh", "ao"])
def test_pair_layout_backward_reaches_every_face_of_the_cube(model):
    """The pair layout (VH/AO's tiled backward) keeps slots for w₀ = −1 and w₀ = N − 1, where one
    voxel of a pair lies outside the cube: a volume dense up to its faces, seen from oblique views,
    gets the Expand scatters' gradient there too (a dropped or misplaced face would differ by a
    whole voxel's contribution)."""
    M = _marcher()
    if not (M.tiled_backward(32, 1) and M.pair_layout(True, 1, RenderSettings(model=model))):
        pytest.skip("the pair layout needs the tiled backward (LLVM backend)")
    b = 3
    vol = torch.rand(b, 1, 32, 32, 32, generator=torch.Generator().manual_seed(2)) * 0.2
    views = torch.tensor([[0.6, 0.5, 0.62], [-0.3, -0.9, 0.3], [0.0, 0.0, 1.0]])
    views = views / views.norm(dim=1, keepdim=True)
    weights = torch.rand(b, 1, 32, 32)

    def gradient(tiled):
        M.TILED = tiled
        try:
            x = vol.clone().requires_grad_()
            (render(x, views, model, "mitsuba") * weights).sum().backward()
        finally:
            M.TILED = True
        return x.grad

    expand = gradient(False)
    for face in [(..., 0), (..., -1), (..., 0, slice(None)), (..., -1, slice(None))]:
        assert (expand[face] != 0).float().mean() > 0.5        # the faces (w = 0, N − 1, …) are seen
    assert (gradient(True) - expand).abs().max() <= 1e-5 * expand.abs().max()


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("filter", FILTERS)
@pytest.mark.parametrize("options", [{}, {"spp": 4, "jitter": True}, {"termination": 0.05, "step": 0.5}],
                         ids=["default", "jittered-spp4", "terminated-half-step"])
def test_tiled_backward_equals_the_expand_backward(model, filter, options):
    """The atomic-free backward (tiled lanes, NoConflicts scatters) gives the gradient of the
    Expand scatters up to float summation order: a lost update would show as a large difference."""
    M = _marcher()
    if not M.tiled_backward(32, options.get("spp", 1)):
        pytest.skip("the tiled backward needs the LLVM backend with packets of ≤ 16 lanes")
    b = 2                                                       # fewer pairs than blocks: padded launch
    vol = _pair(model, 32, "cloud", batch=b)
    views = V.sample_views(b, seed=3)
    weights = torch.rand(b, 4 if model == "ea" else 1, 32, 32)

    def gradient(tiled):
        M.TILED = tiled
        try:
            x = vol.clone().requires_grad_()
            (render(x, views, model, "mitsuba", filter=filter, seed=5, **options) * weights).sum().backward()
        finally:
            M.TILED = True
        return x.grad

    expand = gradient(False)
    assert expand.abs().max() > 0
    for _ in range(3):                                          # a race between threads is intermittent
        assert (gradient(True) - expand).abs().max() <= 1e-5 * expand.abs().max()


def _blobs(model, n, batch):
    """Small dense blobs at different places of each volume (mostly empty space), one volume empty,
    one dense up to a face of the cube."""
    g = torch.Generator().manual_seed(11)
    vol = torch.zeros(batch, 4 if model == "ea" else 1, n, n, n)
    for b in range(batch - 1):
        lo = torch.randint(0, n - 4, (3,), generator=g).tolist()
        vol[b, :, lo[0]:lo[0] + 4, lo[1]:lo[1] + 3, lo[2]:lo[2] + 5] = torch.rand(
            vol.shape[1], 4, 3, 5, generator=g) * 0.9 + 0.05
    vol[0, :, :, :, -2:] = 0.5                                  # dense up to the face w = N − 1
    return vol                                                  # the last volume stays empty


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("options", [{}, {"filter": "nearest"}, {"step": 0.5}, {"step": 2.0},
                                     {"spp": 4, "jitter": True}, {"camera": "perspective", "fov": 50.0},
                                     {"camera": "perspective", "fov": 30.0, "distance": 2.5, "step": 0.5}],
                         ids=["default", "nearest", "half-step", "step-2", "jittered-spp4", "pinhole",
                              "pinhole-near-half-step"])
def test_skipping_empty_space_leaves_the_image_unchanged_to_the_last_bit(model, options):
    """A forward-only call marches only the segments that meet the box around its pair's occupied
    voxels; a call that records for the gradient marches every segment. Their images are equal
    bit for bit (a box one voxel too tight would cut a trilinear footprint and differ)."""
    n, batch = 16, 5
    vol = _blobs(model, n, batch)
    views = torch.cat([V.front_view(1), OBLIQUE[:1], V.sample_views(batch - 2, seed=4)])
    M = _marcher()
    boxes = M.occupied_boxes(vol)
    assert (boxes[-1, :3] > boxes[-1, 3:]).all()                # the empty volume: an empty box
    with torch.no_grad():
        skipped = render(vol, views, model, "mitsuba", seed=3, **options)
    whole = render(vol.clone().requires_grad_(), views, model, "mitsuba", seed=3, **options).detach()
    assert skipped.abs().max() > 0
    assert torch.equal(skipped, whole)
    assert (skipped[-1] == 0).all()


def test_a_box_that_cuts_the_trilinear_footprint_is_caught():
    """The equality above can fail: widening the boxes by less than a voxel changes the image."""
    M = _marcher()
    vol = _blobs("ea", 16, 3)
    views = OBLIQUE[:1].expand(3, -1).contiguous()
    exact = M.occupied_boxes
    try:
        M.occupied_boxes = lambda v: exact(v) + torch.tensor([1.0, 1.0, 1.0, -1.0, -1.0, -1.0]) * (1.4 * 2 / 16)
        with torch.no_grad():
            tight = render(vol, views, "ea", "mitsuba")
    finally:
        M.occupied_boxes = exact
    with torch.no_grad():
        right = render(vol, views, "ea", "mitsuba")
    assert not torch.equal(tight, right)


def test_a_second_backward_through_the_scene_path_raises_instead_of_repeating_the_first():
    """drjit.wrap's render releases its AD graph in the first backward: a second gradient from the
    same render (retain_graph) used to return the first one again, silently."""
    from mitsuba_platonic.render.mitsuba.per_pair import render_mitsuba
    vol = _pair("ea", 8, "cloud", batch=2)
    views = V.sample_views(2, seed=3)
    x = vol.clone().requires_grad_()
    image = render_mitsuba(x, views, "ea")
    w1, w2 = torch.rand_like(image), torch.rand_like(image)
    first = torch.autograd.grad((image * w1).sum(), x, retain_graph=True)[0]
    y = vol.clone().requires_grad_()
    fresh = torch.autograd.grad((render_mitsuba(y, views, "ea") * w1).sum(), y)[0]
    assert torch.allclose(first, fresh, rtol=1e-5, atol=1e-7)   # the first gradient is right
    with pytest.raises(RuntimeError, match="differentiated once"):
        torch.autograd.grad((image * w2).sum(), x)
    image = render_mitsuba(x, views, "ea")                      # a loss using the image twice: one backward
    ((image * w1).sum() + (image * w2).sum()).backward()
    assert x.grad is not None and x.grad.abs().max() > 0


@pytest.mark.parametrize("model", MODELS)
def test_gradients_of_successive_calls_are_separate_tensors(model):
    """The gradient is handed to torch in Dr.Jit's memory (a second backward launch writes it in
    torch's layout): later calls, which replay the same recorded kernels, must not write into an
    earlier call's gradient, and torch may add into it in place (a leaf's .grad accumulates)."""
    g = torch.Generator().manual_seed(0)
    c = 4 if model == "ea" else 1
    grads, copies = [], []
    for _ in range(3):
        x = (torch.rand(8, c, 32, 32, 32, generator=g) * 0.3).requires_grad_()
        render(x, V.sample_views(8, "sphere", seed=g), model, "mitsuba").sum().backward()
        grads.append(x.grad)
        copies.append(x.grad.clone())
    assert len({t.data_ptr() for t in grads}) == 3
    grads[0].add_(1.0)
    assert torch.equal(grads[0], copies[0] + 1.0)
    assert all(torch.equal(a, b) for a, b in zip(grads[1:], copies[1:]))
    assert all(t.shape == (8, c, 32, 32, 32) and t.is_contiguous() for t in grads)


@pytest.mark.parametrize("model, n, step", [("ea", 16, 1.0), ("ea", 32, 0.5), ("ao", 32, 1.0), ("ao", 16, 0.75)])
def test_the_backward_reading_the_recorded_lookups_equals_one_that_looks_up_again(monkeypatch, model, n, step):
    """The backward pass reads each segment's lookup as the forward pass recorded it; the same
    gradient comes out of a backward pass that makes the 8 gathers again (tiled at 32³ with step 1,
    per-thread copies otherwise), on a volume with exact 0s and 1s."""
    import importlib
    M = importlib.import_module("mitsuba_platonic.render.drjit.marcher")
    vol = _pair(model, n, "cloud", batch=2)
    vol[:, -1, : n // 4] = 1.0                                 # opaque slabs and empty ones
    vol[:, -1, -n // 4:] = 0.0
    views = torch.cat([V.front_view(1), OBLIQUE[:1]])
    w = torch.rand(2, 4 if model == "ea" else 1, n, n)
    grads, images = {}, {}
    for recorded in (True, False):
        monkeypatch.setattr(M, "RECORD_LOOKUPS", recorded)
        x = vol.clone().requires_grad_()
        images[recorded] = render(x, views, model, "mitsuba", step=step)
        (images[recorded] * w).sum().backward()
        grads[recorded] = x.grad
    assert torch.equal(images[True], images[False])
    assert torch.allclose(grads[True], grads[False], rtol=1e-5, atol=1e-7), \
        float((grads[True] - grads[False]).abs().max())


def test_a_differentiable_render_too_large_to_record_is_refused_with_its_size(monkeypatch):
    """Before it allocates: the message gives rays, segments and the GiB the records would take
    (T_k and the lookup beside it, 5 floats per ray and segment for EA)."""
    import importlib
    M = importlib.import_module("mitsuba_platonic.render.drjit.marcher")
    monkeypatch.setattr(M, "RECORD_LIMIT", 16 * 16 * 16 * 5 - 1)
    x = _pair("ea", 16, "cloud", batch=1).requires_grad_()
    with pytest.raises(ValueError, match=r"256 rays × 16 segments records 0\.0 GiB"):
        render(x, V.front_view(1), "ea", "mitsuba")
    assert render(x.detach(), V.front_view(1), "ea", "mitsuba").shape == (1, 4, 16, 16)


def test_the_ea_gradient_comes_back_channels_last_as_the_generator_computes():
    """EA's gradient is handed to torch in the layout it was scattered in (channels last, no
    conversion launch); VH's and AO's in torch's default layout. The values are the closed form's."""
    for model in ("ea", "ao"):
        vol = _pair(model, 16, "cloud", batch=2)
        x = vol.clone().requires_grad_()
        y = vol.clone().requires_grad_()
        w = torch.rand(2, 4 if model == "ea" else 1, 16, 16)
        g = torch.autograd.grad((render(x, OBLIQUE[:2], model, "mitsuba") * w).sum(), x)[0]
        ref = torch.autograd.grad((render(y, OBLIQUE[:2], model, "closed_form") * w).sum(), y)[0]
        assert g.is_contiguous(memory_format=torch.channels_last_3d) if model == "ea" else g.is_contiguous()
        assert (g - ref).norm() / ref.norm() <= 1e-3
