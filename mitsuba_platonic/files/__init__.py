"""Files: each format the package writes or reads, in one place: :mod:`.fileio` (writes whole or not at
all, never through a link), :mod:`.outputs` (the ``--out`` folders), :mod:`.resources` (the package data),
:mod:`.volume_io` (``.npz``, ``.vol``), :mod:`.checkpoint` (read safely, with :mod:`.pickle_scan`). Images
are :mod:`mitsuba_platonic.images`'. Imports nothing, so the command line's use of :mod:`.fileio` stays light.
"""
