"""bench.timing.kernel_time: Dr.Jit's kernel history read around one call, and switched off after it."""

import math

import pytest

from mitsuba_platonic.bench.timing import best_kernel_ms, kernel_time
from mitsuba_platonic.render.variant import ensure_variant

mi = ensure_variant()
import drjit as dr  # noqa: E402


def _one_kernel():
    x = dr.arange(mi.Float, 100_000)
    dr.eval(dr.sin(x) * x + dr.opaque(mi.Float, 1.0))


def test_kernel_time_counts_the_call_s_launches_and_leaves_the_history_off():
    ms, launches = kernel_time(_one_kernel)
    assert launches >= 1 and 0.0 < ms and math.isfinite(ms)    # the kernel ran (no bound on its time: a test never times)
    assert not dr.flag(dr.JitFlag.KernelHistory)
    assert kernel_time(lambda: None) == (0.0, 0)              # nothing launched: nothing counted
    best = best_kernel_ms(_one_kernel, 2)
    assert 0.0 < best and math.isfinite(best)


def test_kernel_time_switches_the_history_off_on_an_error():
    def fails():
        _one_kernel()
        raise RuntimeError("boom")

    with pytest.raises(RuntimeError, match="boom"):
        kernel_time(fails)
    assert not dr.flag(dr.JitFlag.KernelHistory)
