"""Helpers of the end-to-end fault tests: profiles over HTTP, waiting, job posting,
and the reference profile of a clean in-process run."""

from __future__ import annotations

import io
import time
from pathlib import Path

import httpx
import pandas as pd
from sqlalchemy import func, select

from app.db.models import JobChunk, ProfileBin
from app.db.session import Database

#: several chunks (7) on the short simulated run
FAULT_SETTINGS = {"chunk_seconds": 5.0}


def profile(client: httpx.Client, run_id: int) -> pd.DataFrame:
    """The run's profile rows (all wheels) from the Parquet export, sorted."""
    r = client.get(f"/api/v1/runs/{run_id}/profile.parquet")
    assert r.status_code == 200, r.text
    return pd.read_parquet(io.BytesIO(r.content)).sort_values(["wheel", "bin"], ignore_index=True)


def wait_for(predicate, timeout_s: float, what: str, service) -> None:
    """Poll ``predicate`` (errors count as False) until true; fail with the logs."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            if predicate():
                return
        except (httpx.HTTPError, KeyError, ValueError):
            pass
        time.sleep(0.1)
    raise AssertionError(f"timed out waiting for {what}:\n{service.log_text()}")


def job(client: httpx.Client, job_id: int) -> dict:
    r = client.get(f"/api/v1/jobs/{job_id}")
    r.raise_for_status()
    return r.json()


def wait_final(client: httpx.Client, job_id: int, service, timeout_s: float = 240) -> dict:
    """Wait until a job is done/failed/cancelled, tolerating API errors meanwhile."""
    out: dict = {}

    def final() -> bool:
        out.update(job(client, job_id))
        return out["status"] in ("done", "failed", "cancelled")

    wait_for(final, timeout_s, f"job {job_id} final", service)
    return out


def upload_with_job(client: httpx.Client, path: Path, settings: dict | None = None) -> tuple[int, int]:
    """Upload a run, replace its default job by one with ``settings``: (run_id, job_id)."""
    with open(path, "rb") as fh:
        r = client.post("/api/v1/runs", files={"file": (path.name, fh)})
    assert r.status_code in (200, 201), r.text
    run = r.json()
    assert client.post(f"/api/v1/jobs/{run['latest_job']['id']}/cancel").status_code == 200
    r = client.post(f"/api/v1/runs/{run['id']}/jobs", json=settings or FAULT_SETTINGS)
    assert r.status_code in (200, 201, 202), r.text
    return run["id"], r.json()["id"]


def assert_same_as_clean(got: pd.DataFrame, reference: pd.DataFrame) -> None:
    """Profile rows equal to a clean run's (same bins, values within 1e-9 relative)."""
    cols = [c for c in reference.columns if c in got.columns]
    assert {"wheel", "bin", "km", "sleeper_amp", "n_samples"} <= set(cols)
    pd.testing.assert_frame_equal(
        got[cols].reset_index(drop=True), reference[cols].reset_index(drop=True),
        check_exact=False, rtol=1e-9, check_dtype=False,
    )


def assert_rows_once(database_url: str, job_id: int, n_profile_rows: int, n_chunks: int) -> None:
    """One profile row per (wheel, bin), all from ``job_id``; one chunk row per chunk; every
    row's display level that of the pyramid over its whole wheel (however the rows were
    written: at once, or chunk by chunk with the levels corrected at the end)."""
    from app.analysis.aggregate import display_levels

    db = Database(database_url)
    try:
        with db.read() as s:
            assert s.scalar(select(func.count()).select_from(ProfileBin)) == n_profile_rows
            assert set(s.scalars(select(ProfileBin.job_id).distinct())) == {job_id}
            rows = pd.DataFrame(
                s.execute(select(ProfileBin.wheel, ProfileBin.bin, ProfileBin.sleeper_amp,
                                 ProfileBin.display_level)).all(),
                columns=["wheel", "bin", "amp", "level"],
            )
            for wheel, w in rows.groupby("wheel"):
                expected = display_levels(w["bin"].to_numpy(), w["amp"].to_numpy(dtype=float))
                assert (w["level"].to_numpy() == expected).all(), f"display levels of wheel {wheel}"
            n_chunk_rows = s.scalar(
                select(func.count()).select_from(JobChunk).where(JobChunk.job_id == job_id)
            )
            assert n_chunk_rows == n_chunks
    finally:
        db.dispose()
