"""A generated fleet history written into the condition store (``trackvkf simulate-fleet``).

Each generated run (:class:`app.simulate.fleet.FleetSimulator`) becomes a run
row and a done job (source format ``fleet``: no run file and no 25 cm rows,
marked like a run whose profile rows the retention sweep removed), and its segment
rows, change tests and flags are written exactly as the publish step writes a
processed run's (:func:`app.condition.writer.wheel_segments`: the store's one
index function; :func:`app.condition.writer.write_assessed_run`), one
transaction per run. The change tests read the history from an in-memory
window (:class:`app.analysis.condition.RollingHistory`, the same matrices
:class:`~app.condition.writer.DbHistory` builds from the store), so a year
is written in minutes. The planted maintenance actions and the line's
superstructure sections are imported as reference data, replacing the line's.
Generated runs send no webhook alerts (a year of history at once is not news).
"""

from __future__ import annotations

import datetime as dt
import hashlib
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
from sqlalchemy import func, select

from app.analysis.condition import DEFAULT_CHANGE_PARAMS, ChangeParams, RollingHistory, assess_run
from app.analysis.settings import ProcessingSettings
from app.analysis.units import KMH_PER_MPS
from app.condition.actions import days_of
from app.condition.config import FLEET_SOURCE_FORMAT
from app.condition.writer import wheel_segments, write_assessed_run
from app.db import reference_crud
from app.db.condition_store import line_of
from app.db.models import Job, JobStatus, Run, SegmentCondition, utcnow
from app.db.session import Database
from app.simulate.fleet import FLEET_WHEELS, FleetDay, FleetSimulator

__all__ = ["FleetIngest", "FLEET_SOURCE_FORMAT", "fleet_history", "ingest_fleet"]

def _segments(sim: FleetSimulator, tracks: dict) -> dict:
    """A generated run's segments with the store's index (:func:`app.condition.writer.wheel_segments`;
    the generator states no 1-sigma: ``index_sd`` NaN, its noise being a run-to-run repeatability
    model the change tests' spread of the history measures already)."""
    positions = {w: (t.position_m, t.amplitude, t.speed_mps) for w, t in tracks.items()}
    return wheel_segments(positions, bin_length_m=sim.grid_m, bins_per_cell=int(round(sim.grid_m / sim.line.bin_length)))


def fleet_history(
    sim: FleetSimulator,
    n_runs: int,
    *,
    every_days: float = 1.0,
    seed: int = 0,
    params: ChangeParams = DEFAULT_CHANGE_PARAMS,
) -> Iterator[FleetDay]:
    """Generate ``n_runs`` runs ``every_days`` apart (day 0 first) and assess each against the
    ones before it (:func:`~app.analysis.condition.assess_run` over a
    :class:`~app.analysis.condition.RollingHistory`), in date order, in memory: what a detection
    is scored against the plan with (:func:`app.simulate.fleet_scoring.score_history`)."""
    if n_runs < 1:
        raise ValueError(f"n_runs: must be >= 1, got {n_runs!r}")
    history = RollingHistory(params)
    for i in range(n_runs):
        day = i * every_days
        speed, tracks = sim.run(day, np.random.default_rng([seed, i]))
        segs = _segments(sim, tracks)
        assessment = assess_run(segs, history, day, params=params, previous_flags=history.flags)
        history.append(day, segs, assessment.flags)
        yield FleetDay(i, day, speed, tracks, segs, assessment)


@dataclass(frozen=True)
class FleetIngest:
    """What :func:`ingest_fleet` wrote.

    Attributes
    ----------
    runs, skipped : int
        Runs written, and runs already in the database (same seed and number).
    segment_rows, flags : int
        Segment rows and flags written.
    seconds : float
        Wall time of the whole ingest, s.
    write_seconds : float
        Of which in database transactions, s.
    """

    runs: int
    skipped: int
    segment_rows: int
    flags: int
    seconds: float
    write_seconds: float


def _sha(line_id: str, track: str, seed: int, number: int) -> str:
    return hashlib.sha256(f"trackvkf-fleet:{line_id}:{track}:{seed}:{number}".encode()).hexdigest()


def ingest_fleet(
    db: Database,
    sim: FleetSimulator,
    n_runs: int,
    *,
    line_id: str,
    track: str = "1",
    start: dt.datetime,
    every_days: float = 1.0,
    seed: int = 0,
    vehicle_id: str = "FLEET-SIM",
    params: ChangeParams = DEFAULT_CHANGE_PARAMS,
    reference: bool = True,
    progress: Callable[[int, int], None] | None = None,
    on_run: Callable[[FleetDay], None] | None = None,
) -> FleetIngest:
    """Generate ``n_runs`` runs of ``sim`` (day ``i · every_days`` after ``start``) and store them.

    Runs already stored by an earlier call with the same line, track and seed
    are kept and skipped (their history is regenerated in memory, so the runs
    after them are judged against the same history). ``on_run`` sees every
    generated run with its assessment (e.g. to score the flags against the plan,
    :func:`app.simulate.fleet_scoring.score_history`).
    """
    if n_runs < 1:
        raise ValueError(f"n_runs: must be >= 1, got {n_runs!r}")
    if start.tzinfo is None:
        raise ValueError("start: give a timezone")
    t0 = time.perf_counter()
    write_s = 0.0
    history = RollingHistory(params)
    written = skipped = rows = n_flags = 0
    settings = ProcessingSettings().to_dict()
    length_m = sim.line.track_to_m - sim.line.track_from_m
    for i in range(n_runs):
        day = i * every_days
        when = start + dt.timedelta(days=day)
        speed_kmh, tracks = sim.run(day, np.random.default_rng([seed, i]))
        sha = _sha(line_id, track, seed, i)
        t1 = time.perf_counter()
        with db.write() as session:
            line = line_of(session, line_id, track, sim.line.bin_length)
            segments = _segments(sim, tracks)
            assessment = assess_run(segments, history, days_of(when), params=params, previous_flags=history.flags)
            if session.scalar(select(Run.id).where(Run.sha256 == sha)) is not None:
                skipped += 1
            else:
                run = Run(sha256=sha, file_path="", source_format=FLEET_SOURCE_FORMAT, original_filename=None,
                          size_bytes=0, vehicle_id=vehicle_id, line_id=line_id, track=track, direction="up",
                          start_time=when, km_start=sim.line.track_from_m / 1000.0, km_increasing=True, fs=0.0,
                          n_samples=0, duration_s=length_m / (speed_kmh / KMH_PER_MPS), distance_m=length_m,
                          speed_min=float(np.min(tracks[FLEET_WHEELS[0]].speed_mps)),
                          speed_max=float(np.max(tracks[FLEET_WHEELS[0]].speed_mps)),
                          channels=[f"Z{w}" for w in FLEET_WHEELS],
                          meta={"simulated_fleet": {"seed": seed, "number": i, "speed_kmh": round(speed_kmh, 2)}},
                          created_by="simulate-fleet", created_at=utcnow(), profiles_swept_at=utcnow())
                session.add(run)
                session.flush()
                job = Job(run_id=run.id, status=JobStatus.DONE, progress=1.0, settings=settings, attempts=1,
                          created_by="simulate-fleet", created_at=utcnow(), started_at=utcnow(),
                          finished_at=utcnow())
                session.add(job)
                session.flush()
                flags = write_assessed_run(session, run_id=run.id, job_id=job.id, line=line, when=when,
                                           segments=segments, assessment=assessment)
                job.meta = {"simulated_fleet": True, "condition": {
                    "stored": True, "flags": len(flags), "new_flag_ids": [f.id for f in flags if f.is_new],
                    "history_runs": min(i, params.history_scan_runs)}}
                written += 1
                n_flags += len(flags)
                rows += int(sum(len(st) for w in segments.values() for st in w.values()))
        write_s += time.perf_counter() - t1
        history.append(days_of(when), segments, assessment.flags)
        if on_run is not None:
            on_run(FleetDay(i, day, speed_kmh, tracks, segments, assessment))
        if progress is not None:
            progress(i + 1, n_runs)
    if reference:
        _import_reference(db, sim, line_id, track, start)
    return FleetIngest(written, skipped, rows, n_flags, time.perf_counter() - t0, write_s)


def _import_reference(db: Database, sim: FleetSimulator, line_id: str, track: str, start: dt.datetime) -> None:
    """The planted maintenance actions and the line's sections as reference data (replacing the line's)."""
    actions = [{"line_id": line_id, "track": track, "km_from": a.track_from_m / 1000.0, "km_to": a.track_to_m / 1000.0,
                "type": a.type, "date": (start + dt.timedelta(days=a.day)).date()} for a in sim.plan.actions]
    sections = [{"line_id": line_id, "track": track, "km_from": s.km_from, "km_to": s.km_to, "type": s.type,
                 "details": "simulated fleet"} for s in sim.line.sections]
    with db.write() as session:
        reference_crud.delete_reference(session, "maintenance", line_id, track)
        if actions:
            reference_crud.insert_reference(session, "maintenance", actions)
        reference_crud.insert_reference(session, "superstructure", sections, replace=True)


def segment_row_count(db: Database) -> int:
    """Rows of the segment condition store (for reports)."""
    with db.read() as session:
        return int(session.scalar(select(func.count()).select_from(SegmentCondition)) or 0)
