"""Reference data matching a simulated line, with known relations (ground truth).

Given a :class:`~app.simulate.track.LineModel`, :func:`simulate_reference`
writes the three reference files an asset manager would import:

``subsidence.<ext>``
    line_id, track, km, rail, subsidence_mm, date: one value per 25 cm bin
    centre and rail (1 = right, 2 = left, the wheel side),
    ``u = a ln(Z_ref) + b + N(0, sigma)`` where ``Z_ref`` is the rail's
    sleeper-passage acceleration amplitude at the simulator's ``v_ref``
    (m/s², natural log). A wheel passing at constant speed ``v`` therefore
    sees ``u = a ln Z + b_v`` with ``b_v = b - a alpha ln(v / v_ref)``
    (:meth:`ReferenceTruth.subsidence_fit_at`).
``maintenance.<ext>``
    line_id, track, km_from, km_to, type, date: per year and type, each block
    of ``block_m`` (default 50 m) is maintained with probability
    ``p_type (Zbar_block / z0) ** gamma`` (capped at 1), ``Zbar_block`` the
    block's mean sleeper-passage amplitude at ``v_ref`` over both rails; adjacent blocks of one year and type form one
    action. Stiff track (high amplitude) is maintained more often, as in the
    paper (Fig. 6). :meth:`ReferenceTruth.expected_actions` gives the
    expected count at any position.
``superstructure.<ext>``
    line_id, track, km_from, km_to, type, details: the line's sections.

A ``reference-truth.json`` beside them records the parameters.
"""

from __future__ import annotations

import datetime as dt
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
import pandas as pd

from app.simulate.track import SUPERSTRUCTURE_LABELS, LineModel

__all__ = ["ReferenceTruth", "simulate_reference", "MAINTENANCE_RATES"]

#: Probability per year that a block of track at ``z0`` is maintained, per type.
MAINTENANCE_RATES: dict[str, float] = {
    "tamping": 0.08,
    "grinding": 0.05,
    "rail_replacement": 0.01,
    "ballast_cleaning": 0.01,
    "other": 0.01,
}


@dataclass(frozen=True)
class ReferenceTruth:
    """Parameters of the simulated reference data (units in the names).

    Attributes
    ----------
    line_id, track : str
        Where the data belong.
    subsidence_slope_mm, subsidence_intercept_mm : float
        ``a`` (mm per unit of natural log of m/s²) and ``b`` (mm) of
        ``u = a ln(Z_ref) + b`` per rail.
    subsidence_noise_mm : float
        Standard deviation of the white measurement noise on ``u``, mm.
    subsidence_date : str
        Date of the subsidence measurement (ISO).
    maintenance_rates : dict
        ``p_type`` per type and year at ``z0``.
    maintenance_exponent : float
        ``gamma``.
    maintenance_z0_mps2 : float
        ``z0``, m/s².
    maintenance_block_m : float
        Block length, m.
    maintenance_years : tuple of int
        First and last year with actions.
    files : dict
        Paths of the written files by kind (and ``truth``).
    """

    line_id: str
    track: str
    subsidence_slope_mm: float
    subsidence_intercept_mm: float
    subsidence_noise_mm: float
    subsidence_date: str
    maintenance_rates: dict[str, float]
    maintenance_exponent: float
    maintenance_z0_mps2: float
    maintenance_block_m: float
    maintenance_years: tuple[int, int]
    files: dict[str, str] = field(default_factory=dict)
    block_start_m: float = 0.0
    block_amplitude_mps2: tuple[float, ...] = ()

    def subsidence_fit_at(self, speed_mps: float, alpha: float, v_ref_mps: float) -> tuple[float, float]:
        """``(a, b_v)`` of ``u = a ln Z + b_v`` for a wheel passing at constant speed (m/s).

        Parameters
        ----------
        speed_mps : float
            The run's constant speed, m/s.
        alpha, v_ref_mps : float
            The simulator's speed law ``(v / v_ref) ** alpha`` (truth of the run).
        """
        a, b = self.subsidence_slope_mm, self.subsidence_intercept_mm
        return a, b - a * alpha * float(np.log(speed_mps / v_ref_mps))

    def block_probability(self, kind: str) -> np.ndarray:
        """Yearly probability of an action of ``kind`` per block."""
        z = np.asarray(self.block_amplitude_mps2)
        p = self.maintenance_rates[kind] * (z / self.maintenance_z0_mps2) ** self.maintenance_exponent
        return np.minimum(p, 1.0)

    def expected_actions(self, track_m: np.ndarray, kinds: tuple[str, ...] | None = None,
                         since_year: int | None = None) -> np.ndarray:
        """Expected number of actions covering positions ``track_m`` (m), all years from ``since_year``."""
        x = np.asarray(track_m, dtype=np.float64)
        j = np.floor((x - self.block_start_m) / self.maintenance_block_m).astype(np.int64)
        j = np.clip(j, 0, len(self.block_amplitude_mps2) - 1)
        y0, y1 = self.maintenance_years
        years = y1 - max(y0, since_year or y0) + 1
        total = np.zeros(x.shape)
        for kind in kinds or tuple(self.maintenance_rates):
            total += max(years, 0) * self.block_probability(kind)[j]
        return total


def simulate_reference(
    line: LineModel,
    out_dir: Path | str,
    *,
    line_id: str = "SIM",
    track: str = "1",
    seed: int = 0,
    fmt: Literal["csv", "parquet"] = "csv",
    subsidence_slope_mm: float = 0.30,
    subsidence_intercept_mm: float = -1.65,
    subsidence_noise_mm: float = 0.05,
    subsidence_date: str = "2016-06-01",
    subsidence_range_m: tuple[float, float] | None = None,
    maintenance_rates: dict[str, float] | None = None,
    maintenance_exponent: float = 2.0,
    maintenance_z0_mps2: float = 1.5,
    maintenance_block_m: float = 50.0,
    maintenance_years: tuple[int, int] = (2006, 2023),
) -> ReferenceTruth:
    """Write subsidence, maintenance and superstructure files for ``line``.

    Parameters
    ----------
    line : LineModel
        The simulated line (e.g. ``truth.line`` of a run).
    out_dir : Path or str
        Directory to write into (created).
    line_id, track : str
        Written in every row (match the runs' metadata).
    seed : int
        Seed of the noise and of the maintenance draws.
    fmt : {"csv", "parquet"}
        File format.
    subsidence_slope_mm, subsidence_intercept_mm : float
        ``a`` (mm) and ``b`` (mm) of ``u = a ln(Z_ref) + b`` per rail.
    subsidence_noise_mm : float
        Measurement noise, mm (>= 0).
    subsidence_date : str
        ISO date of the subsidence measurement.
    subsidence_range_m : (float, float), optional
        Positions (m on the km axis) measured; default the whole line.
    maintenance_rates : dict, optional
        Yearly probability per type at ``z0`` (default :data:`MAINTENANCE_RATES`).
    maintenance_exponent : float
        ``gamma`` of ``(Zbar / z0) ** gamma``.
    maintenance_z0_mps2 : float
        ``z0``, m/s² (> 0).
    maintenance_block_m : float
        Block length, m (> 0).
    maintenance_years : (int, int)
        First and last year (inclusive).

    Returns
    -------
    ReferenceTruth
    """
    if fmt not in ("csv", "parquet"):
        raise ValueError(f"fmt: must be 'csv' or 'parquet', got {fmt!r}")
    if not subsidence_noise_mm >= 0:
        raise ValueError(f"subsidence_noise_mm: must be >= 0, got {subsidence_noise_mm!r}")
    if not (maintenance_z0_mps2 > 0 and maintenance_block_m > 0):
        raise ValueError("maintenance_z0_mps2, maintenance_block_m: must be > 0")
    if maintenance_years[0] > maintenance_years[1]:
        raise ValueError(f"maintenance_years: first after last: {maintenance_years!r}")
    dt.date.fromisoformat(subsidence_date)
    rates = dict(MAINTENANCE_RATES if maintenance_rates is None else maintenance_rates)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng([int(seed), 11])
    centres = line.centres()
    zbar = 0.5 * (line.amplitude_grid(1) + line.amplitude_grid(2))

    # subsidence per bin centre and rail
    keep = np.ones(centres.size, dtype=bool)
    if subsidence_range_m is not None:
        keep = (centres >= subsidence_range_m[0]) & (centres <= subsidence_range_m[1])
    parts = []
    for rail in (1, 2):
        u = subsidence_slope_mm * np.log(line.amplitude_grid(rail)[keep]) + subsidence_intercept_mm
        u = u + subsidence_noise_mm * rng.standard_normal(u.size)
        parts.append(pd.DataFrame({"line_id": line_id, "track": track, "km": centres[keep] / 1000.0,
                                   "rail": rail, "subsidence_mm": u, "date": subsidence_date}))
    sub = pd.concat(parts, ignore_index=True).sort_values(["km", "rail"], kind="stable")

    # maintenance per block, year and type
    x0 = line.track_from_m
    nblk = int(np.ceil((line.track_to_m - x0) / maintenance_block_m))
    blk = np.minimum(((centres - x0) // maintenance_block_m).astype(np.int64), nblk - 1)
    zblk = np.bincount(blk, weights=zbar, minlength=nblk) / np.maximum(np.bincount(blk, minlength=nblk), 1)
    truth = ReferenceTruth(
        line_id=line_id, track=track,
        subsidence_slope_mm=float(subsidence_slope_mm),
        subsidence_intercept_mm=float(subsidence_intercept_mm),
        subsidence_noise_mm=float(subsidence_noise_mm), subsidence_date=subsidence_date,
        maintenance_rates=rates, maintenance_exponent=float(maintenance_exponent),
        maintenance_z0_mps2=float(maintenance_z0_mps2), maintenance_block_m=float(maintenance_block_m),
        maintenance_years=(int(maintenance_years[0]), int(maintenance_years[1])),
        block_start_m=float(x0), block_amplitude_mps2=tuple(float(z) for z in zblk),
    )
    rows = []
    for year in range(maintenance_years[0], maintenance_years[1] + 1):
        for kind in rates:
            hit = rng.random(nblk) < truth.block_probability(kind)
            day = dt.date(year, 1, 1) + dt.timedelta(days=int(rng.integers(0, 365)))
            j = 0
            while j < nblk:
                if not hit[j]:
                    j += 1
                    continue
                k = j
                while k + 1 < nblk and hit[k + 1]:
                    k += 1
                a = x0 + j * maintenance_block_m
                b = min(x0 + (k + 1) * maintenance_block_m, line.track_to_m)
                rows.append({"line_id": line_id, "track": track, "km_from": a / 1000.0,
                             "km_to": b / 1000.0, "type": kind, "date": day.isoformat()})
                j = k + 1
    maint = pd.DataFrame(rows, columns=["line_id", "track", "km_from", "km_to", "type", "date"])
    sup = pd.DataFrame([
        {"line_id": line_id, "track": track, "km_from": s.km_from, "km_to": s.km_to,
         "type": s.type, "details": SUPERSTRUCTURE_LABELS.get(s.type, "")}
        for s in line.sections
    ])
    files = {}
    for kind, df in (("subsidence", sub), ("maintenance", maint), ("superstructure", sup)):
        path = out / f"{kind}.{fmt}"
        if fmt == "csv":
            df.to_csv(path, index=False, float_format="%.10g")
        else:
            df.to_parquet(path, index=False)
        files[kind] = str(path)
    files["truth"] = str(out / "reference-truth.json")
    truth = ReferenceTruth(**{**asdict(truth), "files": files,
                              "maintenance_years": truth.maintenance_years,
                              "block_amplitude_mps2": truth.block_amplitude_mps2})
    Path(files["truth"]).write_text(json.dumps(asdict(truth), indent=1))
    return truth
