"""Rail findings: the track impacts of a line's runs followed from run to run.

Each run reports its track impacts (dipped welds and joints, :mod:`app.analysis.impacts.classify` and
:mod:`~app.analysis.impacts.welds`) at positions on the line's aligned km axis. A weld is fixed to the
track, so the runs that pass it find it again at the same position (the runs' alignment residuals and
the impact's position error are a few decimetres). :func:`follow_findings` takes the runs in time order:
an impact within :data:`MATCH_M` of a finding already known joins it, else it starts a new one, whose
identity is its first sighting (run and position) — so a later run never changes a finding that exists,
it adds a sighting or a finding. A run whose km axis is off by more than that (its alignment to the line
failed or was not confident: a positioning error of metres) is first registered on the findings already
known (:func:`run_offset`: the offset most of its impacts agree on, within :data:`REGISTER_M`), so its
sightings join the findings they are. Per finding: its position (median of the sightings), its kind (the
asset register's where an asset lies within :data:`ASSET_M`, else by the dip's length: a joint's dip is
short, a weld's about a metre), the depth of each sighting, the runs that saw it out of those that passed
it, and the depth's trend (:func:`app.analysis.condition.outlook.linear_trend`, mm a year) over the
sightings since the latest work on the rails' surface over it (``surface_work``: a grinding or a rail renewal
recorded in the maintenance records; it changes the dip as it changes the surface, so a trend across it is
the work's step, not the rail wearing: on issue 33's real line, five seeds, 10 of 25 steady findings on the
ground stretch had a significant depth trend across the grinding, 1 of 129 elsewhere).

Pure: positions in metres, days from any origin, depths in mm.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from app.analysis.condition.outlook import Trend, linear_trend

__all__ = ["MATCH_M", "REGISTER_M", "MIN_AGREE", "AGREE_M", "run_offset", "ASSET_M", "JOINT_MAX_LENGTH_M", "FINDING_KINDS", "Sighting", "RunImpacts", "RailFinding",
           "SURFACE_MARGIN_M", "finding_kind", "follow_findings", "run_coverage", "latest_surface_work"]

#: An impact this close to a finding (its first sighting's position) is that finding again, m.
MATCH_M = 1.5
#: A run's impacts are registered on the known findings within this offset, m.
REGISTER_M = 12.0
#: Impacts that must agree on a run's offset (within :data:`AGREE_M`) before it is applied.
MIN_AGREE = 3
#: How closely the impacts must agree on the offset, m.
AGREE_M = 0.3
#: A finding this close to an asset of the register takes the asset's kind, m.
ASSET_M = 2.0
#: Work on the rails' surface over a finding: its recorded extent widened by this, m (the finding's position
#: is known to a few decimetres, a record's extent to its own rounding).
SURFACE_MARGIN_M = MATCH_M
#: A dip this short or shorter is a joint's (a rail end: 0.3–0.5 m), longer a weld's (0.8–1.2 m), m.
JOINT_MAX_LENGTH_M = 0.6
#: Kinds of rail findings: from the asset register, else from the dip.
FINDING_KINDS: tuple[str, ...] = ("weld", "joint", "insulated_joint", "switch", "crossing", "level_crossing",
                                  "bridge", "other")
#: Register types that name a finding's kind directly.
_REGISTER_KINDS = {"weld": "weld", "insulated_joint": "insulated_joint", "switch": "switch", "crossing": "crossing",
                   "level_crossing": "level_crossing", "bridge": "bridge", "other": "other"}


@dataclass(frozen=True)
class Sighting:
    """One run's impact at a finding: run, day, position (m), depth (mm), dip length (m, NaN: unknown)."""

    run_id: int
    day: float
    track_m: float
    depth_mm: float
    length_m: float = math.nan


@dataclass(frozen=True)
class RunImpacts:
    """A run's track impacts: its id, day, the stretch it covered (m) and ``(track_m, depth_mm, length_m)``."""

    run_id: int
    day: float
    covered_m: tuple[float, float]
    impacts: Sequence[tuple[float, float, float]]


@dataclass
class RailFinding:
    """A dipped weld or joint followed over a line's runs.

    Attributes
    ----------
    first_run_id : int
        The run that found it first.
    anchor_m : float
        Where that run found it, m (the finding's identity with ``first_run_id``).
    sightings : list of Sighting
        Every run that found it, in time order.
    passed : list of int
        Every run that covered its position (found it or not).
    kind : str
        :data:`FINDING_KINDS` (set by :func:`follow_findings`).
    asset : dict, optional
        The register's asset it lies on (``type``, ``track_m``, ``name``), if any.
    surface_day : float
        Day of the latest work on the rails' surface over it (NaN: none; set by :func:`follow_findings`): its
        depth's trend is read over the sightings after it.
    """

    first_run_id: int
    anchor_m: float
    sightings: list[Sighting] = field(default_factory=list)
    passed: list[int] = field(default_factory=list)
    kind: str = "weld"
    asset: Mapping[str, object] | None = None
    surface_day: float = math.nan

    @property
    def track_m(self) -> float:
        """Median position of the sightings, m."""
        return float(np.median([s.track_m for s in self.sightings]))

    @property
    def runs_seen(self) -> int:
        """Runs that found it."""
        return len(self.sightings)

    @property
    def runs_passed(self) -> int:
        """Runs that covered its position."""
        return len(self.passed)

    @property
    def steady(self) -> bool:
        """Seen by at least half the runs that passed it (``2 · runs_seen ≥ runs_passed``): a feature of
        the rail, which every pass answers, as against a one-off of a few passes (on issue 33's rough
        line 10 of 43 findings matched no weld or joint, each seen by 1 to 3 of 24 runs)."""
        return 2 * self.runs_seen >= self.runs_passed

    @property
    def depth_mm(self) -> float:
        """Depth of the newest sighting, mm."""
        return float(self.sightings[-1].depth_mm)

    @property
    def length_m(self) -> float:
        """Median dip length of the sightings that state one, m (NaN: none does)."""
        lengths = [s.length_m for s in self.sightings if math.isfinite(s.length_m)]
        return float(np.median(lengths)) if lengths else math.nan

    @property
    def trend_sightings(self) -> list[Sighting]:
        """The sightings its depth's trend is read over: those after :attr:`surface_day` (all where none)."""
        if not math.isfinite(self.surface_day):
            return list(self.sightings)
        return [s for s in self.sightings if s.day > self.surface_day]

    def depth_trend(self) -> Trend:
        """The depth's least-squares trend over :attr:`trend_sightings`, mm a year."""
        seen = self.trend_sightings
        return linear_trend(np.array([s.day for s in seen]), np.array([s.depth_mm for s in seen]))


def run_coverage(impacts: Sequence[tuple[float, float, float]], rows_m: tuple[float, float] | None,
                 ) -> tuple[tuple[float, float], list[tuple[float, float, float]]]:
    """A run's covered stretch and the impacts it found there.

    Parameters
    ----------
    impacts : sequence of (track_m, depth_mm, length_m)
        The run's track impacts on the line's km axis.
    rows_m : (float, float) or None
        The stretch the run's condition rows cover, m (None: the run has none).

    Returns
    -------
    covered_m : (float, float)
        ``rows_m``; without rows, the impacts' extent (NaN, NaN: none either).
    impacts : list
        Those within ``covered_m``. An impact beyond the run's rows lies where the store kept none of its
        values (a record's ends): counted, it made the run pass there while the runs that did not find it
        had not passed — a finding at a line's end that three of 24 runs found read "seen 3 of 3".
    """
    found = [tuple(map(float, i)) for i in impacts]
    if rows_m is None:
        xs = [x for x, _, _ in found]
        return ((min(xs), max(xs)) if xs else (math.nan, math.nan)), found
    lo, hi = float(rows_m[0]), float(rows_m[1])
    if not lo <= hi:
        raise ValueError(f"rows_m: need lo <= hi, got {rows_m!r}")
    return (lo, hi), [i for i in found if lo <= i[0] <= hi]


def finding_kind(length_m: float, asset_type: str | None = None) -> str:
    """The kind of a finding: the register's (``asset_type``) where it names one, else ``"joint"`` for a
    dip no longer than :data:`JOINT_MAX_LENGTH_M` and ``"weld"`` for a longer (or unknown) one."""
    if asset_type is not None and asset_type in _REGISTER_KINDS:
        return _REGISTER_KINDS[asset_type]
    if math.isfinite(length_m) and length_m <= JOINT_MAX_LENGTH_M:
        return "joint"
    return "weld"


def run_offset(impacts_m: np.ndarray, anchors_m: np.ndarray, *, register_m: float = REGISTER_M,
               agree_m: float = AGREE_M, min_agree: int = MIN_AGREE) -> float:
    """The offset (m) that moves a run's impacts onto the known findings, 0 where they do not agree on one.

    Every pair of an impact and a finding within ``register_m`` votes for its difference; the difference
    that most pairs share within ``agree_m`` wins when at least ``min_agree`` distinct impacts and more than
    a third of the run's impacts near a finding share it (a line of welds every 60–120 m has no second
    offset as good within 12 m); the offset is the median of those pairs.
    """
    x = np.asarray(impacts_m, dtype=np.float64)
    a = np.asarray(anchors_m, dtype=np.float64)
    x, a = x[np.isfinite(x)], a[np.isfinite(a)]
    if x.size < min_agree or a.size < min_agree:
        return 0.0
    d = a[None, :] - x[:, None]
    i, j = np.nonzero(np.abs(d) <= register_m)
    if i.size < min_agree:
        return 0.0
    diffs = d[i, j]
    order = np.argsort(diffs, kind="stable")
    diffs, i = diffs[order], i[order]
    hi = np.searchsorted(diffs, diffs + agree_m, side="right")
    support = [np.unique(i[k:h]).size for k, h in enumerate(hi)]
    best = int(np.argmax(support))
    near = np.unique(i).size
    if support[best] < min_agree or 3 * support[best] <= near:
        return 0.0
    off = float(np.median(diffs[best:hi[best]]))
    return off if abs(off) > 0.5 * agree_m else 0.0


def latest_surface_work(track_m: float, surface_work: Sequence[tuple[float, float, float]], *,
                        margin_m: float = SURFACE_MARGIN_M) -> float:
    """Day of the latest work on the rails' surface over ``track_m`` (NaN: none).

    Parameters
    ----------
    track_m : float
        Position on the line's km axis, m.
    surface_work : sequence of (start_m, end_m, day)
        The recorded work on the rails' surface (grinding, rail renewal): extent (m, either order) and day.
    margin_m : float
        The extents widened by this, m (≥ 0).
    """
    if not (math.isfinite(margin_m) and margin_m >= 0):
        raise ValueError(f"margin_m: must be >= 0, got {margin_m!r}")
    days = [float(d) for a, b, d in surface_work
            if min(a, b) - margin_m <= track_m <= max(a, b) + margin_m and math.isfinite(float(d))]
    return max(days) if days else math.nan


def follow_findings(runs: Sequence[RunImpacts], *, assets: Sequence[Mapping[str, object]] = (),
                    surface_work: Sequence[tuple[float, float, float]] = (),
                    match_m: float = MATCH_M, asset_m: float = ASSET_M, register_m: float = REGISTER_M
                    ) -> list[RailFinding]:
    """The line's rail findings from its runs' track impacts (module docstring).

    Parameters
    ----------
    runs : sequence of RunImpacts
        Any order (taken in time order, then run id).
    assets : sequence of dict
        The register's assets of the line and track: ``type``, ``track_m`` (m), optional ``name``.
    surface_work : sequence of (start_m, end_m, day)
        The recorded work on the rails' surface (grinding, rail renewal; days on the runs' axis): each
        finding's :attr:`RailFinding.surface_day` (:func:`latest_surface_work`).
    match_m, asset_m, register_m : float
        See :data:`MATCH_M`, :data:`ASSET_M`, :data:`REGISTER_M` (0: runs are taken as aligned).

    Returns
    -------
    list of RailFinding
        Ascending position.
    """
    if not (math.isfinite(match_m) and match_m > 0 and math.isfinite(asset_m) and asset_m >= 0
            and math.isfinite(register_m) and register_m >= 0):
        raise ValueError("match_m: must be > 0, asset_m and register_m: >= 0")
    found: list[RailFinding] = []
    anchors = np.zeros(0)
    coverage: list[tuple[int, float, float]] = []
    for run in sorted(runs, key=lambda r: (float(r.day), int(r.run_id))):
        off = run_offset(np.array([float(i[0]) for i in run.impacts]), anchors, register_m=register_m)
        lo, hi = sorted(float(v) + off for v in run.covered_m)
        coverage.append((int(run.run_id), lo, hi))
        taken: set[int] = set()
        for x, depth, length in sorted(run.impacts, key=lambda i: float(i[0])):
            x = float(x) + off
            if not (math.isfinite(x) and math.isfinite(float(depth))):
                continue
            j = -1
            if anchors.size:
                d = np.abs(anchors - x)
                d[list(taken)] = np.inf  # one sighting per run and finding
                k = int(np.argmin(d))
                if d[k] <= match_m:
                    j = k
            if j < 0:
                found.append(RailFinding(int(run.run_id), x))
                anchors = np.append(anchors, x)
                j = len(found) - 1
            taken.add(j)
            found[j].sightings.append(Sighting(int(run.run_id), float(run.day), x, float(depth), float(length)))
    for f in found:
        # every run that covered its position, also those before the first that saw it: a finding one run of 24
        # saw was "seen 1 of 1" when counted from its first sighting on
        # (a run that saw it passed it, also where its covered stretch ends just short of the anchor)
        seen = {s.run_id for s in f.sightings}
        f.passed = [rid for rid, lo, hi in coverage if lo <= f.anchor_m <= hi or rid in seen]
        pos = f.track_m
        near = [a for a in assets if abs(float(a["track_m"]) - pos) <= asset_m]  # type: ignore[arg-type]
        best = min(near, key=lambda a: abs(float(a["track_m"]) - pos)) if near else None  # type: ignore[arg-type]
        f.asset = best
        f.kind = finding_kind(f.length_m, None if best is None else str(best["type"]))
        f.surface_day = latest_surface_work(pos, surface_work)
    return sorted(found, key=lambda f: f.track_m)
