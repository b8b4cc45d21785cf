#!/usr/bin/env bash
# Throw-away PostgreSQL cluster on 127.0.0.1 for tests, benchmarks and trying the production mode.
#   scripts/postgres.sh start DIR   # init (first time) and start; prints the SQLAlchemy URL
#   scripts/postgres.sh stop DIR
#   scripts/postgres.sh url DIR
# Installs the Debian "postgresql" package with apt-get when the server is missing (as root).
# As root the server runs as the "postgres" system user. Remove DIR to delete the cluster.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
py="${PYTHON:-}"
if [[ -z "$py" ]]; then
  if [[ -x "$root/.venv/bin/python" ]]; then py="$root/.venv/bin/python"; else py=python3; fi
fi
PYTHONPATH="$root${PYTHONPATH:+:$PYTHONPATH}" exec "$py" -m tests.pg_cluster "$@"
