"""``platonic quickstart``: the whole pipeline in one command, a library function each.

- :mod:`.procedural`: a small procedural collection rendered, trained on, its held-out shapes
  reconstructed, scored at novel views and exported;
- :mod:`.photos` (``--photos DIR``): a user's photo folder trained on, judged on its held-out
  photos and exported.

Above training, evaluation and export, which they run; below the command line. Nothing is imported here.
"""
