"""mitsuba-platonic: PlatonicGAN with closed-form and Mitsuba 3 rendering layers.

Data flow: ``views`` → ``volume`` → ``render`` (closed form | Mitsuba) → images →
networks → training → evaluation/export.

Importing the package checks that Dr.Jit has a working backend (see :mod:`.backend`) and
raises :class:`~mitsuba_platonic.backend.BackendError` with install instructions if not.
"""

from .backend import BackendError, check_backend

BACKEND = check_backend()

from . import views, volume  # noqa: E402
from .render import RenderSettings, render, render_with  # noqa: E402

__version__ = "0.1.0"
__all__ = ["render", "render_with", "RenderSettings", "views", "volume", "BackendError", "BACKEND", "__version__"]
