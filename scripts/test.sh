#!/usr/bin/env bash
# Run the whole test suite (pytest) in .venv, creating/refreshing it first with the
# dev extras (pytest, playwright, ruff, ...; the demo installs the runtime only).
# Extra arguments go to pytest, e.g.  ./scripts/test.sh tests/api -x
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
bash scripts/setup.sh --dev
exec .venv/bin/python -m pytest -q "$@"
