"""The index the places are graded on: ``ln(A / A_ref(class, v))`` of a run and of its history.

From the condition store's 10 m rows (the store keeps the condition index ``ln A`` at matched speed,
:mod:`app.condition.index`), with the line's reference curves fitted on those rows
(:func:`~app.analysis.condition.segment_curves.fit_segment_curves`) and each segment's superstructure
class: :func:`run_index` (a run and its history, wheels × segments: what the places are found on),
:func:`run_segment_index` (per segment, mean over the wheels: what the section classes are read from).

Places compare only within one **method version** (:func:`method_version`: the engine and the job's
processing settings): the history a run's tests see, and the curves of its index, are the store's
rows of earlier runs processed the same way (docs/places.md, "Method version").
"""

from __future__ import annotations

import datetime as dt
import hashlib
import json
from dataclasses import dataclass
from typing import Any

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from app.analysis.condition.change import ChangeParams
from app.analysis.condition.lifecycle import PassHistory
from app.analysis.condition.run_places import class_scatter, mean_over_wheels, segment_index
from app.analysis.condition.segment_curves import fit_segment_curves
from app.analysis.stiffness.superstructure import section_classes
from app.condition.actions import days_of
from app.core.profile_schema import ENGINE_VERSION
from app.db import places as q
from app.db import reference_crud
from app.db.models import ConditionLine, ConditionRun
from app.places.config import DEFAULT_PLACES_CONFIG, PlacesConfig

__all__ = ["SEGMENT_M", "RunIndex", "history_runs_of", "method_version", "run_index", "run_segment_index",
           "run_segment_rails", "segment_classes", "version_history"]

#: The store's segment length the places are found on, m.
SEGMENT_M = 10


def method_version(job_settings: dict[str, Any] | None) -> str:
    """The version of the method a run's condition rows come from: the engine and a digest of the job's
    processing settings (the recipe), e.g. ``trackvkf-pipeline/3+1a2b3c4d5e6f``."""
    blob = json.dumps(job_settings or {}, sort_keys=True, separators=(",", ":"), default=str)
    return f"{ENGINE_VERSION}+{hashlib.sha256(blob.encode()).hexdigest()[:12]}"


def segment_classes(session: Session, line: ConditionLine, seg: np.ndarray, margin_m: float) -> np.ndarray:
    """The superstructure class of each :data:`SEGMENT_M` segment ``seg`` of the line (None within ``margin_m``
    of a change of class or outside the sections), from its imported sections."""
    sections = reference_crud.reference_frame(session, "superstructure", line_id=line.line_id, track=line.track)
    return section_classes((seg + 0.5) * SEGMENT_M, sections["km_from"].to_numpy(dtype=float) * 1000.0,
                           sections["km_to"].to_numpy(dtype=float) * 1000.0,
                           sections["type"].to_numpy(dtype=object), boundary_margin_m=margin_m)


def _grids(values: np.ndarray, wheels: list[str], run_ids: list[int]):
    """Per run: (segments, wheel names, ln A, speed, stated 1-σ of ln A) as wheels × segments arrays."""
    order = np.argsort(values[:, 0], kind="stable")
    v_sorted = values[order]
    bounds = np.searchsorted(v_sorted[:, 0], np.asarray(run_ids, dtype=np.float64), side="left")
    ends = np.searchsorted(v_sorted[:, 0], np.asarray(run_ids, dtype=np.float64), side="right")
    out = {}
    for rid, a, b in zip(run_ids, bounds, ends, strict=True):
        part = v_sorted[a:b]
        seg = np.unique(part[:, 2].astype(np.int64))
        codes = np.unique(part[:, 1].astype(np.int64))
        la = np.full((codes.size, seg.size), np.nan)
        v = np.full_like(la, np.nan)
        sd = np.full_like(la, np.nan)
        i = np.searchsorted(codes, part[:, 1].astype(np.int64))
        j = np.searchsorted(seg, part[:, 2].astype(np.int64))
        la[i, j], v[i, j], sd[i, j] = part[:, 3], part[:, 4], part[:, 5]
        out[rid] = (seg, [wheels[c] for c in codes], la, v, sd)
    return out


def _on(src, seg: np.ndarray, wheels: list[str], values: np.ndarray) -> np.ndarray:
    """An earlier run's per-wheel values on this run's segments and wheels (NaN where it has none)."""
    s_seg, s_wheels = src[0], src[1]
    out = np.full((len(wheels), seg.size), np.nan)
    if s_seg.size == 0:
        return out
    j = np.minimum(np.searchsorted(s_seg, seg), s_seg.size - 1)
    hit = s_seg[j] == seg
    for i, w in enumerate(wheels):
        if w in s_wheels:
            out[i, hit] = values[s_wheels.index(w), j[hit]]
    return out


@dataclass(frozen=True)
class RunIndex:
    """The speed-conditioned index of a run and of its history on the run's segments and wheels.

    Attributes
    ----------
    seg : numpy.ndarray
        int64 segment numbers (``SEGMENT_M`` m each) of the run.
    wheels : list of str
        Wheel of each row.
    index : numpy.ndarray
        (wheels, segments) ``ln(A / A_ref(class, v))`` (NaN: none).
    speed : numpy.ndarray
        (wheels, segments) speed, m/s.
    history : numpy.ndarray
        (wheels, segments, runs) the index of the history runs, oldest first.
    history_days : numpy.ndarray
        Days (since 1970) of the history runs.
    classes : numpy.ndarray
        Superstructure class of each segment (None near a change of class).
    index_sd, history_sd : numpy.ndarray
        The stated 1-σ of ``index`` and ``history`` (the store's ``index_sd``; NaN: none).
    history_speed : numpy.ndarray
        (wheels, segments, runs) speed of the history's passes, m/s.
    vehicle : str or None
        The run's vehicle (None: not stated).
    history_vehicle : numpy.ndarray
        (runs,) object: the vehicle of each history run.
    """

    seg: np.ndarray
    wheels: list[str]
    index: np.ndarray
    speed: np.ndarray
    history: np.ndarray
    history_days: np.ndarray
    classes: np.ndarray
    index_sd: np.ndarray | None = None
    history_sd: np.ndarray | None = None
    history_speed: np.ndarray | None = None
    vehicle: str | None = None
    history_vehicle: np.ndarray | None = None

    @property
    def mean_index(self) -> np.ndarray:
        """The index per segment, mean over the wheels (what a place is graded on)."""
        return mean_over_wheels(self.index)

    def passes(self, params: ChangeParams, *, support_days: np.ndarray | None = None) -> PassHistory:
        """The history as the run's matched passes (same vehicle, matched speed:
        :func:`~app.analysis.condition.change.matched_passes`, the step test's rule), mean over the wheels;
        with ``support_days`` (per segment, NaN: none) only the passes since the latest action on the support."""
        return PassHistory.of(self.history, self.history_speed, self.speed, self.history_days, params,
                              history_vehicle=self.history_vehicle, vehicle=self.vehicle, support_days=support_days)


def _vehicle_curves(values: np.ndarray, fit: np.ndarray, wheel_of: np.ndarray, row_cls: np.ndarray,
                    vehicles: dict[int, str | None], config: PlacesConfig) -> dict[str, dict]:
    """Each vehicle's own curves where the runs are of more than one vehicle (a vehicle's unsprung mass, wheel
    and sensor change the amplitude the same track gives: its typical track is its own), by vehicle."""
    run_veh = np.array([vehicles.get(int(r)) for r in values[:, 0].tolist()], dtype=object)
    names = sorted({v for v in run_veh[fit].tolist() if v is not None})
    if len(names) < 2:
        return {}
    out = {}
    for name in names:
        sel = fit & (run_veh == name)
        out[name] = fit_segment_curves(values[sel, 2].astype(np.int64), values[sel, 3], values[sel, 4],
                                       values[sel, 0], wheel_of[values[sel, 1].astype(np.int64)], row_cls[sel],
                                       min_locations=config.curve_min_locations)
    return out


def run_index(session: Session, line: ConditionLine, run_id: int, history: list[tuple[int, dt.datetime]], *,
              config: PlacesConfig = DEFAULT_PLACES_CONFIG) -> RunIndex | None:
    """The index of a run and of ``history`` (run id, time; oldest first) from the store's 10 m rows, with
    the line's reference curves fitted on those rows (None: the run has no 10 m rows)."""
    run_ids = [r for r, _ in history] + [run_id]
    values, wheel_names = q.segment_frame(session, run_ids, SEGMENT_M)
    grids = _grids(values, wheel_names, run_ids)
    seg, wheels, la, v, la_sd = grids[run_id]
    if seg.size == 0:
        return None
    all_seg = np.unique(values[:, 2].astype(np.int64))
    all_cls = segment_classes(session, line, all_seg, config.section_margin_m)
    cls_of = dict(zip(all_seg.tolist(), all_cls.tolist(), strict=True))
    row_cls = np.asarray(all_cls, dtype=object)[np.searchsorted(all_seg, values[:, 2].astype(np.int64))]
    # the curves from the run and its newest history runs (``curve_runs``: enough passes over the ±10 %
    # speed spread of a fleet; fitting a long history costs seconds a run and changes the curve little)
    fit = np.isin(values[:, 0], [r for r, _ in history[-config.curve_runs:]] + [run_id]) \
        if len(history) > config.curve_runs else np.ones(values.shape[0], dtype=bool)
    wheel_of = np.array(wheel_names, dtype=object)
    curves = fit_segment_curves(values[fit, 2].astype(np.int64), values[fit, 3], values[fit, 4], values[fit, 0],
                                wheel_of[values[fit, 1].astype(np.int64)], row_cls[fit],
                                min_locations=config.curve_min_locations)
    vehicles = q.run_vehicles(session, run_ids)
    by_vehicle = _vehicle_curves(values, fit, wheel_of, row_cls, vehicles, config)

    def index_of(r: int) -> np.ndarray:
        r_seg, _, r_la, r_v, _ = grids[r]
        r_cls = np.array([cls_of[int(s)] for s in r_seg.tolist()], dtype=object)
        out = segment_index(r_la, r_v, r_cls, curves)
        own = by_vehicle.get(vehicles.get(r))
        if own is not None:
            mine = segment_index(r_la, r_v, r_cls, own)
            out = np.where(np.isfinite(mine), mine, out)
        return out

    classes = np.array([cls_of[int(s)] for s in seg.tolist()], dtype=object)
    idx = index_of(run_id)
    hist = [_on(grids[r], seg, wheels, index_of(r)) for r, _ in history]
    hist_sd = [_on(grids[r], seg, wheels, grids[r][4]) for r, _ in history]
    hist_v = [_on(grids[r], seg, wheels, grids[r][3]) for r, _ in history]
    empty = np.zeros((*idx.shape, 0))
    return RunIndex(seg=seg, wheels=wheels, index=idx, speed=v,
                    history=np.stack(hist, axis=2) if hist else empty,
                    history_days=np.array([days_of(t) for _, t in history], dtype=np.float64), classes=classes,
                    index_sd=la_sd, history_sd=np.stack(hist_sd, axis=2) if hist_sd else empty,
                    history_speed=np.stack(hist_v, axis=2) if hist_v else empty, vehicle=vehicles.get(run_id),
                    history_vehicle=np.array([vehicles.get(r) for r, _ in history], dtype=object))


def version_history(session: Session, line: ConditionLine, when: dt.datetime, version: str,
                    config: PlacesConfig = DEFAULT_PLACES_CONFIG) -> list[tuple[int, dt.datetime]]:
    """The history runs a run of ``when`` is tested against (run id, time; oldest first): the earlier runs
    applied to the line's places with method ``version`` (:func:`app.db.places.history_runs`: the newest, and
    over the trend window some spread evenly)."""
    return q.history_runs(session, line.id, when, version, scan_runs=max(config.place.history_runs, 60),
                          window_days=config.place.trend_window_days)


def history_runs_of(session: Session, line: ConditionLine, run_id: int,
                    config: PlacesConfig = DEFAULT_PLACES_CONFIG) -> list[tuple[int, dt.datetime]]:
    """The history (run id, time; oldest first) a run's index is read with: a run applied to its line's places,
    its method version's history as the places read it; another run, the line's most recent runs before it
    (``history_runs``). Empty for an unknown run."""
    when = q.run_time(session, run_id)
    if when is None:
        return []
    applied = q.applied_run(session, run_id)
    if applied is not None:
        return version_history(session, line, when, applied.method_version, config)
    rows = session.execute(select(ConditionRun.run_id, ConditionRun.run_time).where(
        ConditionRun.line_key == line.id, ConditionRun.run_time < when)
        .order_by(ConditionRun.run_time.desc()).limit(config.place.history_runs)).all()
    return sorted(((int(r), t) for r, t in rows), key=lambda x: (x[1], x[0]))


def _run_index_as_placed(session: Session, line: ConditionLine, run_id: int,
                         config: PlacesConfig) -> RunIndex | None:
    """A run's index as the places read it (:func:`run_segment_index`)."""
    if q.run_time(session, run_id) is None:
        return None
    return run_index(session, line, run_id, history_runs_of(session, line, run_id, config), config=config)


def run_segment_index(session: Session, line: ConditionLine, run_id: int, *,
                      config: PlacesConfig = DEFAULT_PLACES_CONFIG) -> tuple[np.ndarray, np.ndarray]:
    """The speed-conditioned index per 10 m segment of a run (mean over the wheels) as the places use it:
    segment numbers (int64) and the index (NaN: none).

    A run applied to its line's places: the curves of its method version's history, exactly as the places
    were found on it. Another run: the curves of the line's most recent runs up to it (``history_runs``).
    """
    ri = _run_index_as_placed(session, line, run_id, config)
    return (ri.seg, ri.mean_index) if ri is not None else (np.zeros(0, np.int64), np.zeros(0))


def run_segment_rails(session: Session, line: ConditionLine, run_id: int, *,
                      config: PlacesConfig = DEFAULT_PLACES_CONFIG) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`run_segment_index` and the rails' scatter at each segment beyond the healthy one: its class's
    scatter from segment to segment in the run (:func:`~app.analysis.condition.run_places.class_scatter`, as
    the places take it; NaN where the class has too few neighbouring segments in the run), ln units — what
    the section classes take out of a section's spread. Measured, not the stated 1-σ: on issue 33's rough
    line the stated 1-σ beyond the healthy scatter (0.19–0.44) exceeded the spread of whole 200 m sections
    (0.13–0.21) of sound support."""
    ri = _run_index_as_placed(session, line, run_id, config)
    if ri is None:
        return np.zeros(0, np.int64), np.zeros(0), np.zeros(0)
    level = ri.mean_index
    return ri.seg, level, class_scatter(level, ri.classes, config.levels.alert_limits(ri.classes), ri.seg)
