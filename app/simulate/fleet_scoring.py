"""Scoring a generated fleet history against its plan: how often unchanged places were flagged,
which planted steps were found by the first run after them, how long each planted trend took to
be flagged (the detection targets of the condition store, ``bench/bench_condition.py``).

The history itself (runs, their segments and assessments) comes from :mod:`app.simulate.fleet`.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from app.analysis.condition import Flag
from app.simulate.fleet import FleetDay, FleetPlan

__all__ = ["FleetScore", "FleetScorer", "score_history"]


@dataclass
class FleetScore:
    """How the flags of a generated history compare with its plan.

    Attributes
    ----------
    unchanged_tested : int
        (run, place) pairs away from every planted change with a step score, runs after the first
        ``min_history``.
    unchanged_flagged : int
        Of those, how many were flagged (any test).
    newest_unchanged_rate : float
        The same fraction in the newest run only.
    steps_found, steps_total : int
        Planted steps flagged (10 m step test, right direction, overlapping the extent) by the first
        run on or after their day.
    trend_delays_days : list of float
        Per planted trend, days from its start until the first trend flag over it (inf: never).
    """

    unchanged_tested: int = 0
    unchanged_flagged: int = 0
    newest_unchanged_rate: float = float("nan")
    steps_found: int = 0
    steps_total: int = 0
    trend_delays_days: list[float] = field(default_factory=list)

    @property
    def false_flag_rate(self) -> float:
        """Fraction of unchanged places flagged."""
        return self.unchanged_flagged / self.unchanged_tested if self.unchanged_tested else float("nan")

    @property
    def step_detection_rate(self) -> float:
        """Fraction of planted steps found."""
        return self.steps_found / self.steps_total if self.steps_total else float("nan")

    def trends_found_within(self, days: float) -> float:
        """Fraction of planted trends flagged within ``days`` of their start."""
        d = np.asarray(self.trend_delays_days, dtype=np.float64)
        return float(np.mean(d <= days)) if d.size else float("nan")


def _overlaps(flag: Flag, lo: float, hi: float, margin_m: float = 0.0) -> bool:
    a, b = flag.seg * flag.seg_m, (flag.seg + 1) * flag.seg_m
    return a < hi + margin_m and lo - margin_m < b


class FleetScorer:
    """Scores the flags of generated runs against the planted changes, one run at a time
    (:meth:`add` each :class:`FleetDay` in date order, then :meth:`score`).

    Places within ``margin_m`` of a planted extent (steps, trends, actions) do not
    count as unchanged; runs before ``min_history`` are not counted.
    """

    def __init__(self, plan: FleetPlan, *, min_history: int = 8, margin_m: float = 100.0) -> None:
        self.plan, self.min_history, self.margin_m = plan, min_history, margin_m
        self._extents = [(e.track_from_m, e.track_to_m) for e in (*plan.steps, *plan.trends, *plan.actions)]
        self._step_found = [False] * len(plan.steps)
        self._step_checked = [False] * len(plan.steps)
        self._trend_delay = [float("inf")] * len(plan.trends)
        self._tested = self._flagged = 0
        self._newest = (0, 0)

    def add(self, fd: FleetDay) -> None:
        """Score one run."""
        flags = fd.assessment.flags
        for k, st in enumerate(self.plan.steps):
            if not self._step_checked[k] and fd.day >= st.day:
                self._step_checked[k] = True
                want = 1 if st.factor > 1 else -1
                self._step_found[k] = any(f.kind == "step" and f.seg_m == 10.0 and f.direction == want
                                          and _overlaps(f, st.track_from_m, st.track_to_m) for f in flags)
        for k, tr in enumerate(self.plan.trends):
            if np.isinf(self._trend_delay[k]) and fd.day >= tr.day and any(
                    f.kind == "trend" and f.direction == 1 and _overlaps(f, tr.track_from_m, tr.track_to_m)
                    for f in flags):
                self._trend_delay[k] = fd.day - tr.day
        if fd.number < self.min_history:
            return
        tested = flagged = 0
        m = self.margin_m
        for seg_m, changes in fd.assessment.changes.items():
            flagged_segs = {f.seg for f in flags if f.seg_m == seg_m}
            segs = np.unique(np.concatenate([fd.segments[seg_m][w].seg[np.isfinite(c.change_z)]
                                             for w, c in changes.items()] or [np.zeros(0, np.int64)]))
            lo, hi = segs * seg_m, (segs + 1) * seg_m
            away = np.ones(segs.size, dtype=bool)
            for a, b in self._extents:
                away &= ~((lo < b + m) & (a - m < hi))
            tested += int(away.sum())
            flagged += int(sum(1 for s, ok in zip(segs.tolist(), away.tolist(), strict=True)
                               if ok and s in flagged_segs))
        self._tested += tested
        self._flagged += flagged
        self._newest = (tested, flagged)

    def score(self) -> FleetScore:
        """The score of the runs added so far."""
        tested, flagged = self._newest
        return FleetScore(
            unchanged_tested=self._tested, unchanged_flagged=self._flagged,
            newest_unchanged_rate=flagged / tested if tested else float("nan"),
            steps_found=int(sum(self._step_found)), steps_total=int(sum(self._step_checked)),
            trend_delays_days=list(self._trend_delay),
        )


def score_history(plan: FleetPlan, days: Iterator[FleetDay] | list[FleetDay], *, min_history: int = 8,
                  margin_m: float = 100.0) -> FleetScore:
    """Score the flags of :func:`app.condition.fleet.fleet_history` against the planted changes (:class:`FleetScorer`)."""
    scorer = FleetScorer(plan, min_history=min_history, margin_m=margin_m)
    for fd in days:
        scorer.add(fd)
    return scorer.score()
