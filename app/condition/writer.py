"""The condition writer: a published job's segment rows, change tests and flags.

Called by the publish step (:func:`app.publish.publish_job`), in the transaction
that marks the job done (both worker modes), and by the synthetic fleet
(:mod:`app.condition.fleet`). For a run with a line id it

1. takes the job's 25 cm rows (the frame the local worker just stored, or the
   rows the fan-out tasks stored), leaves out the run's ends
   (``edge_trim_m``), bins slower than ``min_speed_mps``, bins without
   amplitude and every bin a track impact the run found disturbs (a dipped weld or
   joint: within its mask, :func:`impact_masks` — the rail feature is a finding of
   its own, never graded as the support);
2. aligns the run to its line's reference signature (the first run stored for
   the line, :class:`~app.db.models.ConditionLine`;
   :func:`app.analysis.stiffness.alignment.align_runs`); where that alignment is not clear enough and
   the reference was passed at another speed (on rough rails the signature is the rails' response,
   which changes with speed: a run at 26 m/s against a 40 m/s reference reached a confidence of
   0.18–0.20 with its shift right, and was left unaligned by up to 15 m — every segment then compared
   with its neighbour's history, issue 33's false flags), to the newest earlier run of the line at
   matched speed (the matched-speed rule) whose own alignment was applied, that run's shift added;
3. computes the condition index of every bin (:func:`app.condition.index.store_index`,
   the one place that decides it) and the 10 m and 100 m segments of every wheel
   (:func:`app.analysis.condition.segment_stats`) with the stated 1-σ of their index from the
   profile's ``sleeper_amp_sd`` / ``sleeper_amp_sd_shared`` (:func:`app.condition.index.store_index_sd`);
4. tests every segment against the earlier runs of the line read from the
   store (:class:`DbHistory`, :func:`app.analysis.condition.assess_run`; with the stated 1-σ
   and the rail-surface interventions of the line's maintenance records,
   :mod:`app.analysis.condition.change`) and
   writes the rows, the flags and the run's entry, replacing the run's earlier
   ones.

The publish step then queues the alerts of the new flags (:mod:`app.condition.alerts`)
in the same transaction.

Flags are inserted under a transaction-level advisory lock on PostgreSQL, so
their ids (the feed cursor) become visible in increasing order.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pandas as pd
from sqlalchemy import and_, select, text
from sqlalchemy.orm import Session

from app.analysis.condition import (
    OVERVIEW_SEGMENT_M,
    SEGMENT_LENGTHS_M,
    ChangeParams,
    HistoryMatrix,
    RunAssessment,
    SegmentStats,
    assess_run,
    segment_stats,
)
from app.analysis.condition.interventions import intervention_margin_m
from app.analysis.impacts.mask import DEFAULT_RATIO, impact_mask, mask_half_width
from app.analysis.speed_match import speeds_matched
from app.analysis.stiffness.alignment import align_runs
from app.condition.actions import days_of, rail_surface_interventions, support_interventions
from app.condition.config import DEFAULT_CONDITION_CONFIG, ConditionConfig
from app.condition.index import STORE_INDEX, store_index, store_index_sd
from app.core.jsonable import finite_or_none
from app.db import results_reader
from app.db.bulk import insert_frame
from app.db.condition_store import delete_run_condition, line_of
from app.db.models import (
    ConditionFlag,
    ConditionLine,
    ConditionOverview,
    ConditionRun,
    Job,
    Run,
    SegmentCondition,
    utcnow,
)
from app.pipeline.impacts import IMPACT_COLUMN

__all__ = [
    "RunBins",
    "DbHistory",
    "RunCondition",
    "run_time_of",
    "days_of",
    "store_run_condition",
    "write_assessed_run",
    "wheel_segments",
    "uncertainty_settings",
    "rail_surface_interventions",
    "support_interventions",
]

#: advisory lock key of the flag feed (PostgreSQL): flag ids become visible in order
_FLAG_FEED_LOCK = 0x7476_6B66_16
#: PostgreSQL binary types of a segment row (app.db.models.SegmentCondition)
_SEGMENT_PG_TYPES: dict[str, str] = {
    "run_id": "int4", "seg_m": "int2", "wheel": "text", "seg": "int4", "line_key": "int4", "job_id": "int4",
    "n_valid": "int4", "amp_mean": "float4", "amp_p95": "float4", "speed_mean": "float4", "condition_index": "float4",
    "condition_index_sd": "float4", "n_history": "int2", "baseline": "float4", "change": "float4", "change_z": "float4",
    "trend_rate": "float4", "trend_z": "float4",
}


#: PostgreSQL binary types of an overview row (app.db.models.ConditionOverview)
_OVERVIEW_PG_TYPES: dict[str, str] = {
    "run_id": "int4", "seg": "int4", "line_key": "int4", "condition_index": "float4", "n_wheels": "int2", "flagged": "bool",
}


@dataclass(frozen=True)
class RunBins:
    """One wheel of a run on the 25 cm grid: bin numbers, amplitude (m/s²) and speed (m/s), the
    amplitude's stated 1-σ and its shared part (m/s², NaN where not stated) and the bins holding a
    track impact (the profile's ``track_impact_mm``; None: not read)."""

    bins: np.ndarray
    amplitude: np.ndarray
    speed_mps: np.ndarray
    sd: np.ndarray | None = None
    sd_shared: np.ndarray | None = None
    impact_bins: np.ndarray | None = None


def run_time_of(run: Run) -> dt.datetime:
    """When a run was measured: its start time, else when it was uploaded."""
    return run.start_time or run.created_at


_SD_COLUMNS = ("sleeper_amp_sd", "sleeper_amp_sd_shared")


def _job_bins(session: Session, job_id: int, profiles: pd.DataFrame | None) -> dict[str, RunBins]:
    if profiles is None:
        profiles = results_reader.job_profile_frame(session, job_id,
                                                    columns=["speed_mean", "sleeper_amp", *_SD_COLUMNS, IMPACT_COLUMN])
    out = {}
    for wheel, g in profiles.groupby(profiles["wheel"].astype(str), sort=True):
        g = g.sort_values("bin")
        sd = [g[c].to_numpy(dtype=np.float64, na_value=np.nan) if c in g else None for c in _SD_COLUMNS]
        out[str(wheel)] = RunBins(
            g["bin"].to_numpy(dtype=np.int64),
            g["sleeper_amp"].to_numpy(dtype=np.float64, na_value=np.nan),
            g["speed_mean"].to_numpy(dtype=np.float64, na_value=np.nan),
            *sd,
            g["bin"].to_numpy(dtype=np.int64)[g[IMPACT_COLUMN].notna().to_numpy()] if IMPACT_COLUMN in g else None,
        )
    return out


def uncertainty_settings(settings: Mapping[str, Any] | None) -> tuple[float, int]:
    """The track orders' resolution (m) and q of a job's processing settings, which set the along-track
    correlation of the stated 1-σ (:func:`app.analysis.uncertainty.segment_sd`); the recipe's defaults
    (3 m, 2) where the settings do not say (a resolution of none: the profile's own default)."""
    s = settings or {}
    res = s.get("track_resolution_m")
    q = s.get("filter_order")
    res_m = float(res) if isinstance(res, (int, float)) and np.isfinite(res) and res > 0 else 3.0
    order = int(q) if q in (1, 2, 3) else 2
    return res_m, order


def _valid(b: RunBins, bin_length_m: float, cfg: ConditionConfig, masked: np.ndarray | None = None) -> np.ndarray:
    """Amplitude with NaN outside the trimmed ends, below the minimum speed, not positive or ``masked``."""
    amp = b.amplitude.copy()
    if b.bins.size:
        k = cfg.edge_trim_m / bin_length_m
        ends = (b.bins < b.bins.min() + k) | (b.bins > b.bins.max() - k)
        amp[ends | ~(b.speed_mps >= cfg.min_speed_mps) | ~(amp > 0)] = np.nan
        if masked is not None:
            amp[masked] = np.nan
    return amp


def impact_masks(wheels: Mapping[str, RunBins], bin_length_m: float, track_impacts: Sequence[Mapping[str, Any]] | None,
                 impact_bins: Mapping[str, np.ndarray] | None, resolution_m: float, filter_order: int
                 ) -> dict[str, np.ndarray]:
    """Per wheel, the bins within a track impact's mask (on the job's own km axis, before alignment).

    The masks are the job's (``track_impacts``: position and half width as the pipeline derived them,
    :func:`app.pipeline.impacts.impact_extents`); a job without them (processed before they were kept, or
    by the fan-out tasks) has its impacts in the profile's ``track_impact_mm`` bins (``impact_bins``: the
    bins per wheel), masked with the default size/level ratio
    (:func:`app.analysis.impacts.mask.mask_half_width`).
    """
    if track_impacts is not None:
        pos = [float(i["track_m"]) for i in track_impacts]
        half = [float(i["mask_half_width_m"]) for i in track_impacts]
    else:
        found = sorted({float(b) for arr in (impact_bins or {}).values() for b in np.asarray(arr).tolist()})
        pos = [(b + 0.5) * bin_length_m for b in found]
        half = [mask_half_width(1.0, resolution_m, DEFAULT_RATIO, filter_order)] * len(pos)
    return {w: impact_mask((b.bins + 0.5) * bin_length_m, pos, half) for w, b in wheels.items()}


def _signature(wheels: Mapping[str, RunBins], amps: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Mean amplitude over the wheels per bin (bins with a value only)."""
    frames = [pd.Series(amps[w], index=wheels[w].bins) for w in wheels]
    mean = pd.concat(frames, axis=1).mean(axis=1, skipna=True).dropna().sort_index()
    return mean.index.to_numpy(dtype=np.int64), mean.to_numpy(dtype=np.float64)


def _align(line: ConditionLine, run_id: int, bins: np.ndarray, amp: np.ndarray, bin_length_m: float,
           cfg: ConditionConfig, *, session: Session | None = None, when: dt.datetime | None = None,
           speed: float | None = None) -> tuple[float, float | None]:
    """Shift (m) of the run onto the line's reference, and its confidence; sets the reference when none."""
    if bins.size == 0:
        return 0.0, None
    if line.ref_signature is None or line.ref_run_id == run_id:
        grid = np.full(int(bins.max() - bins.min()) + 1, np.nan, dtype=np.float32)
        grid[bins - bins.min()] = amp
        line.ref_run_id, line.ref_first_bin, line.ref_signature = run_id, int(bins.min()), grid.tobytes()
        line.bin_length_m = bin_length_m
        return 0.0, 1.0
    if abs(line.bin_length_m - bin_length_m) > 1e-9:
        return 0.0, None
    ref = np.frombuffer(line.ref_signature, dtype=np.float32).astype(np.float64)
    ref_bins = line.ref_first_bin + np.arange(ref.size)
    ok = np.isfinite(ref)
    if not ok.any():
        return 0.0, None
    al = align_runs(ref_bins[ok], ref[ok], bins, amp, bin_length_m=bin_length_m, max_shift_m=cfg.max_shift_m)
    if np.isfinite(al.shift_m) and al.confidence >= cfg.min_shift_confidence:
        return float(al.shift_m), float(al.confidence)
    if session is not None and when is not None and speed is not None:
        got = _align_at_matched_speed(session, line, run_id, when, speed, bins, amp, bin_length_m, cfg)
        if got is not None:
            return got
    return 0.0, float(al.confidence)


def _run_speed(wheels: Mapping[str, RunBins]) -> float | None:
    """A run's median speed over its bins, m/s (None: none)."""
    v = np.concatenate([b.speed_mps for b in wheels.values()]) if wheels else np.zeros(0)
    v = v[np.isfinite(v) & (v > 0)]
    return float(np.median(v)) if v.size else None


def _align_at_matched_speed(session: Session, line: ConditionLine, run_id: int, when: dt.datetime, speed: float,
                            bins: np.ndarray, amp: np.ndarray, bin_length_m: float, cfg: ConditionConfig,
                            candidates: int = 12) -> tuple[float, float] | None:
    """The shift onto the reference through the newest earlier run at matched speed whose alignment was
    applied (its shift added), and the confidence against that run; None where there is none or it is not
    clear enough either (module docstring, step 2)."""
    earlier = session.execute(
        select(ConditionRun.run_id, ConditionRun.job_id, ConditionRun.shift_m)
        .where(ConditionRun.line_key == line.id, ConditionRun.run_id != run_id, ConditionRun.run_time < when,
               ConditionRun.shift_confidence >= cfg.min_shift_confidence)
        .order_by(ConditionRun.run_time.desc()).limit(candidates)).all()
    if not earlier:
        return None
    sc = SegmentCondition
    by_run: dict[int, list[float]] = {}
    for rid, v in session.execute(select(sc.run_id, sc.speed_mean).where(
            sc.run_id.in_([r[0] for r in earlier]), sc.seg_m == 100, sc.speed_mean.isnot(None))):
        by_run.setdefault(int(rid), []).append(float(v))
    speeds = {rid: float(np.median(v)) for rid, v in by_run.items()}  # the median: cruise, not the ramps
    for other, job_id, shift in earlier:
        v = speeds.get(other)
        if v is None or not bool(speeds_matched(v, speed, cfg.change.speed_tolerance)):
            continue
        wheels = _job_bins(session, int(job_id), None)
        if not wheels:
            continue
        o_bins, o_amp = _signature(wheels, {w: _valid(b, bin_length_m, cfg) for w, b in wheels.items()})
        al = align_runs(o_bins, o_amp, bins, amp, bin_length_m=bin_length_m, max_shift_m=cfg.max_shift_m)
        if np.isfinite(al.shift_m) and al.confidence >= cfg.min_shift_confidence:
            return float(al.shift_m) + float(shift or 0.0), float(al.confidence)
        return None
    return None


def wheel_segments(
    wheels: Mapping[str, tuple[np.ndarray, ...]],
    *, bin_length_m: float, segment_lengths_m: tuple[float, ...] = SEGMENT_LENGTHS_M, bins_per_cell: int = 1,
    resolution_m: float = 3.0, filter_order: int = 2,
) -> dict[float, dict[str, SegmentStats]]:
    """Segments of every wheel from its bins: ``{wheel: (position_m, amplitude, speed_mps[, sd, sd_shared])}``
    (positions aligned, amplitude NaN where not valid; ``sd``/``sd_shared`` the amplitude's stated 1-σ,
    m/s², None or NaN where not stated), with the store's index and its stated 1-σ
    (:func:`app.condition.index.store_index`, :func:`app.condition.index.store_index_sd`).

    ``bins_per_cell``: each value stands for that many bins (a generated fleet
    on a coarser grid); ``n_valid`` counts bins.
    """
    out: dict[float, dict[str, SegmentStats]] = {s: {} for s in segment_lengths_m}
    for wheel, cols in wheels.items():
        pos, amp, speed = cols[:3]
        sd = cols[3] if len(cols) > 3 else None
        shared = cols[4] if len(cols) > 4 else None
        index = store_index(amp)
        for seg_m in segment_lengths_m:
            st = segment_stats(pos, amp, speed, index, segment_m=seg_m, bin_length_m=bin_length_m)
            isd = store_index_sd(pos, amp, sd, shared, st.seg, segment_m=seg_m, bin_length_m=bin_length_m,
                                 resolution_m=resolution_m, filter_order=filter_order)
            out[seg_m][wheel] = replace(st, index_sd=isd,
                                        n_valid=st.n_valid * bins_per_cell if bins_per_cell != 1 else st.n_valid)
    return out


class DbHistory:
    """The earlier runs of a line from the store, as :class:`~app.analysis.condition.HistorySource`.

    The step test sees the ``history_scan_runs`` most recent runs before the run;
    the trend test (``trend=True``) also every run within the trend window.
    """

    def __init__(self, session: Session, line_key: int, run_id: int, when: dt.datetime,
                 params: ChangeParams) -> None:
        self.session, self.params = session, params
        earlier = and_(
            ConditionRun.line_key == line_key,
            ConditionRun.run_id != run_id,
            (ConditionRun.run_time < when) | ((ConditionRun.run_time == when) & (ConditionRun.run_id < run_id)),
        )
        rows = session.execute(
            select(ConditionRun.run_id, ConditionRun.run_time).where(earlier)
            .order_by(ConditionRun.run_time.desc(), ConditionRun.run_id.desc())
            .limit(params.history_scan_runs)
        ).all()
        window = session.execute(
            select(ConditionRun.run_id, ConditionRun.run_time)
            .where(earlier, ConditionRun.run_time >= when - dt.timedelta(days=params.trend_window_days))
        ).all()
        rows = [tuple(r) for r in rows]
        window = [tuple(r) for r in window]
        ids = list({r[0] for r in (*rows, *window)})
        self.vehicles = dict(session.execute(select(Run.id, Run.vehicle_id).where(Run.id.in_(ids))).all()) \
            if ids else {}
        self.step_runs = sorted(rows, key=lambda r: (r[1], r[0]))
        self.trend_runs = sorted({*rows, *window}, key=lambda r: (r[1], r[0]))
        self.previous_run_id = self.step_runs[-1][0] if self.step_runs else None

    def previous_flags(self) -> set[tuple[int, int, str, int]]:
        """:attr:`~app.analysis.condition.Flag.key` of the previous run's flags."""
        if self.previous_run_id is None:
            return set()
        rows = self.session.execute(
            select(ConditionFlag.seg_m, ConditionFlag.seg, ConditionFlag.kind, ConditionFlag.direction)
            .where(ConditionFlag.run_id == self.previous_run_id)
        ).all()
        return {(int(a), int(b), str(c), int(d)) for a, b, c, d in rows}

    def matrix(self, seg_m: float, wheel: str, seg: np.ndarray, *, trend: bool) -> HistoryMatrix:
        """Earlier runs' index and speed on ``seg`` (NaN where a run has none)."""
        runs = self.trend_runs if trend else self.step_runs
        seg = np.asarray(seg, dtype=np.int64)
        if not runs or seg.size == 0:
            return HistoryMatrix.empty(seg.size)
        col = {rid: k for k, (rid, _) in enumerate(runs)}
        sc = SegmentCondition
        stmt = select(sc.run_id, sc.seg, sc.condition_index, sc.speed_mean, sc.condition_index_sd).where(
            sc.run_id.in_(list(col)), sc.seg_m == int(round(seg_m)), sc.wheel == wheel,
            sc.seg >= int(seg.min()), sc.seg <= int(seg.max()),
        )
        result = self.session.connection().execute(stmt)
        try:
            raw = result.cursor.fetchall()
        finally:
            result.close()
        values = np.array(raw, dtype=np.float64).reshape(len(raw), 5)  # NULL -> NaN
        index = np.full((seg.size, len(runs)), np.nan)
        speed = np.full_like(index, np.nan)
        sd = np.full_like(index, np.nan)
        if len(raw):
            cols = np.array([col[int(r)] for r in values[:, 0]], dtype=np.int64)
            j = np.searchsorted(seg, values[:, 1].astype(np.int64))
            hit = (j < seg.size) & (seg[np.minimum(j, seg.size - 1)] == values[:, 1])
            index[j[hit], cols[hit]] = values[hit, 2]
            speed[j[hit], cols[hit]] = values[hit, 3]
            sd[j[hit], cols[hit]] = values[hit, 4]
        days = np.array([days_of(t if t.tzinfo else t.replace(tzinfo=dt.UTC)) for _, t in runs])
        vehicle = np.array([self.vehicles.get(rid) for rid, _ in runs], dtype=object)
        return HistoryMatrix(index, speed, days, sd, vehicle)


def _segment_frame(run_id: int, job_id: int, line_key: int, segments: Mapping[float, Mapping[str, SegmentStats]],
                   assessment: RunAssessment) -> pd.DataFrame:
    parts = []
    for seg_m, wheels in segments.items():
        for wheel, st in wheels.items():
            n = len(st)
            if n == 0:
                continue
            c = assessment.changes.get(seg_m, {}).get(wheel)
            nan = np.full(n, np.nan)
            parts.append(pd.DataFrame({
                "run_id": np.full(n, run_id), "seg_m": np.full(n, int(round(seg_m))),
                "wheel": np.full(n, wheel, dtype=object), "seg": st.seg, "line_key": np.full(n, line_key),
                "job_id": np.full(n, job_id), "n_valid": st.n_valid, "amp_mean": st.amp_mean,
                "amp_p95": st.amp_p95, "speed_mean": st.speed_mean, "condition_index": st.index,
                "condition_index_sd": st.index_sd,
                "n_history": c.n_history if c is not None else np.zeros(n, dtype=np.int64),
                "baseline": c.baseline if c is not None else nan, "change": c.change if c is not None else nan,
                "change_z": c.change_z if c is not None else nan,
                "trend_rate": c.trend_rate if c is not None else nan, "trend_z": c.trend_z if c is not None else nan,
            }))
    frame = pd.concat(parts, ignore_index=True) if parts else pd.DataFrame(columns=list(_SEGMENT_PG_TYPES))
    for name in ("run_id", "seg_m", "seg", "line_key", "job_id", "n_valid", "n_history"):
        frame[name] = frame[name].astype(np.int64)
    return frame


def _overview_frame(run_id: int, line_key: int, segments: Mapping[float, Mapping[str, SegmentStats]],
                    flags: list[ConditionFlag]) -> pd.DataFrame:
    """The run's 100 m overview rows: mean index over the wheels, flagged cells."""
    wheels = segments.get(OVERVIEW_SEGMENT_M, {})
    parts = [pd.DataFrame({"seg": st.seg, "index": st.index}) for st in wheels.values() if len(st)]
    if not parts:
        return pd.DataFrame(columns=list(_OVERVIEW_PG_TYPES))
    g = pd.concat(parts).groupby("seg")["index"].agg(["mean", "count"])
    cells = {int(f.seg * f.seg_m // OVERVIEW_SEGMENT_M) for f in flags}
    seg = g.index.to_numpy(dtype=np.int64)
    return pd.DataFrame({
        "run_id": np.full(seg.size, run_id), "seg": seg, "line_key": np.full(seg.size, line_key),
        "condition_index": g["mean"].to_numpy(), "n_wheels": g["count"].to_numpy(dtype=np.int64),
        "flagged": np.isin(seg, list(cells)),
    })


def _insert_flags(session: Session, run_id: int, job_id: int, line_key: int,
                  assessment: RunAssessment) -> list[ConditionFlag]:
    """Insert the run's flags (under the feed lock on PostgreSQL)."""
    if not assessment.flags:
        return []
    if session.get_bind().dialect.name == "postgresql":
        session.execute(text("SELECT pg_advisory_xact_lock(:k)"), {"k": _FLAG_FEED_LOCK})
    now = utcnow()
    rows = [
        ConditionFlag(
            run_id=run_id, line_key=line_key, job_id=job_id, wheels=",".join(f.wheels), n_wheels=len(f.wheels),
            seg_m=int(round(f.seg_m)), seg=f.seg, kind=f.kind, direction=f.direction, score=f.score,
            change=finite_or_none(f.change), rate_per_year=finite_or_none(f.rate_per_year),
            is_new=f.is_new, created_at=now,
        )
        for f in assessment.flags
    ]
    # one batched INSERT … RETURNING: the ids follow the list's order, as one flush per row gave them
    session.add_all(rows)
    session.flush()
    return rows


def write_assessed_run(
    session: Session, *, run_id: int, job_id: int, line: ConditionLine, when: dt.datetime,
    segments: Mapping[float, Mapping[str, SegmentStats]], assessment: RunAssessment,
    shift_m: float = 0.0, shift_confidence: float | None = None,
) -> list[ConditionFlag]:
    """Write a run's assessed segments, its flags and its entry (replacing earlier ones); the flag rows."""
    delete_run_condition(session, run_id)
    frame = _segment_frame(run_id, job_id, line.id, segments, assessment)
    insert_frame(session, SegmentCondition.__table__, frame, _SEGMENT_PG_TYPES)
    flags = _insert_flags(session, run_id, job_id, line.id, assessment)
    insert_frame(session, ConditionOverview.__table__, _overview_frame(run_id, line.id, segments, flags),
                 _OVERVIEW_PG_TYPES)
    session.add(ConditionRun(run_id=run_id, line_key=line.id, job_id=job_id, run_time=when, shift_m=shift_m,
                             shift_confidence=shift_confidence, n_segments=len(frame), n_flags=len(flags),
                             published_at=utcnow()))
    if len(frame):
        ten = frame[frame["seg_m"] == frame["seg_m"].min()]
        lo = float(ten["seg"].min() * ten["seg_m"].iloc[0] / 1000.0)
        hi = float((ten["seg"].max() + 1) * ten["seg_m"].iloc[0] / 1000.0)
        line.km_min = lo if line.km_min is None else min(line.km_min, lo)
        line.km_max = hi if line.km_max is None else max(line.km_max, hi)
    session.flush()
    return flags


@dataclass(frozen=True)
class RunCondition:
    """What :func:`store_run_condition` wrote for a run (``stored`` False: nothing, and why).

    Attributes
    ----------
    stored : bool
    reason : str or None
        Why nothing was stored (the run has no line id, the job no profile rows).
    line : ConditionLine or None
    flags : list of ConditionFlag
        The run's flags (``is_new``: the alerts to send).
    details : dict
        Provenance of the rows (:meth:`summary`).
    """

    stored: bool
    reason: str | None = None
    line: ConditionLine | None = None
    flags: tuple[ConditionFlag, ...] = ()
    details: dict[str, Any] | None = None

    def summary(self, webhook_deliveries: int = 0) -> dict[str, Any]:
        """Provenance for the job's metadata (``meta["condition"]``): ``index``, ``shift_m``,
        ``shift_confidence``, ``segments``, ``flags``, ``new_flag_ids``, ``webhook_deliveries``,
        ``speed_exponent`` (per segment length, mean over wheels); or ``{"stored": False,
        "reason": ...}``."""
        if not self.stored:
            return {"stored": False, "reason": self.reason}
        d = dict(self.details or {})
        exponents = d.pop("speed_exponent")
        return {"stored": True, **d, "webhook_deliveries": webhook_deliveries, "speed_exponent": exponents}


def store_run_condition(
    session: Session,
    run_id: int,
    job_id: int,
    *,
    config: ConditionConfig = DEFAULT_CONDITION_CONFIG,
    profiles: pd.DataFrame | None = None,
    track_impacts: Sequence[Mapping[str, Any]] | None = None,
) -> RunCondition:
    """Segment rows, change tests and flags of a published job (see the module docstring).

    Run it in the publish transaction, after the job's profile rows are stored.

    Parameters
    ----------
    profiles : pandas.DataFrame, optional
        The job's profile rows when at hand (local worker); read from the
        database otherwise.
    track_impacts : sequence of dict, optional
        The job's track impacts with their masks (its ``meta["track_impacts"]`` when at hand: the publish
        step writes the meta in this transaction); default the job's stored meta's, else the profile's
        impact bins (:func:`impact_masks`).

    Returns
    -------
    RunCondition
        The flags written and the provenance of the rows; not stored for a run
        without a line id or a job without profile rows.
    """
    run = session.get(Run, run_id)
    delete_run_condition(session, run_id)
    if run is None or not run.line_id:
        return RunCondition(False, "the run has no line_id")
    bin_length = results_reader.job_bin_length(session, job_id)
    line = line_of(session, run.line_id, run.track or "", bin_length)
    wheels = _job_bins(session, job_id, profiles)
    if not wheels:
        return RunCondition(False, "the job has no profile rows")
    job = session.get(Job, job_id)
    res_m, order = uncertainty_settings(job.settings if job is not None else None)
    if track_impacts is None and job is not None and isinstance(job.meta, dict):
        track_impacts = job.meta.get("track_impacts")
    masks = impact_masks(wheels, bin_length, track_impacts, {w: b.impact_bins for w, b in wheels.items()
                                                             if b.impact_bins is not None}, res_m, order)
    amps = {w: _valid(b, bin_length, config, masks.get(w)) for w, b in wheels.items()}
    sig_bins, sig_amp = _signature(wheels, amps)
    shift, confidence = _align(line, run_id, sig_bins, sig_amp, bin_length, config, session=session,
                               when=run_time_of(run), speed=_run_speed(wheels))
    positions = {w: ((b.bins + 0.5) * bin_length + shift, amps[w], b.speed_mps, b.sd, b.sd_shared)
                 for w, b in wheels.items()}
    segments = wheel_segments(positions, bin_length_m=bin_length, resolution_m=res_m, filter_order=order)
    when = run_time_of(run)
    history = DbHistory(session, line.id, run_id, when, config.change)
    assessment = assess_run(segments, history, days_of(when), params=config.change,
                            previous_flags=history.previous_flags(),
                            interventions=rail_surface_interventions(session, run.line_id, run.track or ""),
                            support=support_interventions(session, run.line_id, run.track or ""),
                            intervention_margin_m=intervention_margin_m(res_m, order), vehicle=run.vehicle_id)
    flags = write_assessed_run(session, run_id=run_id, job_id=job_id, line=line, when=when, segments=segments,
                               assessment=assessment, shift_m=shift, shift_confidence=confidence)
    exponents = {f"{s:g}": float(np.mean(list(e.values()))) if e else None
                 for s, e in assessment.exponents.items()}
    details = {
        "condition_index": STORE_INDEX, "line_key": line.id,
        "shift_m": round(shift, 3), "shift_confidence": confidence,
        "segments": int(sum(len(st) for w in segments.values() for st in w.values())),
        "history_runs": len(history.step_runs), "flags": len(flags), "new_flag_ids": [f.id for f in flags if f.is_new],
        "impact_masked_bins": int(sum(int(m.sum()) for m in masks.values())),
        "speed_exponent": exponents,
    }
    return RunCondition(True, None, line, tuple(flags), details)
