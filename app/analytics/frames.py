"""The frames the analyses read: the selected runs, their profile rows, the line's reference data.

:func:`select_runs` picks the runs of a line and track with results (or the runs
asked for); :func:`analytics_frame` reads their result jobs' 25 cm rows without the
run ends (``edge_trim_m``: filter end transients), bins slower than a minimum speed
and bins without amplitude; :func:`load_profiles` does so through a per-process
cache (a job's rows never change once published). The analytics endpoints and the
reference curves of the stiffness index (:mod:`app.analytics.reference_curves`) read
the same rows through here.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
from sqlalchemy import func, select
from sqlalchemy.orm import Session

from app.analysis.stiffness.speed_norm import SpeedFit, fit_speed_exponent, normalise_amplitude
from app.analysis.stiffness.superstructure import assign_sections
from app.analysis.units import KMH_PER_MPS
from app.core.errors import ApiError
from app.core.i18n import _
from app.core.ids import MAX_ID
from app.db import crud, reference_crud, results_reader
from app.db.models import ProfileBin, Run
from app.db.session import Database
from app.settings import Settings

__all__ = ["Selection", "RunsQuery", "hac_lag", "ANALYTICS_COLUMNS", "parse_run_ids", "select_runs", "analytics_frame", "load_profiles",
           "own_amplitude", "reference", "speed_exponents", "normalised", "section_types", "PROFILE_CACHE_ROWS"]

#: Columns of :func:`analytics_frame` (and of :func:`load_profiles`).
ANALYTICS_COLUMNS: tuple[str, ...] = ("run_id", "wheel", "bin", "km", "speed_mean", "sleeper_amp", "sleeper_force_amp",
                                       "sleeper_amp_raw")
_COLS = list(ANALYTICS_COLUMNS)
#: rows of analytics profile frames kept in memory per API process (about 60 MB)
PROFILE_CACHE_ROWS = 1_000_000


@dataclass
class Selection:
    """Runs of one line and track with stored results, ordered by start time."""

    line_id: str | None
    track: str | None
    runs: list[Run]
    bin_length: float

    @property
    def run_ids(self) -> list[int]:
        return [r.id for r in self.runs]


@dataclass(frozen=True)
class RunsQuery:
    """The common query of the analytics over runs: line, track, explicit run ids, km range, wheel."""

    line_id: str | None
    track: str | None
    run_ids: list[int] | None
    km_from: float | None
    km_to: float | None
    wheel: str | None

    def select(self, db: Database) -> Selection:
        """The selected runs (:func:`select_runs`)."""
        return select_runs(db, self.line_id, self.track, self.run_ids)


def hac_lag(sel: Selection) -> int:
    """Newey–West lag of the fits over the selection's bins: 100 m of bins."""
    return int(round(100.0 / sel.bin_length))


def parse_run_ids(value: str | None) -> list[int] | None:
    """``"3,5,8"`` → [3, 5, 8] (422 naming ``run_ids`` otherwise)."""
    if value is None or not value.strip():
        return None
    try:
        ids = [int(p) for p in value.split(",") if p.strip()]
    except ValueError:
        raise ApiError(422, "run_ids", _("must be comma-separated integers, got {value}", value=repr(value))) from None
    if not ids or any(i < 1 or i > MAX_ID for i in ids):
        raise ApiError(422, "run_ids", _("must be positive integers"))
    return ids


def select_runs(db: Database, line_id: str | None, track: str | None, run_ids: list[int] | None) -> Selection:
    """Explicit runs (all must exist and have results, on one line/track) or all runs of line/track with results."""
    with db.read() as session:
        if run_ids:
            runs = []
            for rid in run_ids:
                run = crud.get_run(session, rid)
                if run is None:
                    raise ApiError(404, "run_ids", _("run {run_id} not found", run_id=rid))
                if results_reader.results_job(session, rid) is None:
                    raise ApiError(409, "run_ids", _("run {run_id} has no results yet", run_id=rid))
                runs.append(run)
            lines = {(r.line_id, r.track) for r in runs}
            if len(lines) > 1:
                raise ApiError(422, "run_ids", _("runs are on different lines/tracks: {lines}", lines=sorted(map(str, lines))))
            lid, trk = next(iter(lines))
            if line_id is not None and line_id != lid:
                raise ApiError(422, "line_id", _("runs {run_ids} are on line {their_line}, not {line_id}", run_ids=run_ids, their_line=repr(lid), line_id=repr(line_id)))
            if track is not None and track != trk:
                raise ApiError(422, "track", _("runs {run_ids} are on track {their_track}, not {track}", run_ids=run_ids, their_track=repr(trk), track=repr(track)))
            line_id, track = lid, trk
        else:
            if line_id is None:
                raise ApiError(422, "line_id", _("is required unless run_ids are given"))
            runs = results_reader.runs_with_results(session, line_id, track)
            tracks = {r.track for r in runs}
            if track is None and len(tracks) > 1:
                raise ApiError(422, "track", _("line {line_id} has runs on tracks {tracks}: choose one", line_id=repr(line_id), tracks=sorted(map(str, tracks))))
            if track is None and tracks:
                track = next(iter(tracks))
        bin_length = 0.25
        for r in runs:
            job = results_reader.results_job(session, r.id)
            if job is not None:
                bin_length = results_reader.bin_length_of(job)
    runs.sort(key=lambda r: (r.start_time is None, r.start_time, r.id))
    return Selection(line_id, track, runs, bin_length)


def _wheel_extents(session: Session, job_id: int) -> dict[str, tuple[int, int]]:
    """First and last bin of each wheel of a job (index lookups, not a scan of its rows)."""
    out = {}
    for w in results_reader.stored_profile_wheels(session, job_id):
        where = (ProfileBin.job_id == job_id) & (ProfileBin.wheel == w)
        lo = session.scalar(select(func.min(ProfileBin.bin)).where(where))
        hi = session.scalar(select(func.max(ProfileBin.bin)).where(where))
        out[w] = (int(lo), int(hi))
    return out


def analytics_frame(
    session: Session,
    jobs: Sequence[tuple[int, int]],
    *,
    bin_length_m: float,
    min_speed_kmh: float,
    edge_trim_m: float,
    km_from: float | None = None,
    km_to: float | None = None,
    wheel: str | None = None,
    columns: Sequence[str] = ("speed_mean", "sleeper_amp", "sleeper_force_amp", "sleeper_amp_raw"),
) -> pd.DataFrame:
    """Profile rows of the result jobs ``jobs`` (``(run_id, job_id)`` pairs, :func:`result_jobs`),
    columns ``run_id, wheel, bin, km`` and ``columns``.

    Left out: the first and last ``edge_trim_m`` of each wheel's profile,
    bins slower than ``min_speed_kmh`` and bins without a positive
    ``sleeper_amp``.
    """
    min_v = min_speed_kmh / KMH_PER_MPS
    values = list(dict.fromkeys(["speed_mean", "sleeper_amp", *columns]))
    out_cols = ["run_id", "wheel", "bin", "km", *values]
    k = edge_trim_m / bin_length_m
    frames = []
    for run_id, job_id in jobs:
        ext = _wheel_extents(session, job_id)
        df = results_reader.job_profile_frame(session, job_id, wheel=wheel, km_from=km_from, km_to=km_to,
                                              columns=values)
        if df.empty:
            continue
        wheels = df["wheel"].to_numpy(dtype=object)
        bins = df["bin"].to_numpy()
        lo = np.zeros(len(df), dtype=np.int64)
        hi = np.zeros(len(df), dtype=np.int64)
        for w, (b0, b1) in ext.items():
            m = wheels == w
            lo[m], hi[m] = b0, b1
        keep = (bins >= lo + k) & (bins <= hi - k)
        keep &= (df["speed_mean"].to_numpy() >= min_v) & (df["sleeper_amp"].to_numpy() > 0)
        df = df[keep]
        df.insert(0, "run_id", run_id)
        frames.append(df[out_cols])
    if not frames:
        return pd.DataFrame({c: pd.Series(dtype=object if c == "wheel" else float) for c in out_cols})
    return pd.concat(frames, ignore_index=True)


class _FrameCache:
    """Least recently used profile frames of :func:`load_profiles`, at most ``max_rows`` rows.

    Keys name the jobs whose rows a frame holds: a job's profile rows never change once it is
    done (a reprocessing job has a new id), so an entry is never stale. Requests for the same
    key wait for the one that reads it (the correlations page asks three analyses at once).
    """

    def __init__(self, max_rows: int) -> None:
        self.max_rows = max_rows
        self._frames: OrderedDict[tuple, pd.DataFrame] = OrderedDict()
        self._rows = 0
        self._lock = threading.Lock()
        self._loading: dict[tuple, threading.Lock] = {}

    def get(self, key: tuple, load) -> pd.DataFrame:
        with self._lock:
            if key in self._frames:
                self._frames.move_to_end(key)
                return self._frames[key]
            gate = self._loading.setdefault(key, threading.Lock())
        with gate:
            with self._lock:
                if key in self._frames:
                    return self._frames[key]
            frame = load()
            with self._lock:
                self._loading.pop(key, None)
                if len(frame) <= self.max_rows:
                    self._frames[key] = frame
                    self._rows += len(frame)
                    while self._rows > self.max_rows:
                        _key, old = self._frames.popitem(last=False)
                        self._rows -= len(old)
            return frame


_CACHE = _FrameCache(PROFILE_CACHE_ROWS)


def own_amplitude(df: pd.DataFrame) -> pd.DataFrame:
    """``df`` with ``sleeper_amp`` the wheel's own amplitude (``sleeper_amp_raw``; jobs before issue 26: as is).

    For relations of one rail's records (its subsidence, its wheel's force): where both wheels of an axle
    are measured ``sleeper_amp`` is the response common to both rails (docs/indicator.md).
    """
    if "sleeper_amp_raw" not in df.columns or df.empty:
        return df
    raw = df["sleeper_amp_raw"].to_numpy(dtype=np.float64, na_value=np.nan)
    return df.assign(sleeper_amp=np.where(np.isfinite(raw), raw, df["sleeper_amp"].to_numpy(dtype=np.float64)))


def load_profiles(
    db: Database, settings: Settings, sel: Selection, *, km_from: float | None = None,
    km_to: float | None = None, wheel: str | None = None, min_speed_kmh: float | None = None,
) -> pd.DataFrame:
    """Profile rows of the selected runs (columns ``_COLS``), without the run ends
    (``analytics_edge_trim_m``), bins slower than the minimum speed and bins without amplitude
    (:func:`analytics_frame`).

    Frames are kept per API process (:data:`PROFILE_CACHE_ROWS`), keyed by the runs' result
    jobs and the arguments; treat the returned frame as read-only.
    """
    min_v = settings.analytics_min_speed_kmh if min_speed_kmh is None else min_speed_kmh
    trim = settings.analytics_edge_trim_m
    with db.read() as session:
        jobs = results_reader.result_jobs(session, sel.runs)

    def load() -> pd.DataFrame:
        with db.read() as session:
            return analytics_frame(
                session, jobs, bin_length_m=sel.bin_length, min_speed_kmh=min_v, edge_trim_m=trim,
                km_from=km_from, km_to=km_to, wheel=wheel,
            )[_COLS]

    key = (db.url, tuple(jobs), wheel, km_from, km_to, min_v, trim, sel.bin_length)
    return _CACHE.get(key, load).copy(deep=False)


def reference(db: Database, kind: str, sel: Selection, **kw) -> pd.DataFrame:
    """Reference rows of the selection's line and track."""
    with db.read() as session:
        return reference_crud.reference_frame(session, kind, line_id=sel.line_id, track=sel.track, **kw)


def section_types(sections: pd.DataFrame, position_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Section index (-1 none) and type label ('' none) per position (m)."""
    if sections.empty:
        return np.full(len(position_m), -1), np.full(len(position_m), "", dtype=object)
    idx = assign_sections(position_m, sections["km_from"].to_numpy() * 1000, sections["km_to"].to_numpy() * 1000)
    types = np.where(idx >= 0, sections["type"].to_numpy(dtype=object)[np.maximum(idx, 0)], "")
    return idx, types.astype(object)


def speed_exponents(df: pd.DataFrame, sections: pd.DataFrame, bin_length: float,
                    ref_speed_kmh: float, min_speed_kmh: float) -> dict[str, SpeedFit]:
    """Speed exponent per superstructure type ('' = bins outside sections) and over all bins ('*')."""
    out: dict[str, SpeedFit] = {}
    if df.empty:
        return out
    pos = (df["bin"].to_numpy() + 0.5) * bin_length
    _codes, types = section_types(sections, pos)
    amp, v = df["sleeper_amp"].to_numpy(), df["speed_mean"].to_numpy()
    loc = df["wheel"].astype(str).to_numpy() + ":" + df["bin"].astype(str).to_numpy()
    kw = {"reference_speed_mps": ref_speed_kmh / KMH_PER_MPS, "min_speed_mps": min_speed_kmh / KMH_PER_MPS,
          "hac_lag": int(round(100.0 / bin_length))}
    out["*"] = fit_speed_exponent(amp, v, loc, **kw)
    for t in sorted(set(types)):
        m = types == t
        out[t] = fit_speed_exponent(amp[m], v[m], loc[m], **kw)
    return out


def normalised(df: pd.DataFrame, sections: pd.DataFrame, fits: dict[str, SpeedFit], bin_length: float,
               ref_speed_kmh: float, min_speed_kmh: float) -> tuple[np.ndarray, np.ndarray]:
    """Speed-normalised sleeper amplitude per row (type's exponent, else the pooled one) and the type per row."""
    pos = (df["bin"].to_numpy() + 0.5) * bin_length
    _codes, types = section_types(sections, pos)
    pooled = fits["*"].exponent if "*" in fits else float("nan")
    alpha = np.array([fits[t].exponent if t in fits and np.isfinite(fits[t].exponent) else pooled
                      for t in types], dtype=np.float64)
    amp = normalise_amplitude(df["sleeper_amp"].to_numpy(), df["speed_mean"].to_numpy(), alpha,
                              reference_speed_mps=ref_speed_kmh / KMH_PER_MPS, min_speed_mps=min_speed_kmh / KMH_PER_MPS)
    return amp, types
