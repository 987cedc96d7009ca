#!/usr/bin/env bash
# Install everything mitsuba-platonic needs on a fresh Debian/Ubuntu machine:
#   1. a shared libLLVM >= 16 for Dr.Jit's CPU backend (LLVM 14 is rejected, 15 aborts),
#   2. a virtual environment in .venv with the package, its test tools, Jupyter (jupyter lab notebooks/) and the
#      viewer (platonic view); tests/test_viewer.py installs Debian's chromium itself where it is missing.
# Idempotent: re-running it only installs what is missing.
set -euo pipefail
cd "$(dirname "$0")/.."

have_llvm() {  # a shared libLLVM with major version >= 16 where Dr.Jit looks for it
  local f
  for f in /usr/lib/*/libLLVM-{16,17,18,19,20,21}.so* /usr/lib/libLLVM-{16,17,18,19,20,21}.so* \
           /usr/lib/llvm-{16,17,18,19,20,21}/lib/libLLVM*.so*; do
    [ -e "$f" ] && return 0
  done
  return 1
}

if [ -n "${DRJIT_LIBLLVM_PATH:-}" ] && [ -f "$DRJIT_LIBLLVM_PATH" ]; then
  echo "setup: using DRJIT_LIBLLVM_PATH=$DRJIT_LIBLLVM_PATH"
elif have_llvm; then
  echo "setup: a libLLVM >= 16 is present"
else
  SUDO=""
  if [ "$(id -u)" != 0 ]; then
    if command -v sudo >/dev/null 2>&1; then SUDO="sudo -n"; else
      echo "setup: Dr.Jit needs libLLVM >= 16 (e.g. 'apt-get install libllvm19') and this user cannot install it." >&2
      exit 1
    fi
  fi
  if ! command -v apt-get >/dev/null 2>&1; then
    echo "setup: install LLVM >= 16 with your package manager and set DRJIT_LIBLLVM_PATH to its libLLVM." >&2
    exit 1
  fi
  echo "setup: installing libllvm19 for Dr.Jit (apt-get)"
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq libllvm19 >/dev/null || $SUDO apt-get install -y -qq libllvm18 >/dev/null \
    || $SUDO apt-get install -y -qq libllvm17 >/dev/null || $SUDO apt-get install -y -qq libllvm16 >/dev/null
  have_llvm || { echo "setup: could not install a libLLVM >= 16" >&2; exit 1; }
fi

PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  echo "setup: creating .venv"
  "$PY" -m venv .venv
fi

# CPU machines take the local CPU build of torch; machines with an NVIDIA GPU keep pip's default.
CONSTRAINTS=()
if ! command -v nvidia-smi >/dev/null 2>&1 || ! nvidia-smi -L >/dev/null 2>&1; then
  CONSTRAINTS=(-c constraints/cpu.txt)
fi
if ! .venv/bin/python -c "import mitsuba_platonic" >/dev/null 2>&1 || [ pyproject.toml -nt .venv/.installed ]; then
  echo "setup: installing the package into .venv"
  .venv/bin/python -m pip install -q --disable-pip-version-check "${CONSTRAINTS[@]}" -e ".[test,notebooks,viewer]"
  touch .venv/.installed
fi
