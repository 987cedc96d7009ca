"""The renderers in PyTorch: the paper's closed-form layers and single scattering of a sun and a sky.

:mod:`.closed_form` (VH, AO, EA: resample into camera space, reduce along depth; the reference
mode every other backend is checked against) and :mod:`.single_scatter` (a deterministic,
differentiable formation under light, with the light model the Dr.Jit kernels share). Neither
imports Dr.Jit or Mitsuba; :func:`mitsuba_platonic.render.render_with` dispatches to them.
"""
