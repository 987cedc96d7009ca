"""Training speed per renderer and resolution: seconds per step of the quickstart's training
(``configs/quickstart.yaml``: reconstruction, EA, He-initialised E and G, a critic of width 32
with R1, the pose head, the moving average), and where a step's time goes.

A step's wall time t splits into three measured parts (:class:`StepClock`):

- **renderer**: every call of the trainer's rendering layer, forward (the call itself; its
  output is a torch tensor, so the Dr.Jit launches have run when it returns) and backward (from
  the moment autograd hands the render its output's gradient to the moment the render hands
  back the volume's: two identity nodes around the render mark them, and autograd's engine
  runs the nodes between them, which are the render's own, without interleaving others);
- **optimiser**: every ``Optimizer.step`` (Adam on E, G, the pose head and D);
- **networks**: the rest, t − renderer − optimiser: E, G and D forward and backward, the
  losses, the R1 penalty, the moving average.

Shares are over the timed steps' total. The data are random images (the speed of a step does
not depend on what the photos show).

:class:`PartClock` splits a step finer, into :data:`PARTS`, each part's forward *and* backward:

- **G**: the volume from the code (``Trainer._volumes``: G's network, the photos' texture volumes
  and their correction, the copies per random view), without the pose head;
- **E**: every call of the encoder (the photos' codes, and the pose term's codes of G's renders);
- **D**: the critics' update (the augmentation both sides share, the forward passes, R1, the
  backward; D's optimiser step excluded) and D's verdict in G's adversarial term;
- **renderer**: every call of the rendering layer, forward and adjoint;
- **priors**: the terms of G's objective that are neither adversarial nor the input view's
  (train/terms.py: colour_tv, colour_offset, depth_spread, turn, solidity, colour_match, pose, light),
  the calls of E and of the pose head in them excluded (they are E's and pose's);
- **pose**: every call of the pose head P (``train.pose: elevation``) and the input view's volume
  tilted to its elevation (``Trainer._input_volume``);
- **optimiser**: every ``Optimizer.step`` and the moving average's update (``train.ema``);
- **other**: the rest of the step: the batch's draws and the photos' augmentation, the input
  view's term, the sum of the terms, zeroing the gradients, autograd's engine between nodes.

The parts sum to the steps' wall time less the clock's own bookkeeping (``overhead``). A part's
forward is the wall time spent inside it (a section entered inside another is the inner one's);
its backward is the time of the autograd nodes its forward created, each node timed by a pre-
and a post-hook on G's backward pass (CPU autograd runs the nodes one at a time on the calling
thread) and given to the part whose forward created it (by sequence number; a parameter's
accumulation to the node that fed it last). The critics' own backward passes run inside D's
update and are D's. Where the renderer is Dr.Jit's, the clock waits for its launches
(``dr.sync_thread``) before it reads the time at the end of each render and of each of its
backward nodes. :func:`bench_parts` measures that split per resolution of a packaged config on
random images and :func:`growth_table` prints it with each part's growth
(benchmarks/step_growth.py).
"""

from __future__ import annotations

import bisect
import time
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import torch

from ..config import Config, ConfigError, load_config
from ..files.resources import config_path
from ..train.data import TrainingData
from ..train.memory_fit import check_model_fits
from ..train.run import training_threads
from ..train.trainer import Trainer

__all__ = ["StepClock", "PartClock", "PARTS", "TERM_PARTS", "PRIOR", "RENDERERS", "bench_train", "random_training_data", "image_channels",
           "bench_parts", "growth_table"]

#: The renderers a training row is measured for: (backend, label, extra overrides).
RENDERERS = [("closed_form", "closed form", []), ("mitsuba", "marcher", []),
             ("scatter_march", "single scattering, Dr.Jit (m 2)", ["render.steps_per_voxel=2"]),
             ("physical", "path tracer spp 1, depth 2", ["render.physical_spp=1", "render.max_depth=2"])]


class _Mark(torch.autograd.Function):
    """Identity whose backward writes the time it runs into ``clock[key]`` (a list)."""

    @staticmethod
    def forward(ctx, x: torch.Tensor, clock: Dict[str, List[float]], key: str) -> torch.Tensor:
        ctx.clock, ctx.key = clock, key
        return x.view_as(x)

    @staticmethod
    def backward(ctx, grad: torch.Tensor):
        ctx.clock[ctx.key].append(time.perf_counter())
        return grad, None, None


class StepClock:
    """Times a :class:`~mitsuba_platonic.train.trainer.Trainer`'s renderer (forward and backward)
    and optimiser steps while it is attached (module docstring); ``totals()`` gives the seconds
    spent in each since the last ``reset()``."""

    def __init__(self, trainer: Trainer):
        self.trainer = trainer
        self._render = trainer.render
        self._steps = {}
        self.reset()
        trainer.render = self._timed_render
        for opt in (trainer.opt_g, trainer.opt_d, trainer.opt_d3):
            if opt is not None:
                self._steps[opt] = opt.step
                opt.step = self._timed_step(opt.step)

    def reset(self) -> None:
        self.forward = 0.0
        self.optimiser = 0.0
        self._marks: Dict[str, List[float]] = {"start": [], "end": []}

    def _timed_render(self, volume: torch.Tensor, views: torch.Tensor, seed: int) -> torch.Tensor:
        if volume.requires_grad:
            volume = _Mark.apply(volume, self._marks, "end")       # its backward runs after the render's
        t0 = time.perf_counter()
        image = self._render(volume, views, seed)
        self.forward += time.perf_counter() - t0
        if image.requires_grad:
            image = _Mark.apply(image, self._marks, "start")       # its backward runs before the render's
        return image

    def _timed_step(self, step: Callable) -> Callable:
        def timed(*args, **kwargs):
            t0 = time.perf_counter()
            out = step(*args, **kwargs)
            self.optimiser += time.perf_counter() - t0
            return out
        return timed

    def totals(self) -> Dict[str, float]:
        """Seconds in the renderer's forward and backward and in the optimisers' steps. A render
        whose image got no gradient (D's update sees a detached image) has a start and no end; each
        end pairs with the latest start before it."""
        backward, starts = 0.0, sorted(self._marks["start"])
        for end in sorted(self._marks["end"]):
            before = [s for s in starts if s <= end]
            if before:
                backward += end - before[-1]
                starts.remove(before[-1])
        return {"renderer_forward": self.forward, "renderer_backward": backward, "optimiser": self.optimiser}

    def detach(self) -> None:
        """Give the trainer back its own renderer and optimiser steps."""
        self.trainer.render = self._render
        for opt, step in self._steps.items():
            opt.step = step


#: The parts of a step :class:`PartClock` times (module docstring), in the order a table lists them.
PARTS = ("G", "E", "D", "renderer", "priors", "pose", "optimiser", "other")

#: The part a term of G's objective (train/terms.py, by name) is timed in; every other term is a prior,
#: timed as ``PRIOR + name`` (``priors:turn``) and summed into "priors" (:meth:`PartClock.totals`).
TERM_PARTS = {"adv2d": "D", "adv3d": "D", "rec": "other", "rec3d": "other"}
PRIOR = "priors:"


class _TimedTerm:
    """A term of G's objective (:class:`~mitsuba_platonic.train.terms.Term`) whose value the clock
    times as part ``part``; named as the term is, which is all the trainer reads of it."""

    def __init__(self, term: Any, clock: "PartClock", part: str):
        self.term, self.name, self._clock, self._part = term, term.name, clock, part

    def __call__(self, ctx: Any, s: Any) -> torch.Tensor:
        return self._clock._inside(self._part, self.term, ctx, s)


class PartClock:
    """Times a :class:`~mitsuba_platonic.train.trainer.Trainer`'s steps by part (:data:`PARTS`,
    module docstring) while it is attached: ``totals()`` gives the seconds of each part since the
    last ``reset()``; ``wall`` the seconds inside the trainer's ``step`` calls and ``overhead`` the
    clock's own bookkeeping in them (Σ parts = wall − overhead), ``steps`` their count."""

    def __init__(self, trainer: Trainer):
        self.trainer = trainer
        self._sync: Optional[Callable[[], None]] = None
        if trainer.cfg.render.backend != "closed_form":
            import drjit as dr       # lazy: a Dr.Jit renderer's launches are waited for
            self._sync = dr.sync_thread
        self._probe = torch.zeros((), requires_grad=True)     # a node made from it reads autograd's sequence number
        self._undo: List[Callable[[], None]] = []
        self._stack: List[str] = []                           # the parts entered; empty outside a step
        self._opened: List[bool] = []                         # per module call: whether its hook entered a part
        self.reset()
        t = trainer
        self._wrap(t, "step", self._timed_step)
        self._wrap(t, "_update_g", self._hooked_update)
        for name, part in (("render", "renderer"), ("render_lit", "renderer"), ("_volumes", "G"),
                           ("_input_volume", "pose"), ("_update_critics", "D"), ("_update_ema", "optimiser")):
            if getattr(t, name, None) is not None:
                self._wrap(t, name, self._section(part))
        for opt in (t.opt_g, t.opt_d, t.opt_d3):
            if opt is not None:
                self._wrap(opt, "step", self._section("optimiser"))
        for name, part in (("E", "E"), ("D", "D"), ("D3", "D"), ("P", "pose")):
            if name in t.nets:
                self._hook_module(t.nets[name], part)
        terms = t.terms
        t.terms = tuple(_TimedTerm(term, self, TERM_PARTS.get(term.name, PRIOR + term.name)) for term in terms)
        self._undo.append(lambda: setattr(t, "terms", terms))

    def reset(self) -> None:
        self.seconds: Dict[str, float] = dict.fromkeys(PARTS, 0.0)
        self.wall, self.overhead, self.steps = 0.0, 0.0, 0
        self._t, self._last = time.perf_counter(), "other"
        self._seqs: List[int] = []                            # sequence numbers where the part changed ...
        self._owners: List[str] = []                          # ... and the part from there on

    def totals(self) -> Dict[str, float]:
        """Seconds per part (:data:`PARTS`) since the last ``reset()``; "priors" the sum of :meth:`priors`."""
        out = {part: self.seconds.get(part, 0.0) for part in PARTS}
        out["priors"] += sum(self.priors().values())
        return out

    def priors(self) -> Dict[str, float]:
        """Seconds per prior term (by its name in train/terms.py) since the last ``reset()``, forward and backward."""
        return {key[len(PRIOR):]: v for key, v in self.seconds.items() if key.startswith(PRIOR)}

    def detach(self) -> None:
        """Give the trainer back its own methods, renderer, optimiser steps, terms and modules."""
        for undo in reversed(self._undo):
            undo()
        self._undo.clear()

    # -- the bookkeeping ----------------------------------------------------------------------

    def _charge(self) -> None:
        """The time since the last change to the part on top."""
        now = time.perf_counter()
        part = self._stack[-1]
        self.seconds[part] = self.seconds.get(part, 0.0) + now - self._t
        self._t = now

    def _bound(self) -> None:
        """Note the sequence number from which the autograd nodes made belong to the part on top
        (the probe's time, since the last change, is overhead)."""
        t0 = self._t
        with torch.enable_grad():
            self._seqs.append(self._probe.view(()).grad_fn._sequence_nr())
        self._owners.append(self._stack[-1])
        self._t = time.perf_counter()
        self.overhead += self._t - t0

    def _enter(self, part: str) -> None:
        self._charge()
        self._stack.append(part)
        self._bound()

    def _leave(self) -> None:
        if self._stack[-1] == "renderer" and self._sync is not None:
            self._sync()                                      # the marcher's launches belong to the render
        self._charge()
        self._stack.pop()
        self._bound()

    def _inside(self, part: str, fn: Callable, *args, **kwargs):
        """``fn(*args, **kwargs)`` timed as ``part`` (inside a step; elsewhere untimed)."""
        if not self._stack:
            return fn(*args, **kwargs)
        self._enter(part)
        try:
            return fn(*args, **kwargs)
        finally:
            self._leave()

    def _owner(self, seq: int) -> str:
        """The part whose forward made the node of sequence number ``seq``."""
        i = bisect.bisect_left(self._seqs, seq) - 1
        return self._owners[i] if i >= 0 else "other"

    # -- what is wrapped ----------------------------------------------------------------------

    def _wrap(self, obj: Any, name: str, timed: Callable[[Callable], Callable]) -> None:
        """Replace ``obj.name`` by ``timed(obj.name)`` until ``detach()``."""
        own, original = name in vars(obj), getattr(obj, name)
        setattr(obj, name, timed(original))
        self._undo.append(lambda: setattr(obj, name, original) if own else delattr(obj, name))

    def _section(self, part: str) -> Callable[[Callable], Callable]:
        return lambda fn: lambda *args, **kwargs: self._inside(part, fn, *args, **kwargs)

    def _hook_module(self, module: torch.nn.Module, part: str) -> None:
        def before(_module, _args):
            self._opened.append(bool(self._stack))
            if self._opened[-1]:
                self._enter(part)

        def after(_module, _args, _output):
            if self._opened.pop():
                self._leave()
        handles = [module.register_forward_pre_hook(before), module.register_forward_hook(after, always_call=True)]
        self._undo.append(lambda: [h.remove() for h in handles])

    def _timed_step(self, step: Callable) -> Callable:
        def timed(*args, **kwargs):
            t0 = time.perf_counter()
            self._stack, self._seqs, self._owners = ["other"], [], []
            self._t = t0
            self._bound()
            try:
                return step(*args, **kwargs)
            finally:
                self._charge()
                self._stack = []
                self.wall += self._t - t0
                self.steps += 1
        return timed

    def _hooked_update(self, update: Callable) -> Callable:
        """G's update, whose backward pass is timed node by node (module docstring)."""
        def hooked(loss: torch.Tensor, *args, **kwargs):
            if self._stack and loss.grad_fn is not None:
                self._charge()
                self._hook_graph(loss.grad_fn)
                now = time.perf_counter()
                self.overhead += now - self._t
                self._t = now
            return update(loss, *args, **kwargs)
        return hooked

    def _hook_graph(self, root: Any) -> None:
        """A pre- and a post-hook on every node of the graph below ``root``: each node's time goes to
        the part that made it (a parameter's accumulation: to the part of the node before it)."""
        seen, todo = {root}, [root]
        while todo:
            node = todo.pop()
            part = None if type(node).__name__ == "AccumulateGrad" else self._owner(node._sequence_nr())
            node.register_prehook(lambda _grads, part=part: self._node_start(part))
            node.register_hook(lambda _inputs, _outputs: self._node_end())
            for child, _ in node.next_functions:
                if child is not None and child not in seen:
                    seen.add(child)
                    todo.append(child)

    def _node_start(self, part: Optional[str]) -> None:
        self._charge()
        self._stack.append(part or self._last)

    def _node_end(self) -> None:
        if self._stack[-1] == "renderer" and self._sync is not None:
            self._sync()
        self._charge()
        self._last = self._stack.pop()


def random_training_data(resolution: int, channels: int = 4, images: int = 64) -> TrainingData:
    """``images`` random images of ``channels`` × ``resolution``² in [0, 0.5) (seed 0), no held-out
    set: what the speed benches train on (a step's speed does not depend on what the images show).
    ``channels``: 4 for EA's RGBA, 1 for VH's and AO's opacity."""
    g = torch.Generator().manual_seed(0)
    return TrainingData(torch.rand(images, channels, resolution, resolution, generator=g) * 0.5,
                        torch.zeros(0, channels, resolution, resolution))


def image_channels(cfg: Config) -> int:
    """The channels of the images ``cfg`` trains on: 1 under VH and AO (opacity), 4 under EA (RGBA)."""
    return 1 if cfg.render.model in ("vh", "ao") else 4


#: The path tracer trains at most at this resolution here (a 64³ step takes most of a minute on 2 cores).
PHYSICAL_MAX_RESOLUTION = 32


def bench_train(resolutions: Sequence[int], width: int, batch: int, steps: int, warmup: int,
                 log: Callable[[str], None], physical: bool = True) -> List[Dict[str, Any]]:
    """Per resolution and renderer (:data:`RENDERERS`; the path tracer only with ``physical`` and
    up to :data:`PHYSICAL_MAX_RESOLUTION`): seconds per quickstart training step and the shares of
    renderer, networks and optimiser (module docstring)."""
    import drjit as dr               # lazy: Dr.Jit only when the bench runs (its variant is set by then)

    rows: List[Dict[str, Any]] = []
    for r in resolutions:
        data = random_training_data(r)
        base = None
        for backend, label, extra in RENDERERS:
            row: Dict[str, Any] = {"renderer": backend, "config": label, "overrides": extra, "resolution": r,
                                   "width": width, "batch": batch, "steps": steps, "warmup_steps": warmup,
                                   "skipped": None}
            if backend == "physical" and (not physical or r > PHYSICAL_MAX_RESOLUTION):
                row["skipped"] = ("no path tracer (--no-physical)" if not physical else
                                  f"the path tracer trains here up to {PHYSICAL_MAX_RESOLUTION}³")
                rows.append(row)
                continue
            try:
                cfg = load_config(config_path("quickstart"),
                                  [f"model.resolution={r}", f"model.width={width}", f"train.batch_size={batch}",
                                   f"render.backend={backend}", *extra])
                trainer = Trainer(cfg, data, torch.device("cpu"))
                with training_threads(cfg):                   # as a training run sets them (run.drjit_threads)
                    row["drjit_threads"] = None if backend == "closed_form" else dr.thread_count()
                    for step in range(warmup):
                        trainer.step(step)
                    clock = StepClock(trainer)
                    t0 = time.perf_counter()
                    for step in range(warmup, warmup + steps):
                        trainer.step(step)
                    total = time.perf_counter() - t0
                    parts = clock.totals()
                    clock.detach()
            except (ValueError, RuntimeError, TypeError, KeyError) as e:
                row["skipped"] = f"{type(e).__name__}: {e}"
                log(f"train {label} {r}³: skipped ({row['skipped']})")
                rows.append(row)
                continue
            per_step = total / steps
            rate = batch * 2 / per_step                        # the random view and the input view
            base = base or rate
            renderer = parts["renderer_forward"] + parts["renderer_backward"]
            row.update({"s_per_step": per_step, "images_per_s": rate, "vs_closed_form": rate / base,
                        "renderer_share": renderer / total, "renderer_backward_share": parts["renderer_backward"] / total,
                        "optimiser_share": parts["optimiser"] / total,
                        "networks_share": max(0.0, total - renderer - parts["optimiser"]) / total})
            rows.append(row)
            log(f"train {label} {r}³: {per_step:.3f} s/step, {rate:.1f} images/s; renderer "
                f"{row['renderer_share']:.0%}, networks {row['networks_share']:.0%}, optimiser {row['optimiser_share']:.0%}")
    return rows


def bench_parts(config: str, resolutions: Sequence[int], steps: int, warmup: int, overrides: Sequence[str] = (),
                log: Callable[[str], None] = print) -> List[Dict[str, Any]]:
    """Per resolution R: the packaged ``config`` at ``--set model.resolution=R`` (then ``overrides``),
    trained on random images of R² (:func:`random_training_data`) on the CPU with the run's thread
    settings: ``warmup`` untimed steps, ``steps`` timed ones (``s_per_step``), then ``steps`` more
    under a :class:`PartClock` (``parts_s``: seconds per step of each of :data:`PARTS`;
    ``clocked_s_per_step`` and ``overhead_s``, the clock's own bookkeeping per step). A resolution
    whose networks and batch cannot fit in the memory free
    (:func:`~mitsuba_platonic.train.memory_fit.check_model_fits`, a lower bound) is skipped, with the reason."""
    import drjit as dr               # lazy: Dr.Jit only when the bench runs

    if steps < 1 or warmup < 0:
        raise ValueError(f"bench_parts: expected steps ≥ 1 and warmup ≥ 0, got {steps} and {warmup}")
    rows: List[Dict[str, Any]] = []
    for r in resolutions:
        # data.path: the recipe's photo folder, never read (the images are random)
        cfg = load_config(config_path(config), [f"model.resolution={r}", "data.path=unused", *overrides])
        row: Dict[str, Any] = {"config": config, "overrides": list(overrides), "resolution": r, "steps": steps,
                               "warmup_steps": warmup, "batch": cfg.train.batch_size, "skipped": None}
        rows.append(row)
        try:
            check_model_fits(cfg, "cpu")
        except ConfigError as e:
            row["skipped"] = str(e)
            log(f"{config} {r}³: skipped ({e})")
            continue
        trainer = Trainer(cfg, random_training_data(r, image_channels(cfg)), torch.device("cpu"))
        drjit = cfg.render.backend != "closed_form"
        with training_threads(cfg):                           # as a training run sets them
            row["torch_threads"] = torch.get_num_threads()
            row["drjit_threads"] = dr.thread_count() if drjit else None
            for step in range(warmup):
                trainer.step(step)
            t0 = time.perf_counter()
            for step in range(warmup, warmup + steps):
                trainer.step(step)
            if drjit:
                dr.sync_thread()
            row["s_per_step"] = (time.perf_counter() - t0) / steps
            clock = PartClock(trainer)
            for step in range(warmup + steps, warmup + 2 * steps):
                trainer.step(step)
            clock.detach()
        row["parts_s"] = {part: seconds / steps for part, seconds in clock.totals().items()}
        row["priors_s"] = {term: seconds / steps for term, seconds in clock.priors().items()}
        row["clocked_s_per_step"], row["overhead_s"] = clock.wall / steps, clock.overhead / steps
        log(f"{config} {r}³: {row['s_per_step']:.3f} s/step; " +
            ", ".join(f"{part} {seconds * 1e3:.1f} ms" for part, seconds in row["parts_s"].items()))
    return rows


def growth_table(rows: Sequence[Dict[str, Any]]) -> str:
    """:func:`bench_parts`' rows as Markdown: per resolution the seconds per step and each part's
    milliseconds per step and share of the clocked step's parts; then how each grew from the
    resolution before (a ratio of times)."""
    head = "| N | s/step | " + " | ".join(PARTS) + " | with the clock: s/step (its bookkeeping) |"
    rule = "|---|---:|" + "---:|" * len(PARTS) + "---:|"
    lines = [head, rule]
    done = [row for row in rows if not row["skipped"]]
    for row in rows:
        if row["skipped"]:
            lines.append(f"| {row['resolution']}³ | skipped: {row['skipped']} |" + " |" * (len(PARTS) + 1))
            continue
        parts, total = row["parts_s"], sum(row["parts_s"].values())
        cells = [f"{parts[p] * 1e3:.1f} ms ({parts[p] / total:.0%})" for p in PARTS]
        lines.append(f"| {row['resolution']}³ | {row['s_per_step']:.3f} | " + " | ".join(cells) +
                     f" | {row['clocked_s_per_step']:.3f} ({row['overhead_s'] * 1e3:.1f} ms) |")
    if len(done) > 1:
        lines += ["", "| growth | s/step | " + " | ".join(PARTS) + " |", "|---|---:|" + "---:|" * len(PARTS)]
        for before, row in zip(done, done[1:]):
            ratios = [row["parts_s"][p] / before["parts_s"][p] if before["parts_s"][p] > 0 else None for p in PARTS]
            lines.append(f"| {row['resolution']}³ / {before['resolution']}³ | "
                         f"×{row['s_per_step'] / before['s_per_step']:.2f} | " +
                         " | ".join("–" if x is None else f"×{x:.2f}" for x in ratios) + " |")
    terms = list(dict.fromkeys(term for row in done for term in row.get("priors_s", {})))
    if terms:
        lines += ["", "| the priors, by term | " + " | ".join(f"`{t}`" for t in terms) + " |", "|---|" + "---:|" * len(terms)]
        for row in done:
            cells = [f"{row['priors_s'][t] * 1e3:.1f} ms" if t in row["priors_s"] else "–" for t in terms]
            lines.append(f"| {row['resolution']}³ | " + " | ".join(cells) + " |")
    return "\n".join(lines)
