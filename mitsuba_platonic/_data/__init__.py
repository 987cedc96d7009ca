"""Package data: ``scenes/`` and ``configs/`` are links to the repository's top-level folders.

The links make the one source of the scene files, the baked skies and the configs part of the
package: a wheel carries copies of them, an editable install reads the folders themselves.
Read them through :mod:`mitsuba_platonic.files.resources`, never by a path relative to the package.
"""
