"""The import-time Dr.Jit backend check: a clear error instead of an aborted process."""

import os
import subprocess
import sys

import pytest

from mitsuba_platonic.runtime.backend import INSTALL_HINT, MIN_LLVM, _version_of, find_libllvm


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


# --------------------------------------------------------------------------- issue 29: only where Dr.Jit is needed


def _cli_in_child(tmp_path, *argv, env=None, code=None):
    e = dict(os.environ, MITSUBA_PLATONIC_CACHE=str(tmp_path), DRJIT_LIBLLVM_PATH=str(tmp_path / "libLLVM-19.so"),
             **(env or {}))
    e.pop("MITSUBA_PLATONIC_SKIP_BACKEND_CHECK", None)
    command = [sys.executable, "-c", code] if code else [sys.executable, "-m", "mitsuba_platonic.cli", *argv]
    return subprocess.run(command, env=e, capture_output=True, text=True, timeout=600, stdin=subprocess.DEVNULL)


def test_help_and_version_need_no_llvm(tmp_path):
    for argv in (["--help"], ["--version"], ["train", "--help"]):
        r = _cli_in_child(tmp_path, *argv)
        assert r.returncode == 0 and r.stderr == "", (argv, r.stderr)


def test_closed_form_rendering_and_photo_loading_need_no_llvm(tmp_path):
    from PIL import Image
    photo = tmp_path / "p.png"
    Image.new("RGBA", (24, 24), (200, 30, 30, 255)).save(photo)
    code = ("import sys\n"
            "import mitsuba_platonic as mp\n"
            "from mitsuba_platonic.views import front_view\n"
            "from mitsuba_platonic.volume import test_volume\n"
            "from mitsuba_platonic.data.photos import decode_image\n"
            "img = mp.render(test_volume(8), front_view(1), 'ea', 'closed_form')\n"
            f"photo = decode_image({str(photo)!r})\n"
            "print('OK', tuple(img.shape), 'drjit' in sys.modules)\n")
    r = _cli_in_child(tmp_path, code=code)
    assert r.returncode == 0, r.stderr
    assert "OK (1, 4, 8, 8) False" in r.stdout


def test_a_command_that_needs_drjit_says_so_in_one_line(tmp_path):
    r = _cli_in_child(tmp_path, "compare", "--resolution", "8", "--views", "1", "--repeats", "1", "--models", "vh",
                      "--out", str(tmp_path / "out"))
    assert r.returncode == 2, r.stderr
    err = r.stderr.strip()
    assert "\n" not in err and "Traceback" not in err, err
    assert err.startswith("platonic compare: error: Dr.Jit has no working backend"), err
    assert "DRJIT_LIBLLVM_PATH" in err and "libllvm19" in err, err
