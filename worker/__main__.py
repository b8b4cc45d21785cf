"""``python -m worker``: run the local worker (same as ``trackvkf worker``)."""

from __future__ import annotations

import argparse
import sys

from app.core.config import get_settings
from app.core.logging import configure_logging
from worker.runner import run_worker


def main(argv: list[str] | None = None) -> int:
    """Parse arguments and run the worker loop; returns the exit status."""
    parser = argparse.ArgumentParser(
        prog="python -m worker",
        description="Process queued trackvkf jobs (settings from TRACKVKF_* variables).",
    )
    parser.add_argument("--once", action="store_true", help="exit after one job")
    parser.add_argument(
        "--exit-when-idle", action="store_true", help="exit when no job is queued"
    )
    parser.add_argument("--log-level", default=None, help="logging level (default: settings)")
    args = parser.parse_args(argv)
    settings = get_settings()
    configure_logging(args.log_level or settings.log_level)
    try:
        run_worker(settings, once=args.once, exit_when_idle=args.exit_when_idle)
    except KeyboardInterrupt:
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
