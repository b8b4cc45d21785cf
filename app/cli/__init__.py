"""Command line of trackvkf: ``serve``, ``worker``, ``migrate``, ``demo``, ``simulate``,
``process``, ``simulate-fleet``, ``sweep-profiles``, ``apply-places``, ``backup``, ``restore``, ``user``
(create, set-password, list) and ``key`` (create, revoke, list).

Every command reads the service settings from ``TRACKVKF_*`` environment
variables (see :class:`app.settings.Settings`). The commands live by group:
:mod:`app.cli.service` (serve, worker, migrate), :mod:`app.cli.processing`
(simulate, process), :mod:`app.cli.condition` (simulate-fleet, sweep-profiles, apply-places),
:mod:`app.cli.accounts` (user, key), :mod:`app.cli.demo`, :mod:`app.cli.operations` (backup, restore).
"""

from __future__ import annotations

import typer

from app.cli import accounts, condition, demo, operations, processing, service

__all__ = ["app", "main"]

# rich_markup_mode=None: click's plain help (Typer's rich panels label flags "<bool>")
app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    rich_markup_mode=None,
    help="Track stiffness and wheel out-of-roundness from axle-box accelerations.",
)
app.command()(service.serve)
app.command()(service.worker)
app.command()(service.migrate)
app.command()(processing.simulate)
app.command()(processing.process)
app.command("simulate-fleet")(condition.simulate_fleet)
app.command("sweep-profiles")(condition.sweep_profiles)
app.command("apply-places")(condition.apply_places)
app.add_typer(accounts.user_app, name="user")
app.add_typer(accounts.key_app, name="key")
app.command()(demo.demo)
app.command()(operations.backup)
app.command()(operations.restore)


def main() -> None:
    """Entry point of the ``trackvkf`` console script."""
    app()
