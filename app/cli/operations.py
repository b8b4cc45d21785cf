"""Operations commands: ``backup DEST`` and ``restore SRC`` (:mod:`app.operations.backup`)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from app.cli._common import core_settings, echo

__all__ = ["backup", "restore"]


def backup(
    dest: Annotated[Path, typer.Argument(help="New directory to write the backup to (must not exist or be empty)")],
) -> None:
    """Back up the database and the run store (consistent, while the service runs).

    SQLite: the online backup API; PostgreSQL: pg_dump of an exported snapshot.
    Then the run files of the snapshot's runs, with their sha256 in DEST/manifest.json.
    See docs/operations.md.
    """
    from app.operations.backup import BackupError
    from app.operations.backup import backup as take

    try:
        result = take(core_settings(), dest)
    except BackupError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(1) from None
    echo(f"backup {result.dest}: {result.database} database at {result.revision}, {result.n_runs} runs, "
         f"{result.n_files} files ({result.bytes / 1e6:.1f} MB) in {result.seconds:.1f} s")


def restore(
    src: Annotated[Path, typer.Argument(help="Backup directory written by `trackvkf backup`")],
    force: Annotated[bool, typer.Option(help="Replace a database and run store that hold data "
                                             "(both are kept aside)")] = False,
    verify_only: Annotated[bool, typer.Option(help="Only verify the backup (checksums, database, "
                                                   "revision); change nothing")] = False,
) -> None:
    """Restore a backup into TRACKVKF_DATABASE_URL and TRACKVKF_RUN_STORE (stop the service first).

    The backup is verified, read-only, before anything is touched (no symbolic links, relative paths,
    run file checksums, the snapshot's integrity, revision and row counts against the manifest); the
    target's database and run store are kept aside; the database is upgraded to the head if the backup is older; jobs that were
    running at backup time are queued again. See docs/operations.md.
    """
    from app.operations.backup import BackupError, verify_backup
    from app.operations.backup import restore as put_back

    try:
        if verify_only:
            manifest = verify_backup(src)
            echo(f"backup {src} verified: {manifest['database']} at {manifest['revision']}, "
                 f"{len(manifest['files'])} run files")
            return
        result = put_back(core_settings(), src, force=force)
    except (BackupError, OSError) as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(1) from None
    echo(f"restored {result.database} database ({result.revision_in_backup} -> {result.revision_now}) and "
         f"{result.n_files} run files in {result.seconds:.1f} s"
         + (f"; jobs queued again: {result.requeued_jobs}" if result.requeued_jobs else "")
         + (f"; the previous database is at {result.previous_database}" if result.previous_database else "")
         + (f"; the previous run store is at {result.previous_run_store}" if result.previous_run_store else ""))
