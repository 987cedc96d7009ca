"""The import-time Dr.Jit backend check: a clear error instead of an aborted process."""

import os
import subprocess
import sys

import pytest

from mitsuba_platonic.backend import INSTALL_HINT, MIN_LLVM, _version_of, find_libllvm


def _import_in_child(tmp_path, **env):
    e = dict(os.environ, MITSUBA_PLATONIC_CACHE=str(tmp_path), **env)
    e.pop("MITSUBA_PLATONIC_SKIP_BACKEND_CHECK", None)
    code = ("import mitsuba_platonic\n"
            "print('IMPORTED', mitsuba_platonic.BACKEND['llvm'])")
    return subprocess.run([sys.executable, "-c", code], env=e, capture_output=True, text=True, timeout=600)


def test_import_succeeds_and_caches_its_verdict(tmp_path):
    r = _import_in_child(tmp_path)
    assert r.returncode == 0, r.stderr
    assert "IMPORTED True" in r.stdout
    assert list(tmp_path.glob("backend-*.json"))


def test_missing_llvm_raises_a_clear_error(tmp_path):
    r = _import_in_child(tmp_path, DRJIT_LIBLLVM_PATH=str(tmp_path / "libLLVM-19.so"))
    assert r.returncode != 0
    assert "BackendError" in r.stderr and "libllvm19" in r.stderr
    assert not list(tmp_path.glob("backend-*.json"))  # a bad verdict is never cached


@pytest.mark.skipif(not any(os.path.exists(p) for p in ["/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1"]),
                    reason="LLVM 15 is not installed here")
def test_llvm_15_is_reported_not_a_crash(tmp_path):
    r = _import_in_child(tmp_path, DRJIT_LIBLLVM_PATH="/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1")
    assert r.returncode == 1  # a Python exception, not an abort (SIGABRT)
    assert "BackendError" in r.stderr and "DRJIT_LIBLLVM_PATH" in r.stderr


def test_find_libllvm_prefers_a_working_version():
    assert _version_of("/usr/lib/libLLVM-19.so") == 19
    assert _version_of("/usr/lib/libLLVM.so.19.1") == 19
    assert _version_of("/usr/lib/libLLVM-15.so.1") == 15
    lib = find_libllvm()
    assert lib is None or _version_of(lib) >= MIN_LLVM
    assert "apt-get install libllvm19" in INSTALL_HINT
