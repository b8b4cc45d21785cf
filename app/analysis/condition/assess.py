"""A run's condition against its history: change tests per wheel, flags per place.

:func:`assess_run` takes a run's segment statistics (per segment length and
wheel, :class:`~app.analysis.condition.segments.SegmentStats`) and a *history*
— anything that answers :meth:`HistorySource.matrix` with the earlier runs'
index and speed on the run's segments — and returns the change tests of
every wheel (:func:`~app.analysis.condition.change.detect_changes`) and the
flags: per segment length, place and test, the wheels' scores combined
(:func:`~app.analysis.condition.change.combine_wheels`); ``|combined| ≥``
the test's threshold flags the place, with the wheels that agree.

The step test runs on every segment length, the trend test on
``trend_segment_m`` (100 m: a gradual change is slow and wide, and the
longer segments are the more repeatable).

With the stated 1-σ of each run's index (``SegmentStats.index_sd``, :attr:`HistoryMatrix.index_sd`)
and the rail-surface interventions of the line (``interventions``: grinding, rail renewal), the
step test widens as :mod:`app.analysis.condition.change` says (a grinding is not a stiffness change).

Two history sources share the same matrices: the database (the publish step,
:mod:`app.condition.writer`) and :class:`RollingHistory`, an in-memory
window over the runs of one line in date order (the fleet generator and the
tests), so a generated history is judged exactly as a published one.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from app.analysis.condition.change import (
    DEFAULT_CHANGE_PARAMS,
    ChangeParams,
    WheelChange,
    axle_labels,
    combine_wheels,
    detect_changes,
    series_labels,
)
from app.analysis.condition.interventions import latest_action_days, since_actions
from app.analysis.condition.segments import SegmentStats

__all__ = [
    "HistoryMatrix",
    "HistorySource",
    "Flag",
    "RunAssessment",
    "assess_run",
    "RollingHistory",
    "TREND_SEGMENT_M",
]

#: Segment length of the trend test, m.
TREND_SEGMENT_M = 100.0


@dataclass(frozen=True)
class HistoryMatrix:
    """Earlier runs on a run's segments, oldest column first.

    Attributes
    ----------
    index, speed : numpy.ndarray
        (segments, runs) index and speed (m/s); NaN where a run has no value.
    days : numpy.ndarray
        (runs,) time of each run, days.
    index_sd : numpy.ndarray, optional
        (segments, runs) stated 1-σ of the index (NaN or None: none stated).
    vehicle : numpy.ndarray, optional
        (runs,) vehicle of each run (object labels; None: not known).
    """

    index: np.ndarray
    speed: np.ndarray
    days: np.ndarray
    index_sd: np.ndarray | None = None
    vehicle: np.ndarray | None = None

    @classmethod
    def empty(cls, n_segments: int) -> HistoryMatrix:
        """No earlier run."""
        return cls(np.zeros((n_segments, 0)), np.zeros((n_segments, 0)), np.zeros(0), np.zeros((n_segments, 0)))


class HistorySource(Protocol):
    """Where :func:`assess_run` gets the history of a wheel's segments."""

    def matrix(self, seg_m: float, wheel: str, seg: np.ndarray, *, trend: bool) -> HistoryMatrix:
        """Earlier runs of ``wheel`` on segments ``seg`` (the trend window too when ``trend``)."""
        ...


@dataclass(frozen=True)
class Flag:
    """A place whose condition changed beyond the repeatability in the newest run.

    Attributes
    ----------
    seg_m : float
        Segment length, m.
    seg : int
        Segment number (``[seg · seg_m, (seg + 1) · seg_m)`` m on the km axis).
    kind : str
        ``"step"`` or ``"trend"``.
    direction : int
        +1 the index rose, -1 it fell.
    score : float
        Combined score over the wheels (repeatability units).
    change : float
        Mean change of the index over the wheels with a score (log units).
    rate_per_year : float
        Mean trend over those wheels, log units per year (NaN for steps without a trend test).
    wheels : tuple of str
        Wheels that agree.
    is_new : bool
        The previous run was not flagged here by the same test in the same direction.
    """

    seg_m: float
    seg: int
    kind: str
    direction: int
    score: float
    change: float
    rate_per_year: float
    wheels: tuple[str, ...]
    is_new: bool = True

    @property
    def key(self) -> tuple[int, int, str, int]:
        """``(seg_m, seg, kind, direction)``: what "the same flag" means from run to run."""
        return int(round(self.seg_m)), int(self.seg), self.kind, int(self.direction)


@dataclass
class RunAssessment:
    """Change tests and flags of one run.

    Attributes
    ----------
    changes : dict
        ``{seg_m: {wheel: WheelChange}}``, aligned with the run's SegmentStats.
    flags : list of Flag
    exponents : dict
        ``{seg_m: {wheel: speed exponent}}`` used to move the history to the run's speed.
    """

    changes: dict[float, dict[str, WheelChange]] = field(default_factory=dict)
    flags: list[Flag] = field(default_factory=list)
    exponents: dict[float, dict[str, float]] = field(default_factory=dict)


def _combine(kind: str, seg_m: float, stats: Mapping[str, SegmentStats], changes: Mapping[str, WheelChange],
             params: ChangeParams, previous: set[tuple[int, int, str, int]], series: Mapping[str, str]) -> list[Flag]:
    wheels = sorted(changes)
    if not wheels:
        return []
    segs = np.unique(np.concatenate([stats[w].seg for w in wheels]))
    z = np.full((len(wheels), segs.size), np.nan)
    change = np.full_like(z, np.nan)
    rate = np.full_like(z, np.nan)
    sd = np.full_like(z, np.nan)
    for i, w in enumerate(wheels):
        j = np.searchsorted(segs, stats[w].seg)
        c = changes[w]
        z[i, j] = c.change_z if kind == "step" else c.trend_z
        change[i, j] = c.change
        rate[i, j] = c.trend_rate
        if c.change_sd is not None:
            sd[i, j] = c.change_sd
    labels = np.array([series.get(w, w) for w in wheels], dtype=object)
    if kind == "step":
        # a change of the support is one change under every axle (:func:`combine_wheels`)
        combined, agree = combine_wheels(z, params.agree_z, labels, change=change, sd=sd, axles=axle_labels(wheels))
    else:
        combined, agree = combine_wheels(z, params.agree_z, labels)
    threshold = params.step_z if kind == "step" else params.trend_z
    out = []
    for j in np.flatnonzero(np.abs(np.nan_to_num(combined)) >= threshold):
        has = np.isfinite(z[:, j])
        direction = 1 if combined[j] > 0 else -1
        key = (int(round(seg_m)), int(segs[j]), kind, direction)
        out.append(Flag(
            seg_m=seg_m, seg=int(segs[j]), kind=kind, direction=direction, score=float(combined[j]),
            change=float(np.mean(change[has, j])),
            rate_per_year=float(np.mean(rate[has, j])) if np.isfinite(rate[has, j]).any() else float("nan"),
            wheels=tuple(w for i, w in enumerate(wheels) if agree[i, j]),
            is_new=key not in previous,
        ))
    return out


def assess_run(
    run: Mapping[float, Mapping[str, SegmentStats]],
    history: HistorySource,
    now_days: float,
    *,
    params: ChangeParams = DEFAULT_CHANGE_PARAMS,
    previous_flags: set[tuple[int, int, str, int]] | None = None,
    trend_segment_m: float = TREND_SEGMENT_M,
    interventions: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    intervention_margin_m: float | None = None,
    vehicle: object = None,
    support: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> RunAssessment:
    """Change tests of a run's segments against their history, and the flags.

    Parameters
    ----------
    run : mapping
        ``{seg_m: {wheel: SegmentStats}}`` of the newest run.
    history : HistorySource
        Earlier runs of the same line.
    now_days : float
        The run's time, days (the history's time axis).
    params : ChangeParams
    previous_flags : set, optional
        :attr:`Flag.key` of the flags of the line's previous run (what is not new).
    trend_segment_m : float
        Segment length the trend test runs on.
    interventions : tuple of numpy.ndarray, optional
        ``(start_m, end_m, day)`` of the line's rail-surface interventions (grinding, rail renewal) on
        the run's km axis and time axis (:func:`~app.analysis.condition.interventions.latest_action_days`).
    intervention_margin_m : float, optional
        Their extents widened by this much, m (default
        :func:`~app.analysis.condition.interventions.intervention_margin_m` at 3 m resolution).
    vehicle : object, optional
        The run's vehicle: the step tests' passes are the same vehicle's where the history says which
        vehicle each run was (``HistoryMatrix.vehicle``; :func:`~app.analysis.condition.change.vehicle_matched`).
    support : tuple of numpy.ndarray, optional
        ``(start_m, end_m, day)`` of the line's actions on the support (a tamping, ballast cleaning …), widened
        as the interventions are: a segment's history starts anew after the latest one over it
        (:func:`~app.analysis.condition.interventions.since_actions`).

    Returns
    -------
    RunAssessment
    """
    previous = previous_flags or set()
    out = RunAssessment()
    for seg_m, wheels in run.items():
        trend = abs(seg_m - trend_segment_m) < 1e-9
        changes: dict[str, WheelChange] = {}
        scored = [w for w, st in wheels.items() if len(st)]
        # the wheels that give one index (an axle's two under the two-rail estimate) are one witness
        series = {w: scored[k] for w, k in zip(scored, series_labels([wheels[w].index for w in scored]).tolist(),
                                                strict=True)}
        n_wheels = max(len(set(series.values())), 1)
        for wheel, st in wheels.items():
            if len(st) == 0:
                continue
            hist = history.matrix(seg_m, wheel, st.seg, trend=trend)
            surface = None
            if interventions is not None:
                surface = latest_action_days(st.seg, seg_m, *interventions, now_days, margin_m=intervention_margin_m)
            index = hist.index
            if support is not None:
                index = since_actions(index, hist.days, latest_action_days(st.seg, seg_m, *support, now_days,
                                                                            margin_m=intervention_margin_m))
            changes[wheel] = detect_changes(
                index, hist.speed, hist.days, st.index, st.speed_mean, now_days, st.seg,
                segment_m=seg_m, params=params, trend=trend, sd_value=st.index_sd, sd_history=hist.index_sd,
                surface_days=surface, stated_wheels=n_wheels, history_vehicle=hist.vehicle, vehicle=vehicle,
            )
        out.changes[seg_m] = changes
        out.exponents[seg_m] = {w: c.exponent for w, c in changes.items()}
        out.flags += _combine("step", seg_m, wheels, changes, params, previous, series)
        if trend:
            out.flags += _combine("trend", seg_m, wheels, changes, params, previous, series)
    return out


class RollingHistory:
    """The recent runs of one line in memory, as :class:`HistorySource`.

    Keeps, per segment length and wheel, a dense window over the segments
    seen so far: the last ``params.history_scan_runs`` runs, and for the trend
    segment length also every run within ``params.trend_window_days`` of the
    newest. Feed it the runs in date order: :meth:`append` after
    :func:`assess_run`.
    """

    def __init__(self, params: ChangeParams = DEFAULT_CHANGE_PARAMS, trend_segment_m: float = TREND_SEGMENT_M) -> None:
        self.params = params
        self.trend_segment_m = trend_segment_m
        self._cols: dict[tuple[float, str], list[tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]]] = {}
        self.flags: set[tuple[int, int, str, int]] = set()

    def matrix(self, seg_m: float, wheel: str, seg: np.ndarray, *, trend: bool) -> HistoryMatrix:
        """Earlier runs of ``wheel`` on ``seg`` (NaN where a run has no value there)."""
        cols = self._cols.get((seg_m, wheel), [])
        seg = np.asarray(seg, dtype=np.int64)
        index = np.full((seg.size, len(cols)), np.nan)
        speed = np.full_like(index, np.nan)
        sd = np.full_like(index, np.nan)
        for k, (_, s, idx, v, isd) in enumerate(cols):
            if s.size == seg.size and np.array_equal(s, seg):  # the usual case: a run over the same segments
                index[:, k], speed[:, k], sd[:, k] = idx, v, isd
                continue
            j = np.searchsorted(s, seg)
            hit = (j < s.size) & (s[np.minimum(j, s.size - 1)] == seg)
            index[hit, k] = idx[j[hit]]
            speed[hit, k] = v[j[hit]]
            sd[hit, k] = isd[j[hit]]
        return HistoryMatrix(index, speed, np.array([c[0] for c in cols], dtype=np.float64), sd)

    def append(self, day: float, run: Mapping[float, Mapping[str, SegmentStats]],
               flags: list[Flag] | None = None) -> None:
        """Add a run (after assessing it) and remember its flags as the previous ones."""
        for seg_m, wheels in run.items():
            trend = abs(seg_m - self.trend_segment_m) < 1e-9
            for wheel, st in wheels.items():
                cols = self._cols.setdefault((seg_m, wheel), [])
                cols.append((float(day), st.seg.copy(), st.index.copy(), st.speed_mean.copy(), st.index_sd.copy()))
                keep = self.params.history_scan_runs
                if trend:
                    keep = max(keep, sum(1 for c in cols if c[0] > day - self.params.trend_window_days))
                del cols[:-keep]
        self.flags = {f.key for f in (flags or [])}
