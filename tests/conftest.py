import os
import sys

import pytest
import torch

sys.path.insert(0, os.path.dirname(__file__))  # tests/reference.py

torch.set_num_threads(max(1, min(2, os.cpu_count() or 1)))


@pytest.fixture(autouse=True)
def _seed():
    torch.manual_seed(0)


@pytest.fixture(scope="module")
def tiny_class():
    """The cheap shape class of tests/tiny_shapes.py, registered as ``tiny_shapes.TINY`` for a module."""
    from mitsuba_platonic.data import shapes
    from tiny_shapes import TINY, ellipsoid

    with shapes.registered(TINY, ellipsoid):
        yield TINY
