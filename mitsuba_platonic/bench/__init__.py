"""``platonic bench``: the renderers' speed/accuracy trade, measured and published.

For each resolution N and each image formation model (VH, AO, EA) one batch of B (volume, view)
pairs (the built-in test volume, B random views) is rendered by:

- the closed-form layer (the reference mode, trilinear);
- the batched ray marcher (``backend="mitsuba"``) at its default (step 1, spp 1, trilinear, no
  jitter, termination 0) and with one option varied at a time: step {2, 0.5, 0.25}, spp {4, 16}
  on a regular sub-pixel grid and jittered, jitter at spp 1, nearest lookups, early termination
  {1e-3, 1e-2};
- EA only: a *plain layer* (``affine_grid`` + ``grid_sample`` + ``cumprod``, nothing else: a speed
  yardstick for a layer written the obvious way), the *authors' EA layer* (:func:`authors_ea`, the
  image formation of the PlatonicGAN authors' public code: a different image formation, reported
  for its time and for how far its images are from ours), and the differentiable path tracer
  (``backend="physical"``, :func:`~mitsuba_platonic.render.mitsuba.physical.render_physical_ad`: its own
  image formation under a random sky) at spp {1, 4}, and single scattering of a sun and a sky
  (:func:`~mitsuba_platonic.render.pytorch.single_scatter.render_single_scatter`, up to 32³) at its
  defaults and at 2 samples per voxel, and the same light in Dr.Jit
  (:func:`~mitsuba_platonic.render.drjit.scatter_march.render_scatter_march`, up to 64³) at its defaults
  (2 samples per voxel, spp 1), at 4 samples per voxel and at spp 4.

Every row records (all times per image, the best of ``repeats`` timed calls after an untimed
warm-up call):

- ``fwd_ms``: a forward call under ``torch.no_grad()``; ``fwd_bwd_ms``: forward and backward of
  the loss L = Σ W ⊙ image, W a fixed random weight (:func:`loss_weights`), into a leaf volume.
- ``mem_fwd_mb`` / ``mem_fwd_bwd_mb``: the peak increase of the process's resident memory (RSS,
  sampled from ``/proc/self/statm`` by a background thread every 0.5 ms) over its level just
  before one such call, after Python's, Dr.Jit's and glibc's caches were released. CPU memory
  only; it includes everything the call allocates (outputs, the marcher's T_k record, autograd
  buffers, the gradient).
- ``rmse`` / ``max_abs``: image error against the *converged reference*: the ray marcher at step
  0.25 with spp 16 on a regular grid (rendered pair by pair). Rows of another image formation are
  measured against their own reference: the path tracer against itself at ``physical_ref_spp``
  (the same scene, views and sky, whose sun is drawn from the seed and not from the spp); single
  scattering against itself at 8 samples per voxel and a shadow ray of 4 planes (the same suns
  and skies); single scattering in Dr.Jit in RGB against Mitsuba's ``volpath`` at ``max_depth`` 2
  (the physical truth of the formation, at ``scatter_ref_spp``; its noise is part of the error),
  in α and gradient against itself at 8 samples per voxel and spp 4; the authors' layer against *our* reference (for information: it renders a
  different image).
- ``grad_cosine``, ``grad_norm_ratio`` (‖g‖ / ‖g_ref‖) and ``grad_rel_err`` (‖g − g_ref‖ / ‖g_ref‖):
  the gradient of L w.r.t. the volume against the reference's gradient of the same L.
- ``rmse_vs_closed_form`` / ``max_abs_vs_closed_form``: image difference from the closed form.
- A memory-traffic lower bound: the bytes that must move (forward: read the volume once and write
  the image; backward: read the volume and the image gradient, write the volume gradient) divided
  by a bandwidth measured once at the start (the best of several copies of a large tensor,
  counting its read and its write); ``bound_fwd_ms``, ``bound_fwd_bwd_ms`` and the measured time
  over the bound, ``fwd_over_bound`` / ``fwd_bwd_over_bound``.

Plus training images/s per renderer (closed form, the marcher, single scattering in Dr.Jit, the
path tracer at spp 1 depth 2)
for one small reconstruction configuration (:func:`.train.bench_train`).

Outputs (:func:`write_outputs`): ``bench.json`` (every measured row and the run's settings),
``bench.md`` (the tables) and ``pareto_<model>_<N>.png`` (image RMSE vs forward+backward ms per
image, log-log, every configuration labelled, the marcher's default marked). :func:`write_doc`
fills the generated section of ``docs/speed_accuracy.md``. Nothing is asserted here: the tests
check correctness, never time.
"""

from __future__ import annotations

from .layers import (AUTHORS_DENSITY_FACTOR, AUTHORS_DEPTH_SAMPLES, authors_ea, gradient_error, image_error,
                     loss_weights, plain_ea)
from .report import DOC_BEGIN, DOC_END, markdown_tables, pareto_plot, write_doc, write_outputs
from .run import run_bench
from .settings import REFERENCE_OPTIONS, RESOLUTIONS, BenchSettings, marcher_configs
from .timing import PeakRSS, measure_bandwidth

__all__ = ["BenchSettings", "run_bench", "write_outputs", "write_doc", "marcher_configs", "authors_ea",
           "plain_ea", "loss_weights", "image_error", "gradient_error", "REFERENCE_OPTIONS",
           "RESOLUTIONS", "DOC_BEGIN", "DOC_END", "AUTHORS_DEPTH_SAMPLES", "AUTHORS_DENSITY_FACTOR", "PeakRSS",
           "measure_bandwidth", "markdown_tables", "pareto_plot"]
