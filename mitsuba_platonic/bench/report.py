"""``platonic bench``'s outputs: the markdown tables, the Pareto plots (image error vs time), the
files of a run (:func:`write_outputs`) and the generated section of docs/speed_accuracy.md (:func:`write_doc`)."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple

from ..files.fileio import atomic_write, write_text

__all__ = ["markdown_tables", "pareto_plot", "write_outputs", "write_doc", "DOC_BEGIN", "DOC_END"]

#: Markers around the generated section of docs/speed_accuracy.md.
DOC_BEGIN = "<!-- platonic bench: generated section, begin -->"
DOC_END = "<!-- platonic bench: generated section, end -->"


# --------------------------------------------------------------------------- outputs


def _fmt(x: Any, spec: str) -> str:
    return "–" if x is None else format(x, spec)


def _config_name(row: Dict[str, Any]) -> str:
    return f"**{row['config']}**" if row.get("default") else row["config"]


def markdown_tables(result: Dict[str, Any], plot_dir: Optional[str] = None) -> str:
    """The measured rows as Markdown: one table per resolution and model, then training speed.

    ``plot_dir``: a relative folder to link the Pareto plots from (None: no links).
    """
    meta = result["meta"]
    lines = [
        f"Measured {meta['started']} on {meta['machine']} ({meta['cpu_count']} CPUs; torch {meta['torch']} with "
        f"{meta['torch_threads']} threads, Mitsuba {meta['mitsuba']} `{meta['variant']}` with "
        f"{meta['drjit_threads']} Dr.Jit threads); batch {meta['settings']['batch']} of random views, "
        f"built-in volume `{meta['settings']['volume']}`, best of {meta['repeats_used']} after a warm-up; "
        f"memory bandwidth (tensor copy) {meta['bandwidth_gb_s']:.2f} GB/s; the whole run took "
        f"{meta.get('duration_s', 0.0) / 60:.1f} min.",
        "",
        "Times are per image. *mem*: peak RSS increase of a forward+backward call. *RMSE*, *max*: image error "
        "against the reference (the marcher at step 0.25, spp 16, regular); *cos*, *rel*: cosine and relative "
        "error ‖g − g_ref‖/‖g_ref‖ of the gradient of a random-weighted loss; *bound*: the memory-traffic lower "
        "bound of forward+backward, and the measured time over it. The default is in bold. The authors' layer, "
        "the path tracer and single scattering (torch and Dr.Jit) are other image formations: the first is "
        f"compared with our reference, the second with itself at spp {meta['physical_ref_spp_used']} (measured up "
        f"to {meta['settings'].get('physical_max_resolution', 64)}³), the third with itself at 8 samples per voxel "
        f"(up to {meta['settings'].get('single_scatter_max_resolution', 32)}³), the fourth (*scatter march*) "
        f"in RGB with Mitsuba's volpath at max_depth 2 and spp {meta['settings'].get('scatter_ref_spp', 256)} "
        f"(whose own noise is part of its RMSE), in α and gradient with itself at 8 samples per voxel, spp 4 "
        f"(up to {meta['settings'].get('scatter_march_max_resolution', 64)}³).",
        "",
    ]
    rows = result["rows"]
    keys: List[Tuple[int, str]] = []
    for r in rows:
        if (r["resolution"], r["model"]) not in keys:
            keys.append((r["resolution"], r["model"]))
    for n, model in keys:
        lines += [f"### {model.upper()} at {n}³", "",
                  "| configuration | fwd ms | f+b ms | mem MB | RMSE | max | cos | rel | bound ms | ×bound |",
                  "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for r in rows:
            if (r["resolution"], r["model"]) != (n, model):
                continue
            if r.get("skipped"):
                lines.append(f"| {_config_name(r)} | skipped: {r['skipped']} |||||||||")
                continue
            lines.append(
                f"| {_config_name(r)} | {_fmt(r['fwd_ms'], '.3f')} | {_fmt(r['fwd_bwd_ms'], '.3f')} | "
                f"{_fmt(r['mem_fwd_bwd_mb'], '.1f')} | {_fmt(r['rmse'], '.2e')} | {_fmt(r['max_abs'], '.2e')} | "
                f"{_fmt(r['grad_cosine'], '.5f')} | {_fmt(r['grad_rel_err'], '.2e')} | "
                f"{_fmt(r['bound_fwd_bwd_ms'], '.4f')} | {_fmt(r['fwd_bwd_over_bound'], '.0f')} |")
        if plot_dir is not None:
            lines += ["", f"![{model.upper()} {n}³: image error vs time]({plot_dir}/pareto_{model}_{n}.png)"]
        lines.append("")
    if result.get("train"):
        t = result["train"][0]
        lines += [f"### Training speed (the quickstart's step: reconstruction, EA, width {t['width']}, batch "
                  f"{t['batch']}, {t['steps']} steps after {t['warmup_steps']} warm-up)", "",
                  "Shares of a step's time: the renderer (forward and backward), the optimisers' steps, and "
                  "the networks (everything else: E, G, D forward and backward, losses, R1, the moving average).", "",
                  "| N | renderer | Dr.Jit threads | s/step | images/s | vs closed form | renderer (of it backward) | "
                  "networks | optimiser |", "|---:|---|---:|---:|---:|---:|---:|---:|---:|"]
        for t in result["train"]:
            threads = "—" if t.get("drjit_threads") is None else t["drjit_threads"]
            if t.get("skipped"):
                lines.append(f"| {t['resolution']} | {t['config']} | {threads} | skipped: {t['skipped']} ||||||")
            else:
                lines.append(f"| {t['resolution']} | {t['config']} | {threads} | {t['s_per_step']:.3f} | "
                             f"{t['images_per_s']:.1f} | {t['vs_closed_form']:.2f}× | {t['renderer_share']:.0%} "
                             f"({t['renderer_backward_share']:.0%}) | {t['networks_share']:.0%} | "
                             f"{t['optimiser_share']:.0%} |")
        lines.append("")
    return "\n".join(lines)


def _place_labels(ax, points: List[Tuple[float, float, str, str]], fontsize: float = 7.0) -> None:
    """Label each (x, y, text, colour) point without overlaps: a label that would cover one already
    placed moves up in steps of one line, with a leader line back to its point."""
    fig = ax.figure
    fig.canvas.draw()                                         # fixes the axes' transforms
    to_px = ax.transData.transform
    line = fontsize * 1.35 * fig.dpi / 72.0
    char = fontsize * 0.55 * fig.dpi / 72.0
    placed: List[Tuple[float, float, float, float]] = []
    for x, y, text, colour in sorted(points, key=lambda p: (to_px((p[0], p[1]))[1], to_px((p[0], p[1]))[0])):
        px, py = to_px((x, y))
        x0, y0 = px + 6.0, py + 2.0
        w = char * len(text)
        shift = 0
        while any(x0 < bx1 and bx0 < x0 + w and y0 + shift * line < by1 and by0 < y0 + (shift + 1) * line
                  for bx0, by0, bx1, by1 in placed) and shift < 40:
            shift += 1
        box = (x0, y0 + shift * line, x0 + w, y0 + (shift + 1) * line)
        placed.append(box)
        ax.annotate(text, (x, y), xytext=(6.0 * 72.0 / fig.dpi, (2.0 + shift * line) * 72.0 / fig.dpi),
                    textcoords="offset points", fontsize=fontsize, color=colour, va="bottom",
                    arrowprops=dict(arrowstyle="-", color="0.6", lw=0.5) if shift else None)


def _log_axes(ax, xs: Sequence[float], ys: Sequence[float]) -> None:
    """Log-log axes spanning the data with room for labels (at least a factor 4 on each axis),
    ticks at 1, 2, 5 × 10^k labelled in plain numbers."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter  # lazy: matplotlib is slow to import

    ax.set_xscale("log")
    ax.set_yscale("log")
    for values, setter, axis, room in ((xs, ax.set_xlim, ax.xaxis, (1.25, 2.2)), (ys, ax.set_ylim, ax.yaxis, (1.4, 1.6))):
        if not values:
            continue
        lo, hi = min(values) / room[0], max(values) * room[1]
        if hi / lo < 4.0:
            mid = math.sqrt(lo * hi)
            lo, hi = mid / 2.0, mid * 2.0
        setter(lo, hi)
        axis.set_major_locator(LogLocator(base=10.0, subs=(1.0, 2.0, 5.0)))
        axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        axis.set_minor_formatter(NullFormatter())
    ax.grid(True, which="major", alpha=0.3)
    ax.grid(True, which="minor", alpha=0.1)


def pareto_plot(rows: List[Dict[str, Any]], path: Path, title: str) -> Path:
    """Image RMSE vs forward+backward ms per image (log-log) of one (resolution, model).

    Left: our image formation (closed form, marcher configurations, plain layer) against the
    converged reference, with its Pareto front (no other point is both faster and more accurate).
    Right, when present: the other image formations (the authors' layer against our reference, the
    path tracer against its own high-spp render), on their own axes.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # lazy: matplotlib is slow to import, only for figures
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    done = [r for r in rows if not r.get("skipped") and r.get("rmse") is not None]
    ours = [r for r in done if r["formation"] == "ours"]
    others = [r for r in done if r["formation"] != "ours"]
    floor = 1e-9                                              # log axes: an exact 0 is drawn here
    fig = Figure(figsize=(12.0 if others else 8.5, 6.0), dpi=110)
    FigureCanvasAgg(fig)
    if others:
        gs = fig.add_gridspec(1, 2, width_ratios=[2.6, 1.0])
        ax, ax2 = fig.add_subplot(gs[0, 0]), fig.add_subplot(gs[0, 1])
    else:
        ax, ax2 = fig.add_subplot(1, 1, 1), None
    labels = []
    for r in ours:
        x, y = r["fwd_bwd_ms"], max(r["rmse"], floor)
        if r.get("default"):
            ax.scatter([x], [y], marker="*", s=260, color="tab:red", zorder=4)
        elif r["renderer"] == "closed_form":
            ax.scatter([x], [y], marker="s", s=60, color="tab:green", zorder=3)
        elif r["renderer"] == "plain":
            ax.scatter([x], [y], marker="D", s=45, color="tab:purple", zorder=3)
        else:
            ax.scatter([x], [y], marker="o", s=40, color="tab:blue", zorder=3)
        labels.append((x, y, r["config"], "black"))
    pts = sorted((r["fwd_bwd_ms"], max(r["rmse"], floor)) for r in ours)
    front, best = [], float("inf")
    for x, y in pts:
        if y < best:
            front.append((x, y))
            best = y
    if len(front) > 1:
        ax.plot([p[0] for p in front], [p[1] for p in front], color="tab:blue", alpha=0.35, lw=1.5, zorder=1,
                drawstyle="steps-post")
    for a, sel in ((ax, ours), (ax2, others)):
        if a is not None:
            _log_axes(a, [r["fwd_bwd_ms"] for r in sel], [max(r["rmse"], floor) for r in sel])
            a.set_xlabel("forward + backward, ms per image")
    ax.set_ylabel("image RMSE vs reference (marcher step 0.25, spp 16)")
    ax.set_title(title, fontsize=10)
    handles = [Line2D([], [], marker="*", ls="", color="tab:red", ms=14, label="marcher default"),
               Line2D([], [], marker="o", ls="", color="tab:blue", label="marcher, one option varied"),
               Line2D([], [], marker="s", ls="", color="tab:green", label="closed form (reference mode)"),
               Line2D([], [], color="tab:blue", alpha=0.35, lw=1.5, label="Pareto front")]
    if any(r["renderer"] == "plain" for r in ours):
        handles.insert(3, Line2D([], [], marker="D", ls="", color="tab:purple", label="plain layer"))
    if any(r["rmse"] < floor for r in ours):
        handles.append(Line2D([], [], ls="", label=f"RMSE 0 drawn at {floor:g}"))
    ax.legend(handles=handles, fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.11), ncol=3, frameon=False)
    if ax2 is not None:
        for r in others:
            x, y = r["fwd_bwd_ms"], max(r["rmse"], floor)
            ax2.scatter([x], [y], marker="o", s=40, facecolors="none", edgecolors="dimgrey", zorder=3)
        ax2.set_title("other image formations\nauthors' layer: vs our reference\n"
                      "path tracer: vs its own high-spp render\nsingle scattering: vs 8 samples per voxel\n"
                      "scatter march: vs volpath, max_depth 2", fontsize=8)
        ax2.set_ylabel("image RMSE vs its reference")
        fig.tight_layout()
        _place_labels(ax2, [(r["fwd_bwd_ms"], max(r["rmse"], floor), r["config"], "dimgrey") for r in others])
    fig.tight_layout()
    _place_labels(ax, labels)
    atomic_write(path, lambda tmp: fig.savefig(tmp))       # whole or not at all, never through a link
    return path


def write_outputs(result: Dict[str, Any], out: Path) -> Dict[str, Any]:
    """Write ``bench.json``, ``bench.md`` and the Pareto plots into ``out``; return their paths."""
    out = Path(out)
    js = write_text(out / "bench.json", json.dumps(result, indent=1, allow_nan=False))
    plots = []
    keys = []
    for r in result["rows"]:
        if (r["resolution"], r["model"]) not in keys:
            keys.append((r["resolution"], r["model"]))
    for n, model in keys:
        sel = [r for r in result["rows"] if (r["resolution"], r["model"]) == (n, model)]
        plots.append(pareto_plot(sel, out / f"pareto_{model}_{n}.png",
                                 f"{model.upper()} at {n}³, batch {result['meta']['settings']['batch']}: "
                                 f"image error vs forward+backward time"))
    md = write_text(out / "bench.md", "# platonic bench\n\n" + markdown_tables(result, plot_dir=".") + "\n")
    return {"json": js, "markdown": md, "plots": plots}


def write_doc(result: Dict[str, Any], doc: Path, plots: Sequence[Path]) -> Path:
    """Replace the generated section of ``doc`` (between :data:`DOC_BEGIN` and :data:`DOC_END`) with
    the tables, and copy the plots into ``<doc folder>/<doc stem>/`` to link them from there."""
    doc = Path(doc)
    text = doc.read_text()
    if DOC_BEGIN not in text or DOC_END not in text:
        raise ValueError(f"{doc} has no generated section: it needs the lines {DOC_BEGIN!r} and {DOC_END!r}")
    folder = doc.parent / doc.stem
    folder.mkdir(parents=True, exist_ok=True)
    for p in plots:
        shutil.copyfile(p, folder / Path(p).name)
    head, rest = text.split(DOC_BEGIN, 1)
    _, tail = rest.split(DOC_END, 1)
    body = markdown_tables(result, plot_dir=doc.stem)
    doc.write_text(f"{head}{DOC_BEGIN}\n\n{body}\n{DOC_END}{tail}")
    return doc
