#!/usr/bin/env bash
# Run the whole test suite (pytest) in .venv, creating/refreshing it first with the
# dev extras (pytest, playwright, ruff, ...; the demo installs the runtime only).
# Extra arguments go to pytest, e.g.  ./scripts/test.sh tests/api -x
# The 20 slowest set-ups and tests are listed at the end (--durations=20). Processed data sets
# are built once and kept in .pytest_cache/d/trackvkf-datasets (tests/datasets.py; a clean
# checkout builds each once per session; `pytest --cache-clear` empties it).
# TRACKVKF_TEST_WORKERS=N runs the tests in N processes (pytest-xdist): a module's tests stay
# together in one of them (--dist loadscope: module fixtures are made once), the data sets are built by whichever asks first and read by the others;
# tests/xdist_schedule.py groups the modules sharing a session service and hands the long
# modules out first (so the processes end together).
# Default 4 on the 2-core CI machine: a test process often waits (on services, workers, browsers
# and their polls) and another fills the cores meanwhile; clean clone: 26:17 with 2, 24:37 with 3,
# 22:31 with 4 (then: 15:52 to 17:18 with the byte code kept, below); 2026-11-30, 2021 tests: 20:40 with 4,
# 22:18 with 6 (the suite is CPU-bound: 1 986 CPU s with 4); 2029–2037 tests: 17:40 to 21:13 with 4 (1 655 to 2 003 CPU s).
# 0: everything in this one process.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
# the test processes keep their byte code (pytest's rewritten test modules, the helpers, the packages):
# each of them and of the services they start would otherwise compile the same modules again
unset PYTHONDONTWRITEBYTECODE
bash scripts/setup.sh --dev
workers="${TRACKVKF_TEST_WORKERS:-4}"
exec .venv/bin/python -m pytest -q --durations=20 -n "$workers" --dist loadscope "$@"
