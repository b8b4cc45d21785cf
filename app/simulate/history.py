"""Fleet histories for the real pipeline: the runs of one line over weeks, the track changing between them.

:mod:`app.simulate.fleet` writes a year of *segment rows* for the store's benchmark;
this module writes what a measuring vehicle would bring home instead: per run a
full four-wheel signal (:func:`app.simulate.run.simulate_run`) of the line **as
it is on that day**, with the run's own speed profile and odometry error, plus
the reference files an asset manager would import (superstructure sections and
the maintenance actions of the history). Uploaded and processed like any run,
the history goes through ingest, the VKF, the profile rows, the alignment and
the condition store: whatever the work list shows of it was computed by the
product, and :meth:`HistorySpec.truth_places` says what it should show.

The track over time
-------------------
The line model (:class:`~app.simulate.track.LineModel`) is the track on day 0;
its stiffness factor ``f(x)`` (the sleeper-passage amplitude relative to its
superstructure type's, both rails) is changed from a day on by
:class:`TrackChange` s, multiplicatively with raised-cosine tapers::

    ln f(x, t) = ln f0(x) + Σ_c w_c(x) · [ln factor_c + rate_c · (t − day_c) / DAYS_PER_YEAR]   (t ≥ day_c)

* ``kind="change"``: a sudden change (a broken support, a new soft spot):
  ``factor`` from its day on (0.8 = −20 % amplitude);
* ``kind="developing"``: ``factor`` 1 and ``rate_per_year`` (ln units per
  year): a place getting worse;
* ``kind="tamping"``: a maintenance action. It **repairs** what changed inside
  its extent before its day (the earlier changes are weighed down by ``1 − w``
  from then on) and applies its own effect ``factor`` with a regrowth
  ``rate_per_year`` (tamped ballast settles back); it is also written as a
  maintenance record (type ``tamping``).

Runs
----
A :class:`HistoryRun` passes the line on its day at its cruise speed, with
speed ramps at both ends (the train accelerates out of a station over
``ramp_in_m`` and brakes over ``ramp_out_m``: :func:`ramp_profile`) and a start
odometry error ``km_error_m`` (the position the file states is that much off).
The wheels (out-of-roundness) are the same vehicle's in every run.

Scenarios: :func:`planted_history` (lasting anomalies, two new changes, a
developing place, a tamping over it, cruise speeds ±10 %) and
:func:`uniform_history` (one superstructure type, nothing planted, speed
ramps): the two the work list is judged on.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import json
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

from app.analysis.stiffness.track_dynamics import TrackParameters
from app.analysis.units import DAYS_PER_YEAR, KMH_PER_MPS
from app.simulate.amplitude import ResonanceResponse
from app.simulate.run import DEFAULT_TRUE_DIAMETERS_M, simulate_run
from app.simulate.speed import SpeedProfile
from app.simulate.surface import RailGrinding, TrackImpact, as_date, generate_surface
from app.simulate.track import (
    SUPERSTRUCTURE_LABELS,
    SUPERSTRUCTURE_TYPES,
    LineModel,
    StiffnessAnomaly,
    TrackSection,
    generate_line,
)
from app.simulate.wheels import random_wheel_oor

__all__ = [
    "CHANGE_KINDS",
    "TrackChange",
    "HistoryRun",
    "HistorySpec",
    "HistoryFiles",
    "TruthPlace",
    "ramp_profile",
    "planted_history",
    "uniform_history",
    "grinding_history",
    "real_line_history",
    "REAL_LINE_SPEEDS_MPS",
    "HistoryVehicle",
    "HistoryAsset",
    "RailFeature",
    "demo_history",
    "write_history",
]

_KMH = 1.0 / KMH_PER_MPS
#: Kinds of :class:`TrackChange`.
CHANGE_KINDS = ("change", "developing", "tamping")


def _finite(name: str, value: float) -> float:
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"{name}: must be finite, got {value!r}")
    return v


@dataclass(frozen=True)
class TrackChange:
    """A change of the track's stiffness factor over ``[track_from_m, track_to_m]`` from ``day`` on.

    Attributes
    ----------
    kind : {"change", "developing", "tamping"}
        What it stands for (module docstring).
    track_from_m, track_to_m : float
        Extent on the km axis, m (tapers inside it).
    day : float
        Day of the history it happens on (day 0 = the history's start).
    factor : float
        Amplitude factor from ``day`` on (> 0; 1.25 = +25 %).
    rate_per_year : float
        Further change of ``ln f`` per year after ``day`` (ln units / year).
    taper_m : float
        Raised-cosine taper at each end, m (≥ 0).
    """

    kind: str
    track_from_m: float
    track_to_m: float
    day: float
    factor: float = 1.0
    rate_per_year: float = 0.0
    taper_m: float = 5.0

    def __post_init__(self) -> None:
        if self.kind not in CHANGE_KINDS:
            raise ValueError(f"kind: must be one of {CHANGE_KINDS}, got {self.kind!r}")
        a, b = _finite("track_from_m", self.track_from_m), _finite("track_to_m", self.track_to_m)
        if not a < b:
            raise ValueError(f"track_from_m/track_to_m: need from < to, got {a!r}, {b!r}")
        _finite("day", self.day)
        if not (math.isfinite(self.factor) and self.factor > 0):
            raise ValueError(f"factor: must be a finite number > 0, got {self.factor!r}")
        _finite("rate_per_year", self.rate_per_year)
        if not (math.isfinite(self.taper_m) and self.taper_m >= 0):
            raise ValueError(f"taper_m: must be >= 0, got {self.taper_m!r}")

    def weight(self, x: np.ndarray) -> np.ndarray:
        """Shape ``w(x)`` in [0, 1] at track positions ``x`` (m)."""
        shape = StiffnessAnomaly(self.track_from_m, self.track_to_m, 1.0, self.taper_m)
        return shape.weight(x)

    def log_effect(self, day: float) -> float:
        """``ln factor + rate · (day − self.day) / DAYS_PER_YEAR`` on ``day`` (0 before ``self.day``)."""
        if day < self.day:
            return 0.0
        return math.log(self.factor) + self.rate_per_year * (day - self.day) / DAYS_PER_YEAR


@dataclass(frozen=True)
class HistoryRun:
    """One pass of the line.

    Attributes
    ----------
    day : float
        Day of the history (the run starts at ``start + day`` days, 08:00 + ``hour_offset``).
    cruise_kmh : float
        Cruise speed between the ramps, km/h.
    km_error_m : float
        Start odometry error, m (the file states the start that much too far).
    seed : int
        Seed of the run's noise.
    vehicle : int
        Which of :attr:`HistorySpec.vehicles` made the run (0 without vehicles: the spec's own
        ``vehicle_id`` and ``vehicle_seed``).
    """

    day: float
    cruise_kmh: float
    km_error_m: float = 0.0
    seed: int = 0
    vehicle: int = 0


@dataclass(frozen=True)
class HistoryVehicle:
    """A measuring vehicle of a history (its wheels are the same in every run it makes).

    Attributes
    ----------
    vehicle_id : str
        Metadata of its runs.
    seed : int
        Seed of its wheels' out-of-roundness.
    wheel_diameter_m : float, optional
        True (and reported) diameter of all its wheels, m; None: the simulator's defaults
        (:data:`app.simulate.run.DEFAULT_TRUE_DIAMETERS_M`).
    unsprung_mass_factor : float
        Its unsprung mass against the line's reference vehicle (1.25: 25 % heavier): its
        sleeper-passage response and its response to the rail surface are those of that wheel
        on the same track (:class:`app.simulate.amplitude.ResonanceResponse` with the
        reference vehicle), its forces carry that mass.
    sensor_gain : float
        Its accelerometers' true gain against their calibration (1.15: they read 15 % high,
        and nothing in the file says so).
    """

    vehicle_id: str
    seed: int
    wheel_diameter_m: float | None = None
    unsprung_mass_factor: float = 1.0
    sensor_gain: float = 1.0

    def __post_init__(self) -> None:
        if self.wheel_diameter_m is not None and not (math.isfinite(self.wheel_diameter_m)
                                                      and 0.5 <= self.wheel_diameter_m <= 1.5):
            raise ValueError(f"wheel_diameter_m: must be in 0.5 … 1.5 m, got {self.wheel_diameter_m!r}")
        for name in ("unsprung_mass_factor", "sensor_gain"):
            v = getattr(self, name)
            if not (math.isfinite(v) and 0.2 <= v <= 5.0):
                raise ValueError(f"{name}: must be in 0.2 … 5, got {v!r}")

    def diameters(self) -> dict[str, float]:
        """True diameter per wheel, m."""
        if self.wheel_diameter_m is None:
            return dict(DEFAULT_TRUE_DIAMETERS_M)
        return {w: float(self.wheel_diameter_m) for w in DEFAULT_TRUE_DIAMETERS_M}

    def simulation_options(self) -> dict:
        """The :func:`app.simulate.run.simulate_run` options of this vehicle (besides its wheels)."""
        opts: dict = {"vehicle_id": self.vehicle_id}
        if self.unsprung_mass_factor != 1.0:
            base = TrackParameters()
            opts["amplitude_model"] = ResonanceResponse(
                track=base.replace(wheel_mass=base.wheel_mass * self.unsprung_mass_factor), reference_track=base)
            opts["unsprung_mass_kg"] = 300.0 * self.unsprung_mass_factor
        if self.sensor_gain != 1.0:
            opts["sensor_gain"] = float(self.sensor_gain)
        return opts


#: Types of the asset register rows a history can write (those of ``POST /assets``).
ASSET_TYPES = ("switch", "crossing", "bridge", "level_crossing", "insulated_joint", "weld", "other")


@dataclass(frozen=True)
class HistoryAsset:
    """A row of the line's asset register (``POST /assets``): a known discontinuity at ``track_m``."""

    type: str
    track_m: float
    name: str = ""

    def __post_init__(self) -> None:
        if self.type not in ASSET_TYPES:
            raise ValueError(f"type: must be one of {ASSET_TYPES}, got {self.type!r}")
        _finite("track_m", self.track_m)


@dataclass(frozen=True)
class TruthPlace:
    """What a planted feature should look like on a day (for scoring a work list).

    Attributes
    ----------
    kind : str
        ``"anomaly"`` (lasting, in the line from day 0), ``"change"``, ``"developing"`` or ``"tamping"``.
    track_from_m, track_to_m : float
        Extent, m.
    log_change : float
        ``ln`` of the amplitude factor on that day against the track before it (at the
        feature's core; for a tamping the mean over its extent against the day before).
    since_day : float
        Day it appeared.
    """

    kind: str
    track_from_m: float
    track_to_m: float
    log_change: float
    since_day: float

    @property
    def centre_m(self) -> float:
        """Centre of the extent, m."""
        return 0.5 * (self.track_from_m + self.track_to_m)


@dataclass(frozen=True)
class RailFeature:
    """A dipped weld or joint of the line (both rails at one position), the truth of a rail finding.

    Attributes
    ----------
    track_m : float
        Position, m on the km axis.
    kind : str
        ``"weld"`` or ``"joint"``.
    depth_m : dict of int to float
        Depth per rail side, m.
    length_m : float
        The longer of the two rails' dips, m.
    in_register : bool
        Whether the line's asset register holds it.
    """

    track_m: float
    kind: str
    depth_m: dict[int, float]
    length_m: float
    in_register: bool = False


@dataclass(frozen=True)
class HistorySpec:
    """A history: the line, what happens to it, the runs and how they are written.

    Attributes
    ----------
    line : LineModel
        The track on day 0 (must cover every run with its trailing axle and odometry error).
    runs : tuple of HistoryRun
        In date order.
    changes : tuple of TrackChange
        What happens to the track.
    km_start, length_km : float
        Where every run starts (the true position) and how long it is.
    start : datetime.datetime
        Day 0 (timezone-aware), the first run's time of day.
    line_id, track, vehicle_id : str
        Metadata of the runs.
    fs : float
        Sample rate, Hz.
    noise_std : float
        Broadband noise on the accelerations, m/s².
    v_start_kmh, v_end_kmh : float
        Speed at the start and at the end of every run (the ramps), km/h.
    ramp_in_m, ramp_out_m : float
        Lengths of the acceleration and braking ramps, m.
    vehicle_seed : int
        Seed of the vehicle's wheels (the same in every run).
    vehicles : tuple of HistoryVehicle
        The vehicles the runs name (:attr:`HistoryRun.vehicle`); empty: one vehicle,
        ``vehicle_id`` with the wheels of ``vehicle_seed``.
    assets : tuple of HistoryAsset
        The line's asset register (written as the assets CSV).
    record_grindings : bool
        Whether the line surface's grindings are maintenance records too (:meth:`maintenance`).
    """

    line: LineModel
    runs: tuple[HistoryRun, ...]
    changes: tuple[TrackChange, ...] = ()
    km_start: float = 12.0
    length_km: float = 2.4
    start: dt.datetime = dt.datetime(2025, 1, 6, 8, 0, tzinfo=dt.UTC)
    line_id: str = "HIST"
    track: str = "1"
    vehicle_id: str = "SIM-H"
    fs: float = 10_000.0
    noise_std: float = 2.0
    v_start_kmh: float = 65.0
    v_end_kmh: float = 60.0
    ramp_in_m: float = 500.0
    ramp_out_m: float = 400.0
    vehicle_seed: int = 1
    vehicles: tuple[HistoryVehicle, ...] = ()
    assets: tuple[HistoryAsset, ...] = ()
    record_grindings: bool = False

    def __post_init__(self) -> None:
        if not self.runs:
            raise ValueError("runs: at least one run is needed")
        days = [r.day for r in self.runs]
        if any(b < a for a, b in zip(days, days[1:], strict=False)):
            raise ValueError("runs: must be in date order")
        if self.start.tzinfo is None:
            raise ValueError("start: must be timezone-aware")
        if not (self.length_km > 0 and math.isfinite(self.length_km)):
            raise ValueError(f"length_km: must be > 0, got {self.length_km!r}")
        if self.ramp_in_m + self.ramp_out_m >= 1000.0 * self.length_km:
            raise ValueError("ramp_in_m + ramp_out_m: must be shorter than the run")
        for r in self.runs:
            if not r.cruise_kmh > 0:
                raise ValueError(f"runs: cruise_kmh must be > 0, got {r.cruise_kmh!r}")
            if not 0 <= r.vehicle < max(1, len(self.vehicles)):
                raise ValueError(f"runs: vehicle {r.vehicle!r} is not one of the spec's vehicles")

    # --- the vehicles --------------------------------------------------------------
    def vehicle_of(self, run: HistoryRun) -> HistoryVehicle:
        """The vehicle that made a run."""
        if not self.vehicles:
            return HistoryVehicle(self.vehicle_id, self.vehicle_seed)
        return self.vehicles[run.vehicle]

    # --- the track on a day ------------------------------------------------------
    def log_factor(self, day: float, x: np.ndarray) -> np.ndarray:
        """``ln f(x, day) − ln f0(x)``: what the changes did to the track at positions ``x`` (m) by ``day``."""
        x = np.asarray(x, dtype=np.float64)
        out = np.zeros(x.shape)
        ordered = sorted(self.changes, key=lambda c: c.day)
        for c in ordered:
            if day < c.day:
                continue
            w = c.weight(x)
            if c.kind == "tamping":
                out = out * (1.0 - w)  # the repair: what changed here before is gone
            out = out + w * c.log_effect(day)
        return out

    def line_at(self, day: float) -> LineModel:
        """The line model on ``day`` (the factor of both rails changed)."""
        lf = self.log_factor(day, self.line.centres())
        return replace(self.line, factor=self.line.factor * np.exp(lf)[None, :])

    def run_time(self, run: HistoryRun) -> dt.datetime:
        """Start time of a run."""
        return self.start + dt.timedelta(days=float(run.day))

    def speed_profile(self, run: HistoryRun) -> SpeedProfile:
        """The run's speed profile (:func:`ramp_profile`)."""
        return ramp_profile(1000.0 * self.length_km, self.v_start_kmh, run.cruise_kmh, self.v_end_kmh,
                            self.ramp_in_m, self.ramp_out_m)

    def maintenance(self) -> pd.DataFrame:
        """The tamping actions (and, with ``record_grindings``, the line surface's grindings) as
        maintenance records (the reference import's columns), by date."""
        rows = [{"line_id": self.line_id, "track": self.track, "km_from": c.track_from_m / 1000.0,
                 "km_to": c.track_to_m / 1000.0, "type": "tamping",
                 "date": (self.start + dt.timedelta(days=c.day)).date().isoformat()}
                for c in self.changes if c.kind == "tamping"]
        if self.record_grindings and self.line.surface is not None:
            rows += [{"line_id": self.line_id, "track": self.track, "km_from": g.track_from_m / 1000.0,
                      "km_to": g.track_to_m / 1000.0, "type": "grinding", "date": g.date}
                     for g in self.line.surface.grindings]
        rows.sort(key=lambda r: r["date"])
        return pd.DataFrame(rows, columns=["line_id", "track", "km_from", "km_to", "type", "date"])

    def grinding_days(self) -> list[float]:
        """Day of each grinding of the line surface (days from ``start``)."""
        if self.line.surface is None:
            return []
        return [(dt.datetime.combine(as_date(g.date), self.start.timetz()) - self.start).total_seconds() / 86400.0
                for g in self.line.surface.grindings]

    def asset_register(self) -> pd.DataFrame:
        """The asset register as the assets import reads it (``line_id,track,type,km,km_to,name``)."""
        return pd.DataFrame([{"line_id": self.line_id, "track": self.track, "type": a.type,
                              "km": a.track_m / 1000.0, "km_to": "", "name": a.name} for a in self.assets],
                            columns=["line_id", "track", "type", "km", "km_to", "name"])

    def superstructure(self) -> pd.DataFrame:
        """The line's sections as superstructure records."""
        return pd.DataFrame([
            {"line_id": self.line_id, "track": self.track, "km_from": s.km_from, "km_to": s.km_to,
             "type": s.type, "details": SUPERSTRUCTURE_LABELS.get(s.type, "")}
            for s in self.line.sections
        ], columns=["line_id", "track", "km_from", "km_to", "type", "details"])

    # --- truth ---------------------------------------------------------------------
    def truth_places(self, day: float) -> list[TruthPlace]:
        """The planted features present on ``day`` with their size (lasting anomalies, changes, tampings)."""
        out = [TruthPlace("anomaly", a.track_from_m, a.track_to_m, math.log(a.factor), 0.0)
               for a in self.line.anomalies]
        for c in self.changes:
            if day < c.day:
                continue
            core = np.array([0.5 * (c.track_from_m + c.track_to_m)])
            if c.kind == "tamping":
                eff = self.tamping_effect(c)
                out.append(TruthPlace("tamping", c.track_from_m, c.track_to_m, eff, c.day))
                continue
            now = float(self.log_factor(day, core)[0] - self.log_factor(c.day - 1e-6, core)[0])
            later = [t for t in self.changes if t.kind == "tamping" and c.day < t.day <= day
                     and t.track_from_m <= core[0] <= t.track_to_m]
            if later:  # repaired since
                continue
            out.append(TruthPlace(c.kind, c.track_from_m, c.track_to_m, now, c.day))
        return out

    def rail_features(self) -> list[RailFeature]:
        """The welds and joints of the line's rails over the runs' extent, one per position, by position."""
        if self.line.surface is None:
            return []
        x0 = 1000.0 * self.km_start
        groups: dict[tuple[float, str], list[TrackImpact]] = {}
        for imp in self.line.surface.impacts_between(x0 - 50.0, x0 + 1000.0 * self.length_km + 50.0):
            groups.setdefault((round(imp.track_m, 3), imp.kind), []).append(imp)
        reg = {"joint": "insulated_joint", "weld": "weld"}
        return [RailFeature(float(x), kind, {i.side: i.depth_m for i in imps}, max(i.length_m for i in imps),
                            any(a.type == reg[kind] and abs(a.track_m - x) <= 1.0 for a in self.assets))
                for (x, kind), imps in sorted(groups.items())]

    def ramps(self) -> tuple[float, float]:
        """Where the acceleration ramp ends and the braking ramp begins, m on the km axis."""
        x0 = 1000.0 * self.km_start
        return x0 + self.ramp_in_m, x0 + 1000.0 * self.length_km - self.ramp_out_m

    def tamping_effect(self, tamping: TrackChange, *, margin_m: float = 0.0) -> float:
        """True effect of a tamping: the median change of ``ln f`` over its extent on its day.

        Over ``[from + margin, to − margin]`` (25 cm grid), just after the action against
        just before: the typical track of the extent (a defect it repaired on a small part
        of it does not move the median); ``exp(·) − 1`` is the relative change a
        maintenance-effect report should give.
        """
        if tamping.kind != "tamping":
            raise ValueError("tamping: must be a change of kind 'tamping'")
        x = np.arange(tamping.track_from_m + margin_m, tamping.track_to_m - margin_m, self.line.bin_length)
        return float(np.median(self.log_factor(tamping.day, x) - self.log_factor(tamping.day - 1e-6, x)))

    def fingerprint(self) -> str:
        """Short hash of everything that goes into the files (file names change with it)."""
        doc = {
            "line": hashlib.sha256(np.ascontiguousarray(self.line.factor).tobytes()
                                   + self.line.type_code.tobytes()).hexdigest(),
            "first_bin": self.line.first_bin,
            "runs": [{k: v for k, v in asdict(r).items() if k != "vehicle"} for r in self.runs],
            "changes": [asdict(c) for c in self.changes],
            **{k: getattr(self, k) for k in ("km_start", "length_km", "line_id", "track", "vehicle_id", "fs",
                                             "noise_std", "v_start_kmh", "v_end_kmh", "ramp_in_m", "ramp_out_m",
                                             "vehicle_seed")},
            "start": self.start.isoformat(),
        }
        # what came with the vehicles, assets and recorded grindings; a history without them keeps the name it
        # had before them (the rails' surface included only then: roughness seed, welds, joints, grindings)
        if self.line.surface is not None and (self.vehicles or self.assets or self.record_grindings):
            surf = self.line.surface
            doc["surface"] = {"seed": surf.seed, "spectrum": None if surf.spectrum is None else asdict(surf.spectrum),
                              "impacts": [asdict(i) for i in surf.impacts],
                              "grindings": [asdict(g) for g in surf.grindings]}
        if self.vehicles:
            doc["vehicles"] = [asdict(v) for v in self.vehicles]
        if self.assets:
            doc["assets"] = [asdict(a) for a in self.assets]
        if self.record_grindings:
            doc["record_grindings"] = True
        if any(r.vehicle for r in self.runs):
            doc["run_vehicles"] = [r.vehicle for r in self.runs]
        return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()[:10]


@dataclass
class HistoryFiles:
    """Paths of a written history.

    Attributes
    ----------
    directory : Path
    runs : list of Path
        Run files in the order of :attr:`HistorySpec.runs`.
    superstructure, maintenance : Path
        Reference CSV files (the maintenance file may hold no rows).
    assets : Path or None
        The asset register (CSV of ``POST /assets``), where the history has one.
    written : list of Path
        Files made by this call (the others existed).
    """

    directory: Path
    runs: list[Path] = field(default_factory=list)
    superstructure: Path | None = None
    maintenance: Path | None = None
    assets: Path | None = None
    written: list[Path] = field(default_factory=list)


def ramp_profile(length_m: float, v_start_kmh: float, cruise_kmh: float, v_end_kmh: float,
                 ramp_in_m: float, ramp_out_m: float) -> SpeedProfile:
    """Speed profile of a run from a station to a station: accelerate, cruise, brake.

    Parameters
    ----------
    length_m : float
        Distance of the run, m (> 0); the profile reaches ``v_end`` at it and stays there.
    v_start_kmh, cruise_kmh, v_end_kmh : float
        Start, cruise and end speed, km/h (> 0).
    ramp_in_m, ramp_out_m : float
        Distance of the acceleration and the braking ramp, m (≥ 0, together shorter than the run).

    Returns
    -------
    SpeedProfile
        Raised-cosine ramps (:mod:`app.simulate.speed`); a ramp over ``d`` metres from
        ``v0`` to ``v1`` lasts ``2 d / (v0 + v1)`` seconds.
    """
    for name, v in (("v_start_kmh", v_start_kmh), ("cruise_kmh", cruise_kmh), ("v_end_kmh", v_end_kmh),
                    ("length_m", length_m)):
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"{name}: must be a finite number > 0, got {v!r}")
    for name, d in (("ramp_in_m", ramp_in_m), ("ramp_out_m", ramp_out_m)):
        if not (math.isfinite(d) and d >= 0):
            raise ValueError(f"{name}: must be >= 0, got {d!r}")
    if ramp_in_m + ramp_out_m >= length_m:
        raise ValueError("ramp_in_m + ramp_out_m: must be shorter than length_m")
    v0, vc, v1 = v_start_kmh * _KMH, cruise_kmh * _KMH, v_end_kmh * _KMH
    segs: list[tuple[float, float]] = []
    if ramp_in_m > 0:
        segs.append((2.0 * ramp_in_m / (v0 + vc), vc))
    segs.append(((length_m - ramp_in_m - ramp_out_m) / vc, vc))
    if ramp_out_m > 0:
        segs.append((2.0 * ramp_out_m / (vc + v1), v1))
    return SpeedProfile.from_segments(v0 if ramp_in_m > 0 else vc, segs)


def _history_line(seed: int, km_start: float, length_km: float, *, sections: Sequence[TrackSection] | None,
                  anomalies: Sequence[StiffnessAnomaly], variation_std: float = 0.08) -> LineModel:
    start = 1000.0 * km_start
    return generate_line(start - 150.0, start + 1000.0 * length_km + 150.0, np.random.default_rng([seed, 11]),
                         sections=sections, anomalies=anomalies, variation_std=variation_std)


def _runs(seed: int, n_runs: int, every_days: float, cruise_kmh: float, cruise_spread: float,
          km_error_sd_m: float) -> tuple[HistoryRun, ...]:
    if n_runs < 1:
        raise ValueError(f"n_runs: must be >= 1, got {n_runs!r}")
    if not every_days > 0:
        raise ValueError(f"every_days: must be > 0, got {every_days!r}")
    if not 0 <= cruise_spread < 0.5:
        raise ValueError(f"cruise_spread: must be in [0, 0.5), got {cruise_spread!r}")
    rng = np.random.default_rng([seed, 13])
    # the cruise speeds are spread evenly over ±cruise_spread (shuffled): every history spans the range
    factors = 1.0 + cruise_spread * (np.linspace(-1.0, 1.0, n_runs) if n_runs > 1 else np.zeros(1))
    rng.shuffle(factors)
    errors = np.clip(rng.normal(0.0, km_error_sd_m, n_runs), -3 * km_error_sd_m, 3 * km_error_sd_m)
    errors[0] = 0.0  # the first run is the store's alignment reference: its km axis is the line's
    return tuple(HistoryRun(day=i * every_days, cruise_kmh=float(cruise_kmh * factors[i]),
                            km_error_m=float(round(errors[i], 2)), seed=int(seed * 1000 + i))
                 for i in range(n_runs))


def planted_history(*, seed: int = 0, n_runs: int = 12, every_days: float = 14.0, length_km: float = 2.4,
                    km_start: float = 12.0, cruise_kmh: float = 120.0, cruise_spread: float = 0.10,
                    km_error_sd_m: float = 5.0, fs: float = 10_000.0, line_id: str = "HIST",
                    track: str = "1") -> HistorySpec:
    """A history with known places: what the work list should find.

    On a line of three superstructure sections (slab, B91 without pads, B91 with pads):

    * a lasting soft spot (amplitude ×0.6 over 30 m) and a lasting hard spot (×1.6 over 30 m);
    * two new changes after half of the history: −20 % and +25 % over 20 m;
    * a developing place (+25 %/year·… over 40 m, from the start) that a tamping over
      200 m around it repairs three quarters through (effect ×0.8, settling back 10 %/year);
    * cruise speeds spread evenly over ``cruise_kmh`` ±``cruise_spread``, ramps from
      65 km/h over the first 500 m and to 60 km/h over the last 400 m, start odometry
      errors N(0, ``km_error_sd_m``).

    Parameters
    ----------
    seed : int
        Seed of the line's natural variation, the run order and the noise.
    n_runs, every_days : int, float
        Runs and the days between them.
    length_km, km_start : float
        Length and start of the runs, km.
    cruise_kmh, cruise_spread : float
        Cruise speed, km/h, and its relative spread over the runs.
    km_error_sd_m : float
        Standard deviation of the start odometry errors, m.
    fs : float
        Sample rate, Hz.
    line_id, track : str
        Metadata.

    Returns
    -------
    HistorySpec
    """
    if not length_km >= 2.0:
        raise ValueError(f"length_km: the planted history needs >= 2 km, got {length_km!r}")
    x0 = 1000.0 * km_start
    L = 1000.0 * length_km
    # sections: the ramps run over slab, the middle is B91 without pads, the end B91 with pads
    b1, b2 = x0 + 0.35 * L, x0 + 0.7 * L
    sections = (TrackSection(x0 - 150.0, b1, "slab"), TrackSection(b1, b2, "b91_no_pads"),
                TrackSection(b2, x0 + L + 150.0, "b91_pads"))
    anomalies = (StiffnessAnomaly(x0 + 0.46 * L, x0 + 0.46 * L + 30.0, 0.6, 8.0, "soft spot"),
                 StiffnessAnomaly(x0 + 0.80 * L, x0 + 0.80 * L + 30.0, 1.6, 8.0, "hard spot"))
    line = _history_line(seed, km_start, length_km, sections=sections, anomalies=anomalies)
    span = (n_runs - 1) * every_days
    t_new = round(0.55 * span / every_days) * every_days - every_days / 2  # between two runs
    t_tamp = round(0.75 * span / every_days) * every_days - every_days / 2
    dev = x0 + 0.58 * L
    changes = (
        TrackChange("change", x0 + 0.40 * L + 3.0, x0 + 0.40 * L + 23.0, t_new, 0.8, taper_m=2.0),
        TrackChange("change", x0 + 0.75 * L + 6.0, x0 + 0.75 * L + 26.0, t_new, 1.25, taper_m=2.0),
        TrackChange("developing", dev, dev + 40.0, -every_days, 1.0, rate_per_year=1.2, taper_m=8.0),
        TrackChange("tamping", dev - 80.0, dev + 120.0, t_tamp, 0.8, rate_per_year=0.1, taper_m=10.0),
    )
    runs = _runs(seed, n_runs, every_days, cruise_kmh, cruise_spread, km_error_sd_m)
    return HistorySpec(line=line, runs=runs, changes=changes, km_start=km_start, length_km=length_km,
                       line_id=line_id, track=track, fs=fs, vehicle_seed=seed + 1)


def uniform_history(*, seed: int = 0, n_runs: int = 12, every_days: float = 14.0, length_km: float = 2.4,
                    km_start: float = 12.0, cruise_kmh: float = 120.0, cruise_spread: float = 0.10,
                    km_error_sd_m: float = 5.0, fs: float = 10_000.0, superstructure: str = "b91_no_pads",
                    line_id: str = "UNIF", track: str = "1") -> HistorySpec:
    """A uniform line passed with speed ramps: one superstructure type, nothing planted, nothing changing.

    The line keeps the simulator's mild natural stiffness variation (8 %, correlated over
    20 m): real track is never perfectly uniform. Parameters as :func:`planted_history`;
    ``superstructure`` is the one type.
    """
    if superstructure not in SUPERSTRUCTURE_TYPES:
        raise ValueError(f"superstructure: must be one of {SUPERSTRUCTURE_TYPES}, got {superstructure!r}")
    x0 = 1000.0 * km_start
    sections = (TrackSection(x0 - 150.0, x0 + 1000.0 * length_km + 150.0, superstructure),)
    line = _history_line(seed, km_start, length_km, sections=sections, anomalies=())
    runs = _runs(seed, n_runs, every_days, cruise_kmh, cruise_spread, km_error_sd_m)
    return HistorySpec(line=line, runs=runs, km_start=km_start, length_km=length_km, line_id=line_id,
                       track=track, fs=fs, vehicle_seed=seed + 1)


def grinding_history(*, seed: int = 21, n_runs: int = 10, every_days: float = 7.0, length_km: float = 1.2,
                     km_start: float = 12.0, cruise_kmh: float = 126.0, start: dt.datetime | None = None,
                     line_id: str = "ROUGH", track: str = "1") -> tuple[HistorySpec, dict]:
    """A rough line ground between its last two runs, with a real support change beside the grinding.

    One superstructure type (B91 without pads), random rail roughness fixed to the track (Sato, good
    rail; no welds), all runs at one speed (``cruise_kmh``; the ramps are flat). Between the last two
    runs a grinding over 200 m (from 0.33 of the run's length: the rails' roughness there is replaced by
    a new, smoother one) and a −30 % support change over 20 m (from 0.71 of the length): the first must
    not read as a stiffness change where it is recorded, the second must. The grinding is **not** in
    :meth:`HistorySpec.maintenance` (only tampings are): the caller records it or not
    (``info["maintenance"]``, the record as the reference import's row).

    Returns
    -------
    spec : HistorySpec
    info : dict
        ``ground`` and ``soft`` extents (m), ``grind_day`` (days from the start), ``maintenance`` (a row).
    """
    if n_runs < 2:
        raise ValueError(f"n_runs: must be >= 2, got {n_runs!r}")
    start = start or dt.datetime(2025, 4, 7, 8, 0, tzinfo=dt.UTC)
    x0, length = 1000.0 * km_start, 1000.0 * length_km
    lo, hi = x0 - 150.0, x0 + length + 150.0
    ground = (x0 + round(0.33 * length, -1), x0 + round(0.33 * length, -1) + 200.0)
    soft = (x0 + round(0.71 * length, -1), x0 + round(0.71 * length, -1) + 20.0)
    grind_day = (n_runs - 2) * every_days + every_days / 2
    date = (start + dt.timedelta(days=grind_day)).date().isoformat()
    surface = generate_surface(lo, hi, seed, weld_spacing_m=None).with_grindings([RailGrinding(*ground, date)])
    line = generate_line(lo, hi, np.random.default_rng([seed, 7]), sections=(TrackSection(lo, hi, "b91_no_pads"),),
                         anomalies=(), surface=surface)
    runs = tuple(HistoryRun(day=i * every_days, cruise_kmh=cruise_kmh, km_error_m=0.0, seed=seed * 100 + i)
                 for i in range(n_runs))
    spec = HistorySpec(line=line, runs=runs, changes=(TrackChange("change", *soft, grind_day, 0.7, taper_m=2.0),),
                       km_start=km_start, length_km=length_km, start=start, line_id=line_id, track=track,
                       v_start_kmh=cruise_kmh, v_end_kmh=cruise_kmh, ramp_in_m=50.0, ramp_out_m=50.0,
                       vehicle_seed=seed + 1)
    record = {"line_id": line_id, "track": track, "km_from": ground[0] / 1000.0, "km_to": ground[1] / 1000.0,
              "type": "grinding", "date": date}
    return spec, {"ground": ground, "soft": soft, "grind_day": grind_day, "maintenance": record}


#: The real line's cruise speeds, m/s (two speed groups: regional and fast trains).
REAL_LINE_SPEEDS_MPS: tuple[float, float] = (26.0, 40.0)


def real_line_history(*, seed: int = 0, n_runs: int = 24, every_days: float = 15.0, length_km: float = 3.0,
                      km_start: float = 12.0, km_error_sd_m: float = 5.0, fs: float = 10_000.0,
                      line_id: str = "REAL", track: str = "1") -> HistorySpec:
    """A line like a real one: every confounder of the work list at once, with its truth (issue 33).

    On ``length_km`` (3 km) of track passed ``n_runs`` times (24, every 15 days: a year):

    * **four superstructure classes** along the line: slab (the first fifth, under the
      acceleration ramp), B91 without pads, timber sleepers, B91 with pads;
    * **both rails rough**, independently (Sato's short-wave ``k⁻³`` spectrum, good rail), with
      **dipped welds** every 60–120 m (0.2–0.4 mm over 0.8–1.2 m, each rail its own; not in the
      asset register) and **two insulated joints** (0.4 m, 0.6 mm, both rails) that the asset
      register holds (``insulated_joint``);
    * **two speed groups**: cruise 26 and 40 m/s (±3 %), two runs of each in every four, with
      ramps at both ends (60 km/h to cruise over the first 500 m, cruise to 55 km/h over the
      last 400 m; shorter on a shorter line);
    * **two vehicles**: every third run (one in each three, drawn) by the second one, with 25 %
      more unsprung mass, 0.86 m wheels and accelerometers reading 15 % high; the first run is
      the first vehicle's (the store's alignment reference);
    * **maintenance**: a tamping over 200 m (×0.8, settling back 10 %/year) at 0.23–0.30 of the
      line, after 30 % of the runs (beside the ramp's end and a change of class), and a grinding
      of both rails over 500 m (a sixth of the line) from the middle, after 62 % of the runs
      (the rails' roughness there ×0.3 from then on; the support unchanged); both recorded;
    * **support changes**: a lasting soft spot (×0.6 over 30 m), a place developing softer over
      the last ten runs (−1.1 ln units a year over 40 m: −35 % by the newest run) and a new
      −20 % step over 20 m in the newest run;
    * start odometry errors N(0, ``km_error_sd_m``) (none in the first run).

    The truth: :meth:`HistorySpec.truth_places` (support changes), :meth:`HistorySpec.rail_features`
    (welds, joints), :meth:`HistorySpec.maintenance` (actions), :meth:`HistorySpec.speed_group`.
    Features are placed at fixed fractions of the line, so a shorter line (≥ 1.2 km) keeps them all.
    """
    if not length_km >= 1.2:
        raise ValueError(f"length_km: the real line needs >= 1.2 km, got {length_km!r}")
    if n_runs < 6:
        raise ValueError(f"n_runs: the real line needs >= 6 runs, got {n_runs!r}")
    if not every_days > 0:
        raise ValueError(f"every_days: must be > 0, got {every_days!r}")
    x0, L = 1000.0 * km_start, 1000.0 * length_km
    lo, hi = x0 - 150.0, x0 + L + 150.0
    rng = np.random.default_rng([seed, 33])
    sections = (TrackSection(lo, x0 + 0.2 * L, "slab"), TrackSection(x0 + 0.2 * L, x0 + 0.47 * L, "b91_no_pads"),
                TrackSection(x0 + 0.47 * L, x0 + 0.7 * L, "timber"), TrackSection(x0 + 0.7 * L, hi, "b91_pads"))
    soft = StiffnessAnomaly(x0 + 0.38 * L, x0 + 0.38 * L + 30.0, 0.6, 8.0, "soft spot")
    start = dt.datetime(2025, 1, 6, 8, 0, tzinfo=dt.UTC)
    between = lambda k: (k - 0.5) * every_days  # noqa: E731 - the day half way before run k
    grind_day = between(round(0.62 * n_runs))
    ground = (x0 + round(0.5 * L, -1), x0 + round(0.5 * L, -1) + round(L / 6.0, -1))
    joints = tuple(TrackImpact(x0 + f * L, 0.4, 0.6e-3, side, "joint") for f in (0.31, 0.75) for side in (1, 2))
    surface = generate_surface(lo, hi, np.random.default_rng([seed, 34]), weld_spacing_m=(60.0, 120.0))
    surface = replace(surface, impacts=(*surface.impacts, *joints)).with_grindings(
        [RailGrinding(*ground, (start + dt.timedelta(days=grind_day)).date().isoformat())])
    line = generate_line(lo, hi, np.random.default_rng([seed, 11]), sections=sections, anomalies=(soft,),
                         surface=surface)
    n_dev = min(10, n_runs - 3)
    dev, step, tamp = x0 + round(0.8 * L, -1), x0 + round(0.433 * L, -1), x0 + round(0.233 * L, -1)
    changes = (
        TrackChange("tamping", tamp, tamp + 200.0, between(round(0.3 * n_runs)), 0.8, rate_per_year=0.1,
                    taper_m=10.0),
        TrackChange("developing", dev, dev + 40.0, between(n_runs - n_dev), 1.0, rate_per_year=-1.1, taper_m=8.0),
        TrackChange("change", step, step + 20.0, between(n_runs - 1), 0.8, taper_m=2.0),
    )
    # speed groups: two runs of each in every four; vehicles: one run in every three by the second
    group = np.concatenate([rng.permutation([0, 0, 1, 1]) for _ in range((n_runs + 3) // 4)])[:n_runs]
    vehicle = np.zeros(n_runs, dtype=np.int64)
    for b in range(0, n_runs, 3):
        vehicle[b + int(rng.integers(0, min(3, n_runs - b)))] = 1
    vehicle[0] = 0
    cruise = np.array(REAL_LINE_SPEEDS_MPS)[group] * KMH_PER_MPS * (1.0 + rng.uniform(-0.03, 0.03, n_runs))
    errors = np.clip(rng.normal(0.0, km_error_sd_m, n_runs), -3 * km_error_sd_m, 3 * km_error_sd_m)
    errors[0] = 0.0
    runs = tuple(HistoryRun(day=i * every_days, cruise_kmh=float(round(cruise[i], 2)),
                            km_error_m=float(round(errors[i], 2)), seed=int(seed * 1000 + i), vehicle=int(vehicle[i]))
                 for i in range(n_runs))
    vehicles = (HistoryVehicle(f"{line_id}-V1", seed + 1),
                HistoryVehicle(f"{line_id}-V2", seed + 2, wheel_diameter_m=0.86, unsprung_mass_factor=1.25,
                               sensor_gain=1.15))
    assets = tuple(HistoryAsset("insulated_joint", x0 + f * L, f"IJ {i + 1}") for i, f in enumerate((0.31, 0.75)))
    return HistorySpec(line=line, runs=runs, changes=changes, km_start=km_start, length_km=length_km, start=start,
                       line_id=line_id, track=track, fs=fs, v_start_kmh=60.0, v_end_kmh=55.0,
                       ramp_in_m=min(500.0, L / 6.0), ramp_out_m=min(400.0, L / 7.5), vehicle_seed=seed + 1,
                       vehicles=vehicles, assets=assets, record_grindings=True)


def demo_history(line: LineModel, *, km_start: float, length_km: float, n_runs: int = 10,
                 every_days: float = 14.0, start: dt.datetime = dt.datetime(2025, 3, 3, 8, 0, tzinfo=dt.UTC),
                 line_id: str = "SIM", track: str = "1", vehicle_id: str = "SIM-1", fs: float = 10_000.0,
                 seed: int = 7) -> HistorySpec:
    """A short history of the demo's line: something for every part of the Condition page.

    On ``line`` (the demo's line model, with its lasting anomalies): a place developing softer
    (−1 ln unit a year) from the start, a place developing harder (+1.2 a year, since 90 days before
    the first run: on the work list from the first runs, crossing a tier before the work) that a
    tamping over 200 m around it repairs two thirds through (×0.85, maintenance record written), and a new
    change of −20 % over 20 m half way; cruise speeds over 100 km/h ± 10 % with ramps at both ends,
    start odometry errors N(0, 4 m). Positions are chosen at fixed fractions of the run so any
    demo length ≥ 2 km works.
    """
    if not length_km >= 2.0:
        raise ValueError(f"length_km: the demo history needs >= 2 km, got {length_km!r}")
    x0, L = 1000.0 * km_start, 1000.0 * length_km
    span = (n_runs - 1) * every_days
    half = round(0.5 * span / every_days) * every_days - every_days / 2
    t_tamp = round(0.65 * span / every_days) * every_days - every_days / 2
    soft, hard = x0 + 0.55 * L, x0 + 0.85 * L
    changes = (
        TrackChange("developing", soft, soft + 40.0, -every_days, 1.0, rate_per_year=-1.0, taper_m=8.0),
        TrackChange("developing", hard, hard + 40.0, -90.0, 1.0, rate_per_year=1.2, taper_m=8.0),
        TrackChange("tamping", hard - 80.0, hard + 120.0, t_tamp, 0.85, rate_per_year=0.1, taper_m=10.0),
        TrackChange("change", x0 + 0.35 * L + 4.0, x0 + 0.35 * L + 24.0, half, 0.8, taper_m=2.0),
    )
    runs = _runs(seed, n_runs, every_days, 100.0, 0.10, 4.0)
    return HistorySpec(line=line, runs=runs, changes=changes, km_start=km_start, length_km=length_km,
                       start=start, line_id=line_id, track=track, vehicle_id=vehicle_id, fs=fs,
                       v_start_kmh=50.0, v_end_kmh=45.0, ramp_in_m=400.0, ramp_out_m=300.0, vehicle_seed=seed)


def write_history(spec: HistorySpec, directory: Path | str) -> HistoryFiles:
    """Write the history's run files (and truths) and its reference CSVs (missing files only).

    Parameters
    ----------
    spec : HistorySpec
    directory : Path or str
        Where the files go (created). Names carry :meth:`HistorySpec.fingerprint`,
        so another history never reuses these files.

    Returns
    -------
    HistoryFiles
    """
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    tag = spec.fingerprint()
    files = HistoryFiles(directory=out)
    wheels_of: dict[int, dict] = {}
    for i, run in enumerate(spec.runs):
        when = spec.run_time(run)
        path = out / f"{spec.line_id}-{spec.track}-{tag}-{i:03d}-{when:%Y%m%d}.h5"
        files.runs.append(path)
        if path.is_file():
            continue
        vehicle = spec.vehicle_of(run)
        if run.vehicle not in wheels_of:  # the vehicle's wheels: the same in every run it makes
            rng = np.random.default_rng([vehicle.seed, 3])
            wheels_of[run.vehicle] = {w: random_wheel_oor(rng, w, d) for w, d in vehicle.diameters().items()}
        simulate_run(path, length_km=spec.length_km, fs=spec.fs, seed=run.seed, line=spec.line_at(run.day),
                     wheels=wheels_of[run.vehicle], speed_profile=spec.speed_profile(run), noise_std=spec.noise_std,
                     start_time=when.isoformat(), line_id=spec.line_id, track=spec.track, km_start=spec.km_start,
                     km_error_m=run.km_error_m, with_forces=True, **vehicle.simulation_options())
        files.written.append(path)
    frames = [("superstructure", spec.superstructure()), ("maintenance", spec.maintenance())]
    if spec.assets:
        frames.append(("assets", spec.asset_register()))
    for name, frame in frames:
        path = out / f"{spec.line_id}-{spec.track}-{tag}-{name}.csv"
        setattr(files, name, path)
        if not path.is_file():
            frame.to_csv(path, index=False, float_format="%.10g")
            files.written.append(path)
    return files
