"""Dr.Jit backend check: find a working LLVM (or CUDA) before Dr.Jit is imported.

Dr.Jit's LLVM backend loads a shared ``libLLVM`` at run time. On Debian 12 the system's
LLVM 14 is rejected at start-up and LLVM 15 *aborts the whole process* on the first
``dr.minimum``/``dr.maximum`` (``LLVM ERROR: Cannot select ... fminimum``), which no
``try`` can catch. So the check runs in a child process, once per (Dr.Jit version, LLVM
library) pair, and its verdict is cached in ``$MITSUBA_PLATONIC_CACHE`` (default
``~/.cache/mitsuba_platonic``).

Before the check, where ``DRJIT_LIBLLVM_PATH`` is unset, the newest ``libLLVM-NN.so`` with
NN ≥ 16 found in the usual library folders is chosen, so a machine with both LLVM 15 and
19 uses 19.
"""

from __future__ import annotations

import glob
import os
import re
import sys
from typing import TYPE_CHECKING, Dict, List, Optional

if TYPE_CHECKING:           # the rest loads in check_backend: `import mitsuba_platonic` stays quick
    from pathlib import Path

__all__ = ["BackendError", "check_backend", "find_libllvm", "preselect_libllvm", "INSTALL_HINT"]

#: LLVM major versions Dr.Jit 1.5 works with here (14 rejected, 15 aborts).
MIN_LLVM = 16

INSTALL_HINT = (
    "Install a recent LLVM shared library and let Dr.Jit find it:\n"
    "  Debian 12 / Ubuntu:  sudo apt-get update && sudo apt-get install libllvm19\n"
    "  or point Dr.Jit at one:  export DRJIT_LIBLLVM_PATH=/path/to/libLLVM-19.so\n"
    "(LLVM 14 is rejected by Dr.Jit and LLVM 15 aborts the process on dr.minimum.) "
    "The project's scripts/setup.sh does this for you."
)

_SEARCH = ["/usr/lib/x86_64-linux-gnu", "/usr/lib/aarch64-linux-gnu", "/usr/lib64", "/usr/lib",
           "/usr/local/lib", "/usr/lib/llvm-*/lib", "/opt/homebrew/opt/llvm/lib",
           "/usr/local/opt/llvm/lib"]

_PROBE = r"""
import json, sys
out = {"llvm": False, "cuda": False, "error": ""}
try:
    import drjit as dr
    try:
        import drjit.cuda as C
        if dr.has_backend(dr.JitBackend.CUDA):
            x = dr.minimum(C.Float([1.0, 2.0]), C.Float([2.0, 0.0])); dr.eval(x)
            out["cuda"] = list(x) == [1.0, 0.0]
    except Exception as e:
        pass
    if dr.has_backend(dr.JitBackend.LLVM):
        import drjit.llvm as L
        x = dr.maximum(dr.minimum(L.Float([1.0, 2.0]), L.Float([2.0, 0.0])), L.Float(0.5)); dr.eval(x)
        out["llvm"] = list(x) == [1.0, 0.5]
    else:
        out["error"] = "Dr.Jit found no usable LLVM library"
except Exception as e:
    out["error"] = f"{type(e).__name__}: {e}"
print("PROBE" + json.dumps(out))
"""


class BackendError(ImportError):
    """Dr.Jit has no working backend on this machine; the message says what to install (its first
    line what is wrong, the following lines how to fix it)."""


def _version_of(path: str) -> int:
    m = re.search(r"libLLVM(?:-|\.so\.)(\d+)", os.path.basename(path))
    return int(m.group(1)) if m else -1


def find_libllvm() -> Optional[str]:
    """The newest ``libLLVM`` shared library with major version ≥ 16 on this machine, or None."""
    found: List[str] = []
    for folder in _SEARCH:
        for d in glob.glob(folder):
            found += glob.glob(os.path.join(d, "libLLVM-*.so*")) + glob.glob(os.path.join(d, "libLLVM.so.*"))
            found += glob.glob(os.path.join(d, "libLLVM.dylib"))
    good = [p for p in found if _version_of(p) >= MIN_LLVM and os.path.isfile(p)]
    good.sort(key=lambda p: (_version_of(p), -len(p)), reverse=True)
    return good[0] if good else None


def preselect_libllvm() -> None:
    """Set ``DRJIT_LIBLLVM_PATH`` to :func:`find_libllvm` where it is unset and Dr.Jit is not yet
    imported (no Dr.Jit import, no probe: cheap enough for ``import mitsuba_platonic``)."""
    if os.environ.get("MITSUBA_PLATONIC_SKIP_BACKEND_CHECK") == "1":
        return
    if "DRJIT_LIBLLVM_PATH" not in os.environ and "drjit" not in sys.modules:
        lib = find_libllvm()
        if lib:
            os.environ["DRJIT_LIBLLVM_PATH"] = lib


def _cache_dir() -> "Path":
    from pathlib import Path  # lazy: the check's alone; `import mitsuba_platonic` stays quick (issue 29)

    return Path(os.environ.get("MITSUBA_PLATONIC_CACHE", Path.home() / ".cache" / "mitsuba_platonic"))


def _key(libllvm: Optional[str]) -> str:
    import hashlib  # lazy: the check's alone; `import mitsuba_platonic` stays quick (issue 29)
    from importlib import metadata

    try:
        drjit_version = metadata.version("drjit")
    except metadata.PackageNotFoundError:
        drjit_version = "missing"
    stat = ""
    if libllvm and os.path.exists(libllvm):
        st = os.stat(libllvm)
        stat = f"{st.st_size}:{int(st.st_mtime)}"
    raw = f"{sys.executable}|{drjit_version}|{libllvm}|{stat}|{os.environ.get('CUDA_VISIBLE_DEVICES', '')}"
    return hashlib.sha1(raw.encode()).hexdigest()[:16]


def _probe(env: Dict[str, str]) -> Dict[str, object]:
    import json  # lazy: the check's alone; `import mitsuba_platonic` stays quick (issue 29)
    import subprocess

    try:
        r = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True, text=True,
                           timeout=300)
    except subprocess.TimeoutExpired:
        return {"llvm": False, "cuda": False, "error": "the Dr.Jit probe timed out after 300 s"}
    for line in r.stdout.splitlines():
        if line.startswith("PROBE"):
            return json.loads(line[5:])
    tail = (r.stderr.strip().splitlines() or ["(no output)"])[-1]
    return {"llvm": False, "cuda": False,
            "error": f"the Dr.Jit probe process died (exit code {r.returncode}): {tail}"}


def check_backend() -> Dict[str, object]:
    """Make sure Dr.Jit has a working backend; return ``{"llvm", "cuda", "libllvm"}``.

    Sets ``DRJIT_LIBLLVM_PATH`` when it is unset and a suitable library exists. Raises
    :class:`BackendError` with install instructions when neither LLVM nor CUDA works.
    Set ``MITSUBA_PLATONIC_SKIP_BACKEND_CHECK=1`` to skip the check entirely.
    """
    import json  # lazy: the check's alone; `import mitsuba_platonic` stays quick (issue 29)

    from ..files.fileio import atomic_write        # here, not at the top: importing the package stays cheap (issue 29)

    if os.environ.get("MITSUBA_PLATONIC_SKIP_BACKEND_CHECK") == "1":
        return {"llvm": True, "cuda": False, "libllvm": os.environ.get("DRJIT_LIBLLVM_PATH")}
    preselect_libllvm()
    libllvm = os.environ.get("DRJIT_LIBLLVM_PATH")
    cache = _cache_dir() / f"backend-{_key(libllvm)}.json"
    result = None
    if cache.exists():
        try:
            result = json.loads(cache.read_text())
        except (OSError, ValueError):
            result = None
    if result is None:
        result = _probe(dict(os.environ))
        if result.get("llvm") or result.get("cuda"):
            try:  # cache only good verdicts: a fix (installing LLVM) must be seen at once
                atomic_write(cache, lambda tmp: tmp.write_text(json.dumps(result)))
            except OSError:
                pass
    result["libllvm"] = libllvm
    if not (result.get("llvm") or result.get("cuda")):
        where = f" (DRJIT_LIBLLVM_PATH={libllvm})" if libllvm else " (no libLLVM >= 16 found)"
        raise BackendError(f"Dr.Jit has no working backend{where}: {result.get('error')}.\n{INSTALL_HINT}")
    return result
