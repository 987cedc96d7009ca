#!/usr/bin/env bash
# The main job on the built-in default data: set up, then run it.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
exec .venv/bin/platonic quickstart "$@"
