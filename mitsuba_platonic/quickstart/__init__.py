"""``platonic quickstart``, the whole pipeline in one command: :mod:`.procedural` (a collection rendered,
trained on, scored at novel views, exported) and :mod:`.photos` (``--photos DIR``: a photo folder trained
on, judged, exported). Above training, evaluation and export, below the command line. Imports nothing.
"""
