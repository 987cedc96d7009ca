"""The Mitsuba scene side: the scene files, the per-pair integrator and the path tracer.

:mod:`.scenes` (the one loader of ``scenes/*.xml``), :mod:`.integrator` (``platonic_raymarch``,
the marcher's formulas as a Mitsuba integrator) and :mod:`.per_pair` (one ``mi.render`` per pair
with it, wrapped for torch), :mod:`.physical` (the volumetric path tracer under natural light),
:mod:`.single_scatter_reference` (``volpath`` at depth 2: single scattering's reference) and
:mod:`.sky` (skies baked from ``sunsky``). This package's face imports none of them.
"""
