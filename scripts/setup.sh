#!/usr/bin/env bash
# Create or refresh .venv with trackvkf and its dev dependencies.
# Idempotent: re-installs only when pyproject.toml changed or the package is missing.
# Set PYTHON=/path/to/python3.11 to choose the interpreter.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

py="${PYTHON:-}"
if [[ -z "$py" ]]; then
  for candidate in python3.11 python3 python; do
    if command -v "$candidate" >/dev/null 2>&1 \
      && "$candidate" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
      py="$candidate"
      break
    fi
  done
fi
if [[ -z "$py" ]]; then
  echo "error: Python >= 3.11 not found; set PYTHON=/path/to/python3.11" >&2
  exit 1
fi

if [[ ! -x .venv/bin/python ]]; then
  echo "setup: creating .venv with $("$py" --version 2>&1)"
  "$py" -m venv .venv
fi

stamp=.venv/.trackvkf-install-stamp
want="$(.venv/bin/python -c 'import hashlib; print(hashlib.sha256(open("pyproject.toml", "rb").read()).hexdigest())')"
have="$(cat "$stamp" 2>/dev/null || true)"
if [[ "$have" != "$want" ]] \
  || ! .venv/bin/python -c 'import importlib.metadata as m; m.version("trackvkf")' >/dev/null 2>&1; then
  echo "setup: installing trackvkf and its dependencies into .venv ..."
  if ! .venv/bin/python -m pip install --disable-pip-version-check -e '.[dev]' \
    >.venv/pip-install.log 2>&1; then
    tail -n 40 .venv/pip-install.log >&2
    echo "error: pip install failed (full log: .venv/pip-install.log)" >&2
    exit 1
  fi
  echo "$want" >"$stamp"
fi
