"""Closed form vs Mitsuba: render one volume from several views with both backends and compare.

For each image formation model the volume is rendered (one batch, one view per batch entry)
by ``render(..., backend="closed_form")`` and ``render(..., backend="mitsuba")`` with the same
lookup filter. Reported per model:

- ``max_abs_diff`` / ``mean_abs_diff``: over all pixels, channels and views (EA: premultiplied
  R, G, B and A).
- ``closed_form_ms`` / ``mitsuba_ms``: forward-only wall time per image, the best of
  ``repeats`` timed runs after one untimed warm-up run (which absorbs Mitsuba's kernel
  compilation and scene building), measured with :func:`time.perf_counter` around a whole batch
  and divided by the batch size. ``ratio`` = ``mitsuba_ms / closed_form_ms``.

Files written to ``out_dir`` (when given): ``compare_<model>.png`` (one row per view:
closed form | Mitsuba | |difference| heat map with a colour bar) and
``mitsuba_<model>_view<i>.exr`` (the Mitsuba render, float32, with its alpha channel; channel
names as in :func:`mitsuba_platonic.images.save_exr`: ``R, G, B, A`` for EA, ``Y, A`` for
VH/AO, where ``A`` is the opacity).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Sequence, Union

import numpy as np
import torch

from ..errors import UserError
from ..files.fileio import atomic_write, make_folder, write_text
from ..images import composite, heatmap, save_exr, to_hwc
from ..runtime.budget import available_memory
from ..runtime.progress import progress_bar
from ..views import front_view, sample_views, to_angles, validate_views
from ..volume import CHANNELS
from ..render import MODELS, render
from ..render.settings import OPTIONS_OF, RenderSettings
from ..render.variant import ensure_variant
from .timing import time_render

__all__ = ["compare", "format_table", "DISPLAY_BACKGROUND", "HEATMAP_CMAP",
           "memory_estimate", "available_memory", "check_memory", "comparison_views", "write_summary"]

#: Grey level EA renders (premultiplied RGBA) are composited over for display.
DISPLAY_BACKGROUND = 0.5
#: Colour map of the |difference| heat maps.
HEATMAP_CMAP = "inferno"
_MITSUBA_ONLY = (set(OPTIONS_OF["mitsuba"]) - {"filter"}) | {"seed"}   # the marcher's options, and its seed

#: Peak memory per voxel of a comparison (bytes, measured with ``platonic compare`` on CPU at 64³–128³
#: and rounded up): rendering takes about ``RENDER_BYTES + VIEW_BYTES × views`` (the volume, its
#: expanded copies, the renderers' buffers); building a built-in test volume takes ``BUILTIN_BYTES``
#: at its peak (float64 coordinates and shape fields), before rendering starts.
RENDER_BYTES, VIEW_BYTES, BUILTIN_BYTES = 64, 48, 330
#: The most views a comparison figure shows (one row each; the rest are in the EXRs and the numbers).
FIGURE_VIEWS = 8


def memory_estimate(n: int, views: int, builtin: bool = False) -> int:
    """Estimated peak memory (bytes) of comparing an ``n``³ volume from ``views`` views (``builtin``:
    including building a built-in test volume): ``n³ × max(BUILTIN_BYTES, RENDER_BYTES + VIEW_BYTES × views)``."""
    return int(n) ** 3 * max(BUILTIN_BYTES if builtin else 0, RENDER_BYTES + VIEW_BYTES * int(views))


def check_memory(n: int, views: int, builtin: bool = False, what: Optional[str] = None) -> None:
    """Raise :class:`~mitsuba_platonic.errors.UserError` (one line: the estimate, what is available
    and the largest resolution that fits) if :func:`memory_estimate` exceeds :func:`available_memory`.
    ``what`` names the input in the message (e.g. ``'--resolution 1000'``)."""
    need = memory_estimate(n, views, builtin)
    have, source = available_memory()
    if have is None or need <= have:
        return
    per_voxel = need / int(n) ** 3
    largest = (max(have, 0) / per_voxel) ** (1.0 / 3.0)
    fit_views = _most_views(n, views, builtin, have)
    fewer = (f"at most {fit_views} view(s) fit at {n}³ (--views), or " if fit_views else
             f"not even one view fits at {n}³; ")
    raise UserError(f"{what or f'a {n}³ volume'} with --views {views}: comparing {views} view(s) at {n}³ needs "
                    f"about {need / 1e9:.3g} GB of memory (an estimate), more than the {max(have, 0) / 1e9:.1f} GB "
                    f"available ({source}); {fewer}the largest resolution that fits {views} view(s) is about "
                    f"{int(largest)}")


def _most_views(n: int, views: int, builtin: bool, have: float) -> int:
    """The most views (< ``views``) whose :func:`memory_estimate` at ``n`` fits in ``have`` bytes; 0 if none."""
    lo, hi = 0, views - 1
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if memory_estimate(n, mid, builtin) <= have:
            lo = mid
        else:
            hi = mid - 1
    return lo


def _model_volume(volume: torch.Tensor, model: str, batch: int) -> torch.Tensor:
    """The channels ``model`` needs (VH/AO: the density, the last channel), expanded to ``batch``."""
    v = volume if CHANNELS[model] == volume.shape[1] else volume[:, -1:]
    return v.expand(batch, -1, -1, -1, -1)


def _check_inputs(volume: torch.Tensor, views: torch.Tensor, models: Sequence[str],
                  options: Mapping[str, Any]) -> torch.Tensor:
    if not isinstance(volume, torch.Tensor):
        raise UserError(f"volume must be a torch.Tensor, got {type(volume).__name__}")
    if volume.dim() == 4:
        volume = volume[None]
    if volume.dim() != 5 or volume.shape[0] != 1:
        raise UserError(f"volume must have shape (C, N, N, N) or (1, C, N, N, N), got {tuple(volume.shape)}")
    if volume.shape[1] not in (1, 4):
        raise UserError(f"volume must have 1 channel [density] or 4 [r, g, b, density], "
                        f"got {volume.shape[1]}")
    validate_views(views)
    if views.shape[0] < 1:
        raise UserError("at least one view is needed")
    if isinstance(models, str):
        raise UserError(f"models must be a sequence of model names, e.g. ('vh', 'ao', 'ea'), got {models!r}")
    if not models:
        raise UserError("at least one model is needed")
    for m in models:
        if m not in MODELS:
            raise UserError(f"unknown model {m!r}; expected some of {MODELS}")
        if CHANNELS[m] > volume.shape[1]:
            raise UserError(f"model {m!r} needs {CHANNELS[m]} channels [r, g, b, density], "
                            f"the volume has {volume.shape[1]} [density]")
    if len(set(models)) != len(models):
        raise UserError(f"models repeat: {tuple(models)}")
    unknown = set(options) - _MITSUBA_ONLY
    if unknown:
        raise UserError(f"unknown Mitsuba option(s) {sorted(unknown)}; expected some of "
                        f"{sorted(_MITSUBA_ONLY)} (pass the filter as filter=...)")
    return volume


def _figure(model: str, cf: torch.Tensor, mi: torch.Tensor, views: torch.Tensor, title: str, path: Path) -> None:
    """One row per view: closed form | Mitsuba | |difference| heat map with a colour bar."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # lazy: matplotlib is slow to import, only for figures
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure

    b = cf.shape[0]
    azimuth, elevation = to_angles(views)
    fig = Figure(figsize=(10.5, 3.1 * b + 0.9), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(b, 3, squeeze=False)
    ea = model == "ea"
    for i in range(b):
        a, m = to_hwc(cf[i]), to_hwc(mi[i])
        diff = np.abs(a.astype(np.float64) - m.astype(np.float64)).max(axis=2)
        if ea:
            shown = [composite(a, DISPLAY_BACKGROUND), composite(m, DISPLAY_BACKGROUND)]
            kw = {}
        else:
            shown = [a[..., 0], m[..., 0]]
            kw = {"cmap": "gray", "vmin": 0.0, "vmax": 1.0}
        vmax = float(diff.max()) if diff.max() > 0 else 1e-12
        for j, img in enumerate(shown):
            axes[i, j].imshow(img, interpolation="nearest", **kw)
        axes[i, 2].imshow(heatmap(diff, vmax=vmax, cmap=HEATMAP_CMAP), interpolation="nearest")
        bar = fig.colorbar(ScalarMappable(Normalize(0.0, vmax), cmap=HEATMAP_CMAP), ax=axes[i, 2],
                           fraction=0.046, pad=0.04)
        bar.formatter.set_powerlimits((-2, 2))
        bar.update_ticks()
        bar.set_label("|closed form − Mitsuba|")
        axes[i, 0].set_ylabel(f"view {i}\nazimuth {float(azimuth[i]):.1f}°\n"
                              f"elevation {float(elevation[i]):.1f}°", fontsize=10)
        axes[i, 2].set_title(f"max {diff.max():.2e}, mean {diff.mean():.2e}", fontsize=9)
        for ax in axes[i]:
            ax.set_xticks([])
            ax.set_yticks([])
    what = "premultiplied RGBA over grey 0.5" if ea else "opacity, black = 0, white = 1"
    axes[0, 0].set_title(f"closed form\n({what})", fontsize=10)
    axes[0, 1].set_title(f"Mitsuba\n({what})", fontsize=10)
    axes[0, 2].set_title(f"|difference| ({'max over R, G, B, A' if ea else 'opacity'})\n"
                         + axes[0, 2].get_title(), fontsize=9)
    fig.suptitle(title, fontsize=11)
    make_folder(path.parent)
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=100))     # whole, and never through a link


def compare(volume: torch.Tensor, views: torch.Tensor, models: Sequence[str] = MODELS,
            filter: str = "trilinear", options: Optional[Mapping[str, Any]] = None,
            out_dir: Union[str, Path, None] = None, repeats: int = 3, progress: bool = False) -> List[Dict[str, Any]]:
    """Render ``volume`` from ``views`` with both backends for each model and compare them.

    Args:
        volume: ``(C, N, N, N)`` or ``(1, C, N, N, N)`` in [0, 1]; C = 4 ``[r, g, b, density]``
            (all models; VH/AO use the density, the last channel) or C = 1 ``[density]``
            (VH/AO only). It is expanded to one batch entry per view.
        views: ``(V, 3)`` unit vectors.
        models: image formation models to compare, a subset of ``('vh', 'ao', 'ea')``.
        filter: 'trilinear' or 'nearest' lookups, for both backends.
        options: Mitsuba-only options passed to ``render`` (``step``, ``spp``, ``jitter``,
            ``termination``, ``seed``); default: the renderer's defaults.
        out_dir: where to write ``compare_<model>.png`` and ``mitsuba_<model>_view<i>.exr``;
            ``None`` writes nothing.
        repeats: timed runs per backend after one warm-up run; the best is reported.
        progress: a progress line on stderr at once (the comparison's size) and after each
            backend's runs and each model's files (:func:`~mitsuba_platonic.runtime.progress.progress_bar`).

    Returns:
        One dict per model: ``model``, ``resolution``, ``views``, ``filter``, ``options``,
        ``max_abs_diff``, ``mean_abs_diff``, ``closed_form_ms``, ``mitsuba_ms``, ``ratio``
        (Mitsuba / closed form), ``png`` (path or None), ``exrs`` (list of paths), and the
        images themselves as ``closed_form`` / ``mitsuba`` (``(V, C, N, N)`` tensors).

    Raises:
        ValueError (:class:`~mitsuba_platonic.errors.UserError`): on invalid volumes, views, models,
            options or ``repeats``, or a comparison whose :func:`memory_estimate` exceeds the memory
            available.
    """
    options = dict(options or {})
    volume = _check_inputs(volume, views, models, options)
    if not isinstance(repeats, int) or isinstance(repeats, bool) or repeats < 1:
        raise UserError(f"repeats must be a positive int, got {repeats!r}")
    try:                                                         # bad options fail before any rendering
        RenderSettings.for_call("mitsuba", "ea", filter=filter, **{k: v for k, v in options.items() if k != "seed"})
    except ValueError as e:
        raise UserError(str(e)) from None
    views = views.to(torch.float32)
    b, n = views.shape[0], volume.shape[-1]
    check_memory(n, b)                                           # and a size that cannot fit, too
    out = Path(out_dir) if out_dir is not None else None
    if out is not None:
        make_folder(out)                                     # fail before rendering, not after
    ensure_variant()                                             # a backend that cannot run: said before any line
    results = []
    steps = len(models) * (3 if out is not None else 2)
    bar = progress_bar(steps, unit="step", desc=f"compare: {b} view(s) at {n}³, {1 + repeats} runs per backend",
                       disable=not progress, every=1.0 / steps, first_line=True)
    for model in models:
        v = _model_volume(volume, model, b)
        cf, cf_s = time_render(lambda: render(v, views, model, "closed_form", filter=filter), repeats)
        bar.set_postfix({"done": f"{model} closed form"})
        bar.update(1)
        mi, mi_s = time_render(lambda: render(v, views, model, "mitsuba", filter=filter, **options), repeats)
        bar.set_postfix({"done": f"{model} Mitsuba"})
        bar.update(1)
        diff = (cf.detach().cpu().double() - mi.detach().cpu().double()).abs()
        result: Dict[str, Any] = {
            "model": model, "resolution": n, "views": b, "filter": filter, "options": dict(options),
            "max_abs_diff": float(diff.max()), "mean_abs_diff": float(diff.mean()),
            "closed_form_ms": 1e3 * cf_s / b, "mitsuba_ms": 1e3 * mi_s / b,
            "ratio": mi_s / cf_s if cf_s > 0 else float("inf"),
            "png": None, "exrs": [], "closed_form": cf.detach().cpu(), "mitsuba": mi.detach().cpu(),
        }
        if out is not None:
            opts = ", ".join(f"{k}={options[k]}" for k in sorted(options)) or "defaults"
            title = (f"{model.upper()} at {n}³, filter={filter}, Mitsuba options: {opts}\n"
                     f"max |diff| {result['max_abs_diff']:.2e}, mean {result['mean_abs_diff']:.2e}; "
                     f"closed form {result['closed_form_ms']:.2f} ms/image, "
                     f"Mitsuba {result['mitsuba_ms']:.2f} ms/image")
            if model == "ea":
                title += "\nEA shown as premultiplied RGBA composited over a mid-grey (0.5) background"
            png = out / f"compare_{model}.png"
            shown = min(b, FIGURE_VIEWS)
            if shown < b:
                title += f"\nthe first {shown} of {b} views (every view's Mitsuba render is an EXR)"
            _figure(model, result["closed_form"][:shown], result["mitsuba"][:shown], views[:shown], title, png)
            result["png"] = str(png)
            for i in range(b):
                exr = out / f"mitsuba_{model}_view{i}.exr"
                img = to_hwc(result["mitsuba"][i])          # EA: R,G,B,A; VH/AO: Y,A (A = opacity)
                atomic_write(exr, lambda tmp: save_exr(tmp, img))
                result["exrs"].append(str(exr))
            bar.set_postfix({"done": f"{model} figure and {b} EXR(s)"})
            bar.update(1)
        results.append(result)
    bar.close()
    return results


def comparison_views(n: int, seed: int = 0) -> torch.Tensor:
    """The views ``platonic compare`` renders from: the front view, then ``n − 1`` random views (``seed``)."""

    return torch.cat([front_view(1), sample_views(n - 1, seed=seed)])


#: The keys of a result that ``compare.json`` keeps (the images stay out).
SUMMARY_KEYS = ("model", "resolution", "views", "filter", "options", "max_abs_diff", "mean_abs_diff",
                "closed_form_ms", "mitsuba_ms", "ratio", "png", "exrs")


def write_summary(path: Union[str, Path], volume: str, views: torch.Tensor, results: Sequence[Mapping[str, Any]],
                  repeats: int) -> Path:
    """``compare.json``: the volume's name, ``repeats``, the view vectors and each result's :data:`SUMMARY_KEYS`."""
    return write_text(path, json.dumps({"volume": volume, "repeats": repeats, "view_vectors": views.tolist(),
                                        "results": [{k: r[k] for k in SUMMARY_KEYS} for r in results]}, indent=2))


def format_table(results: Sequence[Mapping[str, Any]]) -> str:
    """A plain-text table: model | max abs diff | mean abs diff | closed-form ms/image |
    Mitsuba ms/image | ratio (Mitsuba / closed form)."""
    header = ("model", "max abs diff", "mean abs diff", "closed-form ms/image", "Mitsuba ms/image",
              "ratio (Mitsuba/CF)")
    rows = [(r["model"], f"{r['max_abs_diff']:.3e}", f"{r['mean_abs_diff']:.3e}",
             f"{r['closed_form_ms']:.3f}", f"{r['mitsuba_ms']:.3f}", f"{r['ratio']:.2f}")
            for r in results]
    widths = [max(len(h), *(len(row[i]) for row in rows)) if rows else len(h) for i, h in enumerate(header)]
    line = lambda cells: " | ".join(c.ljust(w) if i == 0 else c.rjust(w)  # noqa: E731
                                    for i, (c, w) in enumerate(zip(cells, widths)))
    return "\n".join([line(header), "-+-".join("-" * w for w in widths)] + [line(r) for r in rows])
