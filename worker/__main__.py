"""``python -m worker``: run the worker (same as ``trackvkf worker``).

The database URL picks the mode (:func:`worker.modes.run`): SQLite → the
local job loop (:mod:`worker.runner`); PostgreSQL → Procrastinate workers
(:mod:`worker.tasks`), unless ``--local`` asks for the local loop.
"""

from __future__ import annotations

import argparse
import sys

from app.core.logging import configure_logging
from app.settings import get_settings
from worker import modes


def main(argv: list[str] | None = None) -> int:
    """Parse arguments and run the worker loop; returns the exit status."""
    parser = argparse.ArgumentParser(
        prog="python -m worker",
        description="Process queued trackvkf jobs (settings from TRACKVKF_* variables).",
    )
    parser.add_argument("--once", action="store_true", help="exit after one job (local mode)")
    parser.add_argument(
        "--exit-when-idle", action="store_true", help="exit when no job is queued"
    )
    parser.add_argument(
        "--processes", type=int, default=1,
        help="PostgreSQL mode: worker processes to run (0 = one per core; default 1)",
    )
    parser.add_argument(
        "--local", action="store_true",
        help="use the local job loop even on PostgreSQL (one machine)",
    )
    parser.add_argument("--log-level", default=None, help="logging level (default: settings)")
    args = parser.parse_args(argv)
    settings = get_settings()
    configure_logging(args.log_level or settings.log_level, settings.log_format)
    return modes.run(
        settings, local=args.local, once=args.once, exit_when_idle=args.exit_when_idle,
        processes=args.processes,
    )


if __name__ == "__main__":
    sys.exit(main())
