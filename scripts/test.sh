#!/usr/bin/env bash
# Run the whole test suite (pytest) in .venv, creating/refreshing it first with the
# dev extras (pytest, playwright, ruff, ...; the demo installs the runtime only).
# Extra arguments go to pytest, e.g.  ./scripts/test.sh tests/api -x
# The 20 slowest set-ups and tests are listed at the end (--durations=20). Processed data sets
# are built once and kept in .pytest_cache/d/trackvkf-datasets (tests/datasets.py; a clean
# checkout builds each once per session; `pytest --cache-clear` empties it).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
bash scripts/setup.sh --dev
exec .venv/bin/python -m pytest -q --durations=20 "$@"
