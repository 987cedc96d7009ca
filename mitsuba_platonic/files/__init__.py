"""Files: what the package writes and reads, each format in one place.

- :mod:`.fileio`: writes whole or not at all, never through a link out of their folder;
- :mod:`.outputs`: which ``--out`` folder a command may write into;
- :mod:`.resources`: the package data (scene files, configs, baked skies);
- :mod:`.volume_io`: volume files (``.npz``, Mitsuba ``.vol``);
- :mod:`.checkpoint`: the checkpoint file format, read safely, and :mod:`.pickle_scan`, what a
  pickled file would import, read from its opcodes.

Images (PNG, EXR) are :mod:`mitsuba_platonic.images`'. Nothing is imported here, so the command
line's use of :mod:`.fileio` loads no numpy or torch.
"""
