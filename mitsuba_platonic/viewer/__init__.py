"""``platonic view``: an interactive web viewer on the project's own renderers (the ``viewer`` extra).

- :mod:`.start`: what the command does before torch loads: the port's and SOURCE's checks (a
  volume file read with numpy) and the server started with the initial camera, so that the
  address is printed while torch and the scene load. Imports numpy, and viser only to start it.
- :mod:`.scene`: what is shown, without the web library: the SOURCE (a volume file, a run
  folder, a photo run with a photo) opened as volumes, a frame of the current volume rendered by
  one of the project's renderers at a camera direction, and the exports a page may ask for,
  kept inside the output folder. Imports torch and the package, never the web library.
- :mod:`.worker`: the path tracer's passes in a child process of lower priority, a page's newest
  pass only (superseded, cancelled), round-robin between pages. Imports neither torch nor viser
  at the top (the child imports the scene).
- :mod:`.compare`: compare mode's arithmetic, numpy only: two frames side by side, or |A − B|
  through a colour scale over its range.
- :mod:`.live`: a run still training followed: its ``checkpoints/last.pt`` and ``scalars.csv``
  polled in a thread, a new checkpoint read there (a bad one is one line, the model shown stays).
- :mod:`.app`: the page, on `viser <https://viser.studio>`_ (the library nerfstudio's viewer runs
  on): each browser's camera → a view ω (from the object towards the camera) → a frame rendered on
  the server and set as the page's background image (a low-resolution frame while the camera
  moves, the full one when it stops), GUI controls for renderer, formation, resolution, the
  source's inputs and latents, compare mode, a live run's step and losses, and the exports.

Nothing outside this sub-package imports viser (tests/test_viewer.py pins it); this ``__init__``
imports neither module, so ``import mitsuba_platonic.viewer`` is light.
"""

__all__: list = []
