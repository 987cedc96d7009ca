"""A cheap procedural shape class for tests that need a collection or a training run.

``TINY`` names it; the ``tiny_class`` fixture (tests/conftest.py) registers it for a test module:
``pytestmark = pytest.mark.usefixtures("tiny_class")``."""

from __future__ import annotations

import torch

from mitsuba_platonic.volume import voxel_centres


def ellipsoid(rng, n: int) -> torch.Tensor:
    """A grey ellipsoid with random radii: ``(4, N, N, N)`` RGBA, anti-aliased over about a voxel."""
    p = voxel_centres(n)
    radii = torch.tensor(rng.uniform(0.3, 0.7, size=3))
    density = torch.sigmoid(-(((p / radii) ** 2).sum(-1).sqrt() - 1.0) * n / 2.0)
    return torch.cat([torch.full((3, n, n, n), 0.6), density[None]]).float()


#: The class name :func:`ellipsoid` is registered under while a module uses the ``tiny_class`` fixture.
TINY = "tiny_ellipsoid"


def tiny_run_overrides(out, data, *extra: str) -> list:
    """``--set`` overrides of a tiny reconstruction run ``out/r`` on two :data:`TINY` shapes cached in
    ``data`` (16³, 2 steps, a checkpoint at step 2); ``extra`` overrides come last and win."""
    return [f"run.out_dir={out}", "run.name=r", "run.steps=2", "run.log_every=1", "run.sample_every=100000",
            "run.checkpoint_every=2", f"data.cache={data}", f"data.shape_class={TINY}", "data.n_shapes=2",
            "data.views_per_shape=1", "model.resolution=16", "model.width=4", "model.latent=8",
            "train.batch_size=2", *extra]
