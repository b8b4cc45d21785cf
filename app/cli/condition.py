"""Commands of the condition store: ``simulate-fleet`` (a generated history of daily runs),
``sweep-profiles`` (retention of the 25 cm rows) and ``apply-places`` (the places of runs already in the
store)."""

from __future__ import annotations

import datetime as dt
from typing import Annotated

import typer

from app.cli._common import database, echo

__all__ = ["simulate_fleet", "sweep_profiles", "apply_places"]


def simulate_fleet(
    line_id: Annotated[str, typer.Option(help="Line id of the generated runs")] = "FLEET",
    track: Annotated[str, typer.Option(help="Track")] = "1",
    length_km: Annotated[float, typer.Option(help="Length of the line, km")] = 50.0,
    km_start: Annotated[float, typer.Option(help="km of the line's start")] = 0.0,
    runs: Annotated[int, typer.Option(help="Number of runs")] = 365,
    every_days: Annotated[float, typer.Option(help="Days between two runs")] = 1.0,
    start_date: Annotated[str, typer.Option(help="Date of the first run (ISO, UTC)")] = "2025-01-01",
    speed_kmh: Annotated[float, typer.Option(help="Nominal speed of the runs, km/h")] = 120.0,
    seed: Annotated[int, typer.Option(help="Random seed (line, planted changes, noise)")] = 0,
    steps: Annotated[int | None, typer.Option(help="Planted 20 % steps over 20 m (default: one per 2 km)")] = None,
    trends: Annotated[int | None, typer.Option(help="Planted 10 %/year trends (default: one per 10 km)")] = None,
    actions: Annotated[int | None, typer.Option(help="Planted tamping actions (default: one per 5 km)")] = None,
    reference: Annotated[bool, typer.Option(
        help="Import the planted maintenance actions and the line's sections as reference data")] = True,
) -> None:
    """Write a generated fleet history into the condition store (TRACKVKF_DATABASE_URL, migrated).

    Segment rows of every run come from the simulator's truth with realistic
    repeatability noise and planted changes (steps, gradual trends, tamping with
    its recovery), and are judged by the same change tests as published runs.
    Run again with the same options: the runs already written are kept.
    """
    from app.condition.config import ConditionConfig
    from app.condition.fleet import ingest_fleet
    from app.settings import get_settings
    from app.simulate.fleet import FleetSimulator, random_plan
    from app.simulate.track import generate_line

    if not length_km > 0 or runs < 1 or not every_days > 0:
        raise typer.BadParameter("--length-km and --every-days must be > 0 and --runs >= 1")
    try:
        start = dt.datetime.combine(dt.date.fromisoformat(start_date), dt.time(8, 0), tzinfo=dt.UTC)
    except ValueError:
        raise typer.BadParameter(f"not an ISO date: {start_date!r}", param_hint="--start-date") from None
    lo, hi = km_start * 1000.0, (km_start + length_km) * 1000.0
    line = generate_line(lo, hi, seed=seed)
    plan = random_plan(lo, hi, int(runs * every_days), seed=seed + 1,
                       n_steps=steps if steps is not None else max(1, round(length_km / 2)),
                       n_trends=trends if trends is not None else max(1, round(length_km / 10)),
                       n_actions=actions if actions is not None else max(1, round(length_km / 5)))
    sim = FleetSimulator(line, plan, speed_kmh=speed_kmh)
    params = ConditionConfig.from_settings(get_settings()).change
    echo(f"line {line_id!r} track {track!r}: km {km_start:g}–{km_start + length_km:g}, {runs} runs every "
         f"{every_days:g} day(s) from {start.date()}; planted {len(plan.steps)} steps, {len(plan.trends)} trends, "
         f"{len(plan.actions)} tamping actions")
    db = database()
    try:
        def progress(done: int, total: int) -> None:
            if done % 25 == 0 or done == total:
                echo(f"  {done}/{total} runs")

        result = ingest_fleet(db, sim, runs, line_id=line_id, track=track, start=start, every_days=every_days,
                              seed=seed, params=params, reference=reference, progress=progress)
    finally:
        db.dispose()
    echo(f"wrote {result.runs} runs ({result.skipped} already there), {result.segment_rows} segment rows, "
         f"{result.flags} flags in {result.seconds:.1f} s ({result.write_seconds:.1f} s in the database)")


def sweep_profiles(
    older_than_days: Annotated[int | None, typer.Option(
        help="Remove the 25 cm rows of runs measured more than this many days ago "
        "(default: TRACKVKF_PROFILE_RETENTION_DAYS)")] = None,
    dry_run: Annotated[bool, typer.Option(help="Only count the runs")] = False,
) -> None:
    """Remove old 25 cm profile rows (segment condition rows stay); the workers do it hourly when
    TRACKVKF_PROFILE_RETENTION_DAYS is set."""
    from app.db.models import utcnow
    from app.db.retention import sweep_profiles as sweep
    from app.settings import get_settings

    days = older_than_days if older_than_days is not None else get_settings().profile_retention_days
    if days is None or days < 1:
        raise typer.BadParameter("give --older-than-days N (>= 1) or set TRACKVKF_PROFILE_RETENTION_DAYS",
                                 param_hint="--older-than-days")
    db = database()
    try:
        result = sweep(db, utcnow() - dt.timedelta(days=days), dry_run=dry_run)
    finally:
        db.dispose()
    what = "would lose" if dry_run else "lost"
    echo(f"{result.runs} run(s) measured more than {days} days ago {what} their 25 cm rows"
         + ("" if dry_run else f" ({result.rows} rows deleted, partitions dropped: "
                                f"{', '.join(result.partitions) or 'none'}) in {result.seconds:.1f} s"))


def apply_places(
    line_id: Annotated[str, typer.Option(help="Line id")],
    track: Annotated[str, typer.Option(help="Track")] = "1",
) -> None:
    """Apply the runs of a line already in the condition store to its places, oldest first (runs published
    before the places existed — after upgrading — or a generated fleet history). A run applied already,
    or older than the newest applied one, is left as it is. Sends no alerts."""
    from app.places.config import PlacesConfig
    from app.places.followup import apply_stored_runs
    from app.settings import get_settings

    db = database()
    try:
        done = apply_stored_runs(db, line_id, track, config=PlacesConfig.from_settings(get_settings()))
    finally:
        db.dispose()
    applied = [u for u in done if u.applied]
    events = sum(len(u.events) for u in applied)
    echo(f"line {line_id!r} track {track!r}: {len(applied)} run(s) applied, {len(done) - len(applied)} not "
         f"({'; '.join(sorted({u.reason for u in done if not u.applied}))}); {events} place event(s)"
         if len(done) != len(applied) else
         f"line {line_id!r} track {track!r}: {len(applied)} run(s) applied; {events} place event(s)")
