"""Runs for the condition tests: generated fleet tracks published through the real publish step."""

from __future__ import annotations

import datetime as dt
from typing import Any

import numpy as np
import pandas as pd

from app import publish
from app.condition.config import ConditionConfig
from app.db.models import Job, JobStatus, Run, utcnow
from app.db.session import Database
from app.simulate.fleet import FleetSimulator, WheelTrack

__all__ = ["profile_frame_of", "publish_tracks", "publish_history", "DAY0"]

DAY0 = dt.datetime(2025, 1, 1, 8, 0, tzinfo=dt.UTC)


def profile_frame_of(tracks: dict[str, WheelTrack], bin_length_m: float = 0.25, shift_m: float = 0.0,
                     sd_rel: float | None = None) -> pd.DataFrame:
    """Profile rows (the columns the condition store reads) of generated tracks on a 25 cm grid.

    ``shift_m`` is an odometry error: the run's positions are reported that much too far. ``sd_rel``:
    the rows state ``sleeper_amp_sd = sd_rel · A`` (half of it shared), else none.
    """
    frames = []
    for wheel, t in tracks.items():
        pos = t.position_m + shift_m
        bins = np.floor(pos / bin_length_m).astype(np.int64)
        frames.append(pd.DataFrame({
            "wheel": wheel, "bin": bins, "km": (bins + 0.5) * bin_length_m / 1000.0,
            "n_samples": np.full(bins.size, 100), "speed_mean": t.speed_mps, "sleeper_amp": t.amplitude,
            **({} if sd_rel is None else {"sleeper_amp_sd": sd_rel * t.amplitude,
                                          "sleeper_amp_sd_shared": 0.5 * sd_rel * t.amplitude}),
        }))
    return pd.concat(frames, ignore_index=True)


def publish_tracks(
    db: Database, tracks: dict[str, WheelTrack], when: dt.datetime, *, line_id: str | None = "L1",
    track: str = "1", shift_m: float = 0.0, config: ConditionConfig | None = None, sha: str | None = None,
    run_id: int | None = None, places: Any = None, followup: bool = True, sd_rel: float | None = None,
) -> tuple[int, int, dict[str, Any]]:
    """Publish generated tracks as a processed run through :func:`app.publish.publish_job`
    (the local worker's path); returns (run id, job id, the job's condition summary). ``followup`` False:
    the places follow-up is not run after the commit (as if the worker died there)."""
    with db.write() as s:
        if run_id is None:
            run = Run(sha256=sha or f"{when.isoformat()}-{line_id}-{np.random.default_rng().integers(1 << 62)}",
                      file_path="x", source_format="hdf5", size_bytes=1, fs=10_000.0, n_samples=10,
                      duration_s=1.0, channels=[f"Z{w}" for w in tracks], meta={}, line_id=line_id,
                      track=track, start_time=when, created_at=utcnow())
            s.add(run)
            s.flush()
            run_id = run.id
        job = Job(run_id=run_id, status=JobStatus.RUNNING, worker_id="test-worker", settings={"bin_length_m": 0.25},
                  created_at=utcnow())
        s.add(job)
        s.flush()
        job_id = job.id
    kw = {"condition": config} if config is not None else {}
    if places is not None:
        kw["places"] = places
    if not followup:
        kw["places_followup"] = None
    assert publish.publish_job(db, job_id, run_id, profile_frame_of(tracks, shift_m=shift_m, sd_rel=sd_rel), [], {},
                              worker_id="test-worker", **kw)
    with db.read() as s:
        meta = s.get(Job, job_id).meta
    return run_id, job_id, meta["condition"]


def publish_history(db: Database, sim: FleetSimulator, n_runs: int, *, seed: int = 0, every_days: float = 1.0,
                    config: ConditionConfig | None = None, line_id: str = "L1") -> list[tuple[int, dict[str, Any]]]:
    """Publish ``n_runs`` generated runs of ``sim`` in date order; (run id, summary) of each."""
    out = []
    for i in range(n_runs):
        _, tracks = sim.run(i * every_days, np.random.default_rng([seed, i]))
        run_id, _, summary = publish_tracks(db, tracks, DAY0 + dt.timedelta(days=i * every_days), config=config,
                                            line_id=line_id)
        out.append((run_id, summary))
    return out
