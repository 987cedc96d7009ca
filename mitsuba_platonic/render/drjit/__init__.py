"""The Dr.Jit kernels: every (volume, view) pair of a call in one launch, primal and adjoint.

:mod:`.marcher` (VH, AO, EA: the batched ray marcher, backend ``mitsuba``), :mod:`.scatter_march`
(single scattering at the marcher's speed, backend ``scatter_march``) with :mod:`.sky_light` (its
sky's far occlusion), and :mod:`.launch`, what their launches share (threads, scatter mode, torch
memory handed to Dr.Jit, replay keys). Importing any of them sets Mitsuba's variant
(:func:`~mitsuba_platonic.render.variant.ensure_variant`); this package's face imports none.
"""
