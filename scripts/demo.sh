#!/usr/bin/env bash
# The demo in one command: set up .venv, migrate the SQLite database, simulate a
# demo run, start the API and a worker, upload and process the run over HTTP,
# print where to look, and keep serving until Ctrl-C.
# Options go to `trackvkf demo`, e.g.  ./scripts/demo.sh --port 8080 --length-km 5
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
bash scripts/setup.sh
exec .venv/bin/trackvkf demo "$@"
