"""A simulated history through the real service: upload over the API, the local worker's pipeline,
the publish step and its condition store (what the work list tests and the places benchmark use)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from app.simulate.history import HistoryFiles, HistorySpec, write_history

__all__ = ["ProcessedHistory", "history_service", "process_history", "store_flags_without", "places_without_sd"]


@dataclass
class ProcessedHistory:
    """A history processed into a service's database.

    Attributes
    ----------
    spec : HistorySpec
    files : HistoryFiles
    client : fastapi.testclient.TestClient
        Admin client of the service (``client.settings``: its settings).
    run_ids : list of int
        Run ids in the order of ``spec.runs``.
    jobs : list of dict
        The final state of each run's job.
    """

    spec: HistorySpec
    files: HistoryFiles
    client: Any
    run_ids: list[int] = field(default_factory=list)
    jobs: list[dict] = field(default_factory=list)

    @property
    def database_url(self) -> str:
        return self.client.settings.database_url


@contextmanager
def history_service(tmp_path: Path, **overrides: Any) -> Iterator[Any]:
    """An admin API client on a fresh migrated SQLite database (settings overridable)."""
    from fastapi.testclient import TestClient

    from app.db import migrate
    from app.main import create_app
    from tests.api.support import auth_headers, create_api_key, make_settings

    settings = make_settings(tmp_path, **overrides)
    migrate.upgrade(settings.database_url)
    key = create_api_key(settings.database_url, "admin")
    with TestClient(create_app(settings), headers=auth_headers(key)) as client:
        client.settings = settings  # type: ignore[attr-defined]
        client.api_key = key  # type: ignore[attr-defined]
        yield client


def _post(client: Any, url: str, path: Path, params: dict | None = None) -> dict:
    with open(path, "rb") as fh:
        r = client.post(url, params=params, files={"file": (path.name, fh)})
    assert r.status_code in (200, 201), f"{url} {path.name}: {r.status_code} {r.text}"
    return r.json()


def process_history(client: Any, spec: HistorySpec, file_dir: Path, *, runs: slice | None = None,
                    reference: bool = True) -> ProcessedHistory:
    """Write the history's files (if missing), import its reference data and upload and process
    its runs one by one in date order with the real local worker.

    Parameters
    ----------
    client : TestClient
        Admin client (:func:`history_service`).
    spec : HistorySpec
    file_dir : Path
        Where the run files are written (reused between tests and benchmarks).
    runs : slice, optional
        Only these runs (default all).
    reference : bool
        Import the superstructure sections, the maintenance actions and the asset register (where the
        history has one) first.
    """
    from app.db.session import Database
    from worker.runner import LocalWorker

    files = write_history(spec, file_dir)
    out = ProcessedHistory(spec, files, client)
    if reference:
        _post(client, "/api/v1/reference/superstructure", files.superstructure, {"mode": "replace"})
        if spec.maintenance().shape[0]:
            _post(client, "/api/v1/reference/maintenance", files.maintenance, {"mode": "replace"})
        if files.assets is not None:
            _post(client, "/api/v1/assets", files.assets)
    db = Database(client.settings.database_url)
    try:
        worker = LocalWorker(client.settings, db=db)
        try:
            for path in files.runs[runs or slice(None)]:
                run = _post(client, "/api/v1/runs", path)
                worker.run(exit_when_idle=True)
                job = client.get(f"/api/v1/jobs/{run['latest_job']['id']}").json()
                assert job["status"] == "done", f"{path.name}: job {job['id']} {job['status']}: {job.get('error')}"
                out.run_ids.append(run["id"])
                out.jobs.append(job)
        finally:
            worker.runtime.close()
    finally:
        db.dispose()
    return out


@dataclass
class StoredRun:
    """A run's 10 m segment rows as the condition store holds them (wheels × segments).

    ``log_amp`` is the store's condition index ``ln(A / 1 m/s²)``, ``speed`` m/s; ``classes`` the
    superstructure class per segment (None near a change of class or outside the sections).
    """

    run_id: int
    day: float
    seg: Any
    wheels: list[str]
    log_amp: Any
    speed: Any
    classes: Any
    index_sd: Any = None


def stored_runs(database_url: str, spec: HistorySpec, *, margin_m: float = 50.0) -> list[StoredRun]:
    """The history's runs in the store, oldest first (days from ``spec.start``)."""
    import numpy as np
    import pandas as pd
    from sqlalchemy import select

    from app.analysis.stiffness.superstructure import section_classes
    from app.db import reference_crud
    from app.db.models import ConditionLine, ConditionRun
    from app.db.models import SegmentCondition as SC
    from app.db.session import Database

    db = Database(database_url)
    out: list[StoredRun] = []
    try:
        with db.read() as s:
            sections = reference_crud.reference_frame(s, "superstructure", line_id=spec.line_id, track=spec.track)
            line = s.scalar(select(ConditionLine).where(ConditionLine.line_id == spec.line_id))
            runs = s.execute(select(ConditionRun.run_id, ConditionRun.run_time).where(ConditionRun.line_key == line.id)
                             .order_by(ConditionRun.run_time)).all()
            for run_id, when in runs:
                rows = pd.DataFrame(s.execute(select(SC.wheel, SC.seg, SC.condition_index, SC.speed_mean, SC.condition_index_sd)
                                              .where(SC.run_id == run_id, SC.seg_m == 10)).all(),
                                    columns=["wheel", "seg", "index", "speed", "index_sd"])
                seg = np.sort(rows.seg.unique())
                wheels = sorted(rows.wheel.unique())
                la = np.full((len(wheels), seg.size), np.nan)
                v = np.full((len(wheels), seg.size), np.nan)
                sd = np.full((len(wheels), seg.size), np.nan)
                for i, w in enumerate(wheels):
                    a = rows[rows.wheel == w]
                    j = np.searchsorted(seg, a.seg.to_numpy())
                    la[i, j] = a["index"].to_numpy(dtype=float)
                    v[i, j] = a["speed"].to_numpy(dtype=float)
                    sd[i, j] = a["index_sd"].to_numpy(dtype=float, na_value=np.nan)
                day = (when.replace(tzinfo=spec.start.tzinfo) - spec.start).total_seconds() / 86400.0
                cls = section_classes((seg + 0.5) * 10.0, sections["km_from"].to_numpy() * 1000.0,
                                      sections["km_to"].to_numpy() * 1000.0, sections["type"].to_numpy(dtype=object),
                                      boundary_margin_m=margin_m)
                out.append(StoredRun(int(run_id), day, seg, wheels, la, v, cls, sd))
    finally:
        db.dispose()
    return out


def store_flags_without(db: Any, run_id: int, job_id: int, *, line_id: str, track: str,
                        stated_sd: bool = True) -> tuple[list[tuple[int, int, float]], list[tuple[int, str, float]]]:
    """A run's 10 m step flags ``(seg, direction, score)`` and per-wheel ``(seg, wheel, change_z)`` as the store
    computes them with the line's maintenance records deleted and, ``stated_sd=False``, the history's
    ``index_sd`` too (the change tests before issue 26 item 3) — in a transaction rolled back: a
    counterfactual of what the service did."""
    from sqlalchemy import select, update

    from app.condition.writer import store_run_condition
    from app.db import reference_crud
    from app.db.models import SegmentCondition as SC

    with db.read() as s:
        reference_crud.delete_reference(s, "maintenance", line_id, track)
        if not stated_sd:
            s.execute(update(SC).values(condition_index_sd=None))
        rc = store_run_condition(s, run_id, job_id)
        flags = [(int(f.seg), int(f.direction), float(f.score)) for f in rc.flags if f.kind == "step" and f.seg_m == 10]
        z = [(int(a), str(b), c) for a, b, c in s.execute(select(SC.seg, SC.wheel, SC.change_z)
                                                          .where(SC.run_id == run_id, SC.seg_m == 10)).all()]
        s.rollback()
    return flags, z


def places_without_sd(db: Any, run_id: int) -> list[tuple[float, float, int]]:
    """A run's places ``(start_m, end_m, evidence)`` as find_places gives them from the store's rows without
    the stated 1-σ and the rail-surface interventions (the places before issue 26 item 3)."""

    from app.analysis.condition.run_places import DEFAULT_PLACE_PARAMS, find_places
    from app.condition.actions import days_of
    from app.db import places as q
    from app.db.models import ConditionLine, ConditionRun, Job
    from app.places.index import method_version, run_index

    with db.read() as s:
        entry = s.get(ConditionRun, run_id)
        line = s.get(ConditionLine, entry.line_key)
        version = method_version(s.get(Job, entry.job_id).settings)
        hist = q.history_runs(s, line.id, entry.run_time, version, scan_runs=60, window_days=180)
        ri = run_index(s, line, run_id, hist)
    rp = find_places(ri.seg, ri.index, ri.history, ri.history_days, days_of(entry.run_time), ri.classes,
                     segment_m=10.0, params=DEFAULT_PLACE_PARAMS)
    return [(float(a), float(b), int(e)) for a, b, e in zip(rp.places.start_m, rp.places.end_m, rp.places.evidence,
                                                             strict=True)]
