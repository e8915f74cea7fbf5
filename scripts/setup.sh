#!/usr/bin/env bash
# Set up the project environment on a fresh machine, or reuse the cached one.
#
# The virtualenv lives OUTSIDE the clone, in $LEROBOT_OCR_CACHE (default ~/.cache/lerobot-ocr),
# keyed on a hash of uv.lock + pyproject.toml, so CI's fresh clones reuse it until the lock changes.
# `.venv` in the clone is a symlink to it. Needs Python 3.12 on the machine (pyenv or system) and
# PyPI; installs uv (pinned) into the cache if it is not on PATH.
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
CACHE=${LEROBOT_OCR_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/lerobot-ocr}
UV_VERSION=0.13.9
mkdir -p "$CACHE"

find_python() {
  local c
  for c in "${LEROBOT_OCR_PYTHON:-}" "$HOME"/.pyenv/versions/3.12*/bin/python3.12 python3.12 /usr/bin/python3.12 /usr/local/bin/python3.12; do
    [ -n "$c" ] || continue
    if command -v "$c" >/dev/null 2>&1 && "$c" -c 'import sys; assert sys.version_info[:2] == (3, 12)' 2>/dev/null; then
      command -v "$c"; return 0
    fi
  done
  return 1
}
PY=$(find_python) || { echo "setup: Python 3.12 not found; install it (e.g. pyenv install 3.12) or set LEROBOT_OCR_PYTHON." >&2; exit 1; }

if command -v uv >/dev/null 2>&1; then
  UV=$(command -v uv)
else
  UV="$CACHE/uv-$UV_VERSION/bin/uv"
  if [ ! -x "$UV" ]; then
    echo "setup: installing uv $UV_VERSION into $CACHE" >&2
    "$PY" -m venv "$CACHE/uv-$UV_VERSION"
    "$CACHE/uv-$UV_VERSION/bin/python" -m pip install -q "uv==$UV_VERSION"
  fi
fi

KEY=$(cat "$ROOT/uv.lock" "$ROOT/pyproject.toml" | sha256sum | cut -c1-16)
VENV="$CACHE/venv-$KEY"
[ -d "$VENV" ] || echo "setup: creating $VENV (first time: a few minutes, ~7 GB with torch)" >&2
# --frozen: install exactly the lock file. Re-running on a cached venv only re-links this clone (seconds).
UV_PROJECT_ENVIRONMENT="$VENV" "$UV" sync --frozen --all-extras --python "$PY" --project "$ROOT" -q
ln -sfn "$VENV" "$ROOT/.venv"
echo "setup: environment ready at $ROOT/.venv -> $VENV" >&2
