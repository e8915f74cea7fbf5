#!/usr/bin/env bash
# Lint (ruff, settings in pyproject.toml) and run the test suite in the project environment (set up first if needed).
# Extra arguments go to pytest, e.g. `bash scripts/test.sh -m "not slow"` to skip integration tests.
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
bash "$ROOT/scripts/setup.sh"
cd "$ROOT"
# This clone's sources first: the cached venv is shared by clones with the same lock file and its
# editable install points at whichever clone ran setup last.
export PYTHONPATH="$ROOT/src${PYTHONPATH:+:$PYTHONPATH}"
export MUJOCO_GL=${MUJOCO_GL:-egl} SDL_VIDEODRIVER=${SDL_VIDEODRIVER:-dummy} HF_HUB_OFFLINE=${HF_HUB_OFFLINE:-1}
.venv/bin/ruff check --quiet . || { echo "ruff check failed: fix the lines above (.venv/bin/ruff check --fix . fixes some)" >&2; exit 1; }
exec .venv/bin/python -m pytest "$@"
