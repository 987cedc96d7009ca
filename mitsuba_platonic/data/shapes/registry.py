"""The shape-class registry: names → generators of ``(4, N, N, N)`` RGBA volumes.

A *shape class* is a callable ``(rng: numpy.random.Generator, n: int)`` that returns either a
``(4, n, n, n)`` tensor ``[r, g, b, density]`` in [0, 1] or a sequence of
:class:`~.sdf.Part` (composited with :func:`~.sdf.composite`'s defaults). Register it with
:func:`register`, as a decorator on a function or on a class (a class is instantiated once,
with no arguments, and its instances must be callable the same way).

:func:`generate` seeds the generator from ``(seed, name)`` only, so a shape depends on
``(name, seed)`` and, through sampling alone, on ``n``: the same seed gives the same object
at every resolution. Class code must therefore draw from ``rng`` independently of ``n``.
"""

from __future__ import annotations

import contextlib
import zlib
from typing import Any, Callable, Dict, Iterator, List

import numpy as np
import torch

from ...errors import UserError
from .sdf import Part, composite

__all__ = ["register", "unregister", "registered", "generate", "list_classes", "get_class",
           "MIN_RESOLUTION", "MAX_RESOLUTION"]

MIN_RESOLUTION = 16
MAX_RESOLUTION = 128

_REGISTRY: Dict[str, Callable[[np.random.Generator, int], Any]] = {}
_OBJECTS: Dict[str, Any] = {}


def _check_name(name: Any) -> str:
    if not isinstance(name, str) or not name or name.strip() != name:
        raise ValueError(f"a shape class name must be a non-empty string without surrounding "
                         f"spaces, got {name!r}")
    return name


def register(name: str, obj: Any = None, *, overwrite: bool = False):
    """Register a shape class under ``name``; usable as ``@register("chair")`` or ``register("chair", fn)``.

    ``obj`` is a function ``(rng, n) -> Tensor | Sequence[Part]`` or a class whose no-argument
    instance is such a callable. Returns ``obj`` unchanged (so decorated names stay usable).
    Raises ``ValueError`` if the name is taken (unless ``overwrite``) or ``obj`` is not callable.
    """
    _check_name(name)

    def deco(o: Any) -> Any:
        if name in _REGISTRY and not overwrite:
            raise ValueError(f"shape class {name!r} is already registered "
                             f"(by {_OBJECTS[name]!r}); pass overwrite=True to replace it")
        fn = o() if isinstance(o, type) else o
        if not callable(fn):
            raise ValueError(f"shape class {name!r} must be a function (rng, n) -> volume or a "
                             f"class with a callable instance, got {o!r}")
        _REGISTRY[name] = fn
        _OBJECTS[name] = o
        return o

    return deco if obj is None else deco(obj)


def unregister(name: str) -> None:
    """Remove a registered class; ``ValueError`` if it is not registered."""
    _lookup(name)
    del _REGISTRY[name]
    del _OBJECTS[name]


@contextlib.contextmanager
def registered(name: str, obj: Any) -> Iterator[Any]:
    """Context manager: ``obj`` is registered as ``name`` inside the block, unregistered after
    (for tests and experiments). Yields ``obj``."""
    register(name, obj)
    try:
        yield obj
    finally:
        if _OBJECTS.get(name) is obj:
            unregister(name)


def list_classes() -> List[str]:
    """Names of the registered shape classes, sorted."""
    return sorted(_REGISTRY)


def _lookup(name: Any) -> Callable[[np.random.Generator, int], Any]:
    if not isinstance(name, str) or name not in _REGISTRY:
        known = ", ".join(list_classes()) or "(none)"
        raise UserError(f"unknown shape class {name!r}; known classes: {known}")
    return _REGISTRY[name]


def get_class(name: str) -> Any:
    """The object registered as ``name`` (the function, or the class as written);
    ``ValueError`` listing the known classes if there is none."""
    _lookup(name)
    return _OBJECTS[name]


def _rng(name: str, seed: int) -> np.random.Generator:
    # the class name enters the seed, so seed k of two classes are independent draws
    return np.random.default_rng([int(seed), zlib.crc32(name.encode("utf-8"))])


def generate(name: str, seed: int, n: int = 64) -> torch.Tensor:
    """Generate member ``seed`` of class ``name`` as a float32 ``(4, n, n, n)`` volume
    ``[r, g, b, density]`` in [0, 1] (layout: :mod:`mitsuba_platonic.volume`).

    Deterministic in ``(name, seed, n)``. Raises ``ValueError`` for an unknown class (the
    message lists the known ones), a seed that is not a non-negative int, or ``n`` outside
    [16, 128]; ``RuntimeError`` if the class returns something malformed.
    """
    fn = _lookup(name)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise UserError(f"seed must be an int, got {type(seed).__name__} {seed!r}")
    if seed < 0:
        raise UserError(f"seed must be a non-negative int, got {seed}")
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)):
        raise UserError(f"n must be an int in [{MIN_RESOLUTION}, {MAX_RESOLUTION}], "
                        f"got {type(n).__name__} {n!r}")
    n = int(n)
    if not MIN_RESOLUTION <= n <= MAX_RESOLUTION:
        raise UserError(f"n must be in [{MIN_RESOLUTION}, {MAX_RESOLUTION}], got {n}")
    out = fn(_rng(name, int(seed)), n)
    if not isinstance(out, torch.Tensor):
        if isinstance(out, (list, tuple)) and out and all(isinstance(p, Part) for p in out):
            out = composite(out, n)
        else:
            raise RuntimeError(f"shape class {name!r} returned {type(out).__name__}; expected a "
                               f"(4, {n}, {n}, {n}) tensor or a non-empty sequence of Part")
    if tuple(out.shape) != (4, n, n, n):
        raise RuntimeError(f"shape class {name!r} returned shape {tuple(out.shape)}, "
                           f"expected (4, {n}, {n}, {n})")
    out = out.detach().to(torch.float32).contiguous()
    if not torch.isfinite(out).all() or float(out.min()) < 0.0 or float(out.max()) > 1.0:
        raise RuntimeError(f"shape class {name!r} returned values outside [0, 1] or NaN")
    return out
