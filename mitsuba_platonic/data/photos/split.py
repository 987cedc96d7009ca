"""Splits: the unique usable images of a collection → train / val / test, by content.

Splits are made after de-duplication, over the usable images only: each image's content hash
``h`` is ranked by ``sha256(f"{seed}:{h}")`` (a seeded shuffle that does not depend on file
names or listing order), the ranked list is cut into train/val/test by :func:`split_counts`,
and each split lists its images in content-hash order. The split of an image can change only
when images are added to or removed from the collection (or the seed or fractions change).
"""

from __future__ import annotations

import hashlib
import math
from typing import Dict, List, Sequence, Tuple

from ...errors import UserError

__all__ = ["split_counts", "check_splits", "assign_splits", "SPLITS"]

#: Split names accepted by :class:`PhotoCollection` (``"all"``: every usable image).
SPLITS = ("train", "val", "test", "all")


def split_counts(n: int, fractions: Sequence[float]) -> Tuple[int, ...]:
    """Sizes of the splits of ``n`` items for ``fractions`` (non-negative, summing to 1).

    Largest-remainder rounding of ``fᵢ·n`` (ties go to the earlier split), so the sizes sum to
    ``n``; then every split with ``fᵢ > 0`` that got nothing takes one item from the largest
    split, as long as ``n`` is at least the number of such splits.
    Example: ``n = 32``, (0.8, 0.1, 0.1) → (26, 3, 3).
    """
    fractions = [float(f) for f in fractions]
    exact = [f * n for f in fractions]
    counts = [math.floor(x) for x in exact]
    order = sorted(range(len(fractions)), key=lambda i: (-(exact[i] - counts[i]), i))
    for i in order[: n - sum(counts)]:
        counts[i] += 1
    positive = [i for i, f in enumerate(fractions) if f > 0]
    if n >= len(positive):
        for i in positive:
            if counts[i] == 0:
                donor = max(range(len(counts)), key=lambda j: (counts[j], -j))
                counts[donor] -= 1
                counts[i] += 1
    return tuple(counts)


def check_splits(splits: Sequence[float]) -> Tuple[float, float, float]:
    """Three non-negative fractions (train, val, test) summing to 1, as floats; else UserError."""
    try:
        values = tuple(float(f) for f in splits)
    except (TypeError, ValueError):
        raise UserError(f"splits must be three fractions (train, val, test), got {splits!r}"
                        ) from None
    if len(values) != 3 or not all(math.isfinite(f) and f >= 0 for f in values) \
            or abs(sum(values) - 1.0) > 1e-6:
        raise UserError(f"splits must be three non-negative fractions (train, val, test) "
                        f"summing to 1, got {splits!r}")
    return values  # type: ignore[return-value]


def _rank_key(seed: int, sha256: str) -> str:
    """Seeded shuffle key: SHA-256 of ``"<seed>:<content hash>"`` (independent of names)."""
    return hashlib.sha256(f"{seed}:{sha256}".encode()).hexdigest()


def assign_splits(hashes: Sequence[str], fractions: Tuple[float, float, float],
                  seed: int) -> Dict[str, List[str]]:
    """``{"train", "val", "test", "all"}`` → the content hashes of each split (sorted)."""
    ranked = sorted(hashes, key=lambda h: _rank_key(seed, h))
    n_train, n_val, _ = split_counts(len(ranked), fractions)
    return {"train": sorted(ranked[:n_train]),
            "val": sorted(ranked[n_train:n_train + n_val]),
            "test": sorted(ranked[n_train + n_val:]),
            "all": sorted(ranked)}
