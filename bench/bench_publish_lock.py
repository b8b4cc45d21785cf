"""How long the publish step holds SQLite's write lock for a 50 km line's run: the places update inside the
publish transaction (before issue 24: the publish step of ``--before-rev``, loaded from git) against the
publish transaction plus the places follow-up (:mod:`app.places.followup`: read without the lock, then a
short write), in one run on copies of one database.

A generated 50 km fleet line (:func:`app.condition.fleet.ingest_fleet`, daily runs, ``--history`` runs
applied to its places: the history the places update reads), then the next run published through the publish
step (fan-out style: its 1 m profile rows stored first by :func:`app.publish.store_wheel_rows`, one
transaction per wheel, as the Procrastinate tasks do; the publish transaction then writes the condition rows,
flags, the job done — and, before, the places). Every write transaction's lock hold (``BEGIN IMMEDIATE`` to
``COMMIT``) is recorded, and a probe thread makes a small write (``UPDATE webhooks``, one row: an audited
write's size) every 50 ms in its own connection: its longest wait is what a ``PATCH /webhooks/{id}`` waits.

Usage::

    nice .venv/bin/python bench/bench_publish_lock.py [--history 60] [--before-rev c7b33eb]
"""

from __future__ import annotations

import argparse
import datetime as dt
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import types
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from sqlalchemy import event, insert, select, update  # noqa: E402

from app.db import migrate  # noqa: E402
from app.db.session import Database  # noqa: E402

KM = 50.0
LINE = "U50"
START = dt.datetime(2025, 1, 1, 6, 0, tzinfo=dt.UTC)


def _prepare(url: str, n_history: int):
    """The line's history in the store (applied to its places), the next run's Run row and its tracks."""
    import numpy as np

    from app.analysis.settings import ProcessingSettings
    from app.condition.fleet import ingest_fleet
    from app.db.models import ConditionRun, Job, PlaceRun
    from app.db.webhooks import create_webhook
    from app.places.index import method_version
    from app.simulate.fleet import FleetSimulator
    from app.simulate.track import generate_line

    migrate.upgrade(url)
    db = Database(url)
    sim = FleetSimulator(generate_line(0.0, KM * 1000.0, seed=5))
    ingest_fleet(db, sim, n_history, line_id=LINE, start=START, seed=6, reference=False)
    with db.write() as s:
        runs = s.execute(select(ConditionRun).order_by(ConditionRun.run_time)).scalars().all()
        version = method_version(s.get(Job, runs[0].job_id).settings)
        assert version == method_version(ProcessingSettings().to_dict())
        s.execute(insert(PlaceRun), [{"run_id": r.run_id, "line_key": r.line_key, "run_time": r.run_time,
                                      "method_version": version, "start_m": 0.0, "end_m": KM * 1000,
                                      "n_places": 0, "n_events": 0, "applied_at": r.run_time} for r in runs])
        create_webhook(s, "https://93.184.215.14/probe")  # the probe's row (its alerts go to the outbox)
    db.dispose()
    _, tracks = sim.run(float(n_history), np.random.default_rng([6, n_history]))
    return tracks


class LockLog:
    """Every write transaction's hold of the lock on an engine, with the statements it ran."""

    def __init__(self, db: Database) -> None:
        self.done: list[tuple[float, list[str]]] = []
        self._open: dict[int, tuple[float, list[str]]] = {}
        event.listen(db.engine, "begin", self._begin)  # after the engine's own BEGIN IMMEDIATE: lock taken
        event.listen(db.engine, "before_cursor_execute", self._sql)
        event.listen(db.engine, "commit", self._end)
        event.listen(db.engine, "rollback", self._end)

    def _begin(self, conn) -> None:
        if conn.get_execution_options().get("sqlite_immediate"):
            self._open[id(conn)] = (time.perf_counter(), [])

    def _sql(self, conn, cursor, sql, params, context, executemany) -> None:  # noqa: ARG002
        if id(conn) in self._open:
            self._open[id(conn)][1].append(sql)

    def _end(self, conn) -> None:
        if id(conn) in self._open:
            t0, sqls = self._open.pop(id(conn))
            self.done.append((time.perf_counter() - t0, sqls))

    def hold(self, marker: str) -> list[float]:
        """Holds of the transactions that ran a statement containing ``marker``, s."""
        return [h for h, sqls in self.done if any(marker in q for q in sqls)]


class Probe(threading.Thread):
    """A small write every ``every_s`` in its own connection; the time each took, s."""

    def __init__(self, url: str, every_s: float = 0.05) -> None:
        super().__init__(daemon=True)
        self.db, self.every_s, self.waits = Database(url), every_s, []
        self._halt = threading.Event()

    def run(self) -> None:
        from app.db.models import Webhook

        i = 0
        while not self._halt.is_set():
            t0 = time.perf_counter()
            with self.db.write() as s:
                s.execute(update(Webhook).values(description=f"probe {i}"))
            self.waits.append(time.perf_counter() - t0)
            i += 1
            self._halt.wait(self.every_s)

    def stop(self) -> list[float]:
        self._halt.set()
        self.join()
        self.db.dispose()
        return self.waits


def _main_publish(rev: str) -> types.ModuleType:
    """The publish step of git revision ``rev`` (before issue 24: the places in the publish transaction)."""
    src = subprocess.run(["git", "show", f"{rev}:app/publish.py"], cwd=ROOT, capture_output=True, text=True,
                         check=True).stdout
    mod = types.ModuleType("publish_before")
    exec(compile(src, f"{rev}:app/publish.py", "exec"), mod.__dict__)  # noqa: S102 - the project's own code
    return mod


def _publish(url: str, tracks, publish_mod, label: str) -> dict:
    from app import publish
    from app.analysis.settings import ProcessingSettings
    from app.db.models import Job, JobStatus, PlaceRun, Run, utcnow
    from app.places import followup
    from tests.condition.support import profile_frame_of

    db = Database(url)
    with db.write() as s:
        run = Run(sha256=f"bench-{label}", file_path="x", source_format="hdf5", size_bytes=1, fs=10_000.0,
                  n_samples=10, duration_s=1.0, channels=[f"Z{w}" for w in tracks], meta={}, line_id=LINE,
                  track="1", start_time=START + dt.timedelta(days=400), created_at=utcnow())
        s.add(run)
        s.flush()
        job = Job(run_id=run.id, status=JobStatus.RUNNING, worker_id="bench", settings=ProcessingSettings().to_dict(),
                  created_at=utcnow())
        s.add(job)
        s.flush()
        run_id, job_id = run.id, job.id
    profiles = profile_frame_of(tracks, bin_length_m=1.0)
    for _wheel, rows in profiles.groupby("wheel"):
        assert publish.store_wheel_rows(db, job_id, run_id, rows.reset_index(drop=True))
    log = LockLog(db)
    probe = Probe(url)
    probe.start()
    time.sleep(0.3)
    t0 = time.perf_counter()
    assert publish_mod.publish_job(db, job_id, run_id, None, [], {}, worker_id=None)
    wall = time.perf_counter() - t0
    time.sleep(0.3)
    waits = probe.stop()
    with db.read() as s:
        summary = s.get(Job, job_id).meta["condition"]
        applied = s.get(PlaceRun, run_id) is not None
    db.dispose()
    publish_holds = log.hold("INSERT INTO condition_runs")
    places_holds = log.hold("INSERT INTO place_runs")
    out = {"publish_step_s": wall, "publish_tx_hold_s": max(publish_holds),
           "places_write_hold_s": max(places_holds) if places_holds else None,
           "write_txs": len(log.done), "longest_hold_s": max(h for h, _ in log.done),
           "probe_writes": len(waits), "probe_max_wait_s": max(waits), "probe_median_s": statistics.median(waits),
           "places_applied": applied, "places_found": summary["places"].get("found")}
    if publish_mod is publish:
        out["places_in_publish_tx"] = bool(set(publish_holds) & set(places_holds))
        assert followup.run_pending(Database(url)) == []
    return out


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--history", type=int, default=60, help="runs of the line applied before (the places' history)")
    ap.add_argument("--before-rev", default="c7b33eb", help="git revision of the publish step before issue 24")
    args = ap.parse_args(argv)
    from app import publish

    before_mod = _main_publish(args.before_rev)
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp) / "base.sqlite"
        t = time.perf_counter()
        tracks = _prepare(f"sqlite:///{base}", args.history)
        print(f"== 50 km line, {args.history} history runs applied, generated in {time.perf_counter() - t:.0f} s")
        results = {}
        for label, mod in (("before", before_mod), ("after", publish)):
            path = Path(tmp) / f"{label}.sqlite"
            shutil.copyfile(base, path)
            results[label] = _publish(f"sqlite:///{path}", tracks, mod, label)
    for label, r in results.items():
        print(f"-- {label}: " + ", ".join(f"{k} {v:.3f}" if isinstance(v, float) else f"{k} {v}"
                                         for k, v in r.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
