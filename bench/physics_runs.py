"""Canonical run files built from the physics reference runs (../shared/physics), for benches and tests.

The physics files are short uniform-track records (14.4 m, 0.3–0.9 s) from an independent
vehicle–track model. :func:`steady_unit` cuts the steady part (the last ``n_bays_steady`` whole
sleeper bays of cases.csv, where the lock-in amplitudes were taken) and resamples it by cubic
interpolation in x onto a whole number of samples, so that it tiles seamlessly: a tiled record is
periodic with exactly the lock-in's content (A_lockin, A2, A3 at f_s, 2 f_s, 3 f_s). Splicing units
of two stiffnesses at a bay boundary (a sleeper) gives an instantaneous stiffness step whose truth
on either side is known; the physical transition length of a real step is left out on purpose, so
the measured width is the indicator's own. :func:`write_run` writes the signal as Z11 of a canonical
run (constant speed, position x) that the real pipeline processes.
"""

from __future__ import annotations

import csv
from pathlib import Path

import h5py
import numpy as np
from scipy.interpolate import CubicSpline

PHYSICS = Path(__file__).resolve().parents[2] / "shared" / "physics"
for _cand in (PHYSICS, Path("/work/shared/physics")):
    if (_cand / "cases.csv").is_file():
        PHYSICS = _cand
        break
D_S = 0.6


def cases() -> dict[str, dict[str, float]]:
    """Rows of cases.csv by file name (numbers as float)."""
    with open(PHYSICS / "cases.csv", newline="") as fh:
        return {r["file"]: {k: (float(v) if k != "file" else v) for k, v in r.items()} for r in csv.DictReader(fh)}


def steady_unit(name: str, fs: float | None = None) -> tuple[np.ndarray, float, float, int]:
    """The steady bays of a physics run resampled to a whole number of samples per bay.

    Returns
    -------
    unit : ndarray
        a_axle over ``n_bays`` whole bays, m/s², tiling seamlessly; bay ``i`` is
        ``unit[i*m:(i+1)*m]`` with ``m = unit.size // n_bays``.
    speed : float
        Speed of the resampled unit, m/s (the file's within 0.3 %: a whole number of samples per bay).
    fs : float
        Sample rate, Hz.
    n_bays : int
    """
    d = np.load(PHYSICS / name)
    x, a = d["x"], d["a_axle"]
    fs = float(d["fs"]) if fs is None else fs
    v = float(d["speed"])
    nb = int(cases()[name]["n_bays_steady"])
    x1 = np.floor(x[-1] / D_S + 1e-9) * D_S
    x0 = x1 - nb * D_S
    m = int(round(D_S * fs / v))
    n = nb * m
    grid = x0 + np.arange(n) * (nb * D_S / n)
    unit = CubicSpline(x, a)(grid)
    return unit, nb * D_S * fs / n, fs, nb


def write_run(path: Path, z: np.ndarray, fs: float, speed: float, wheel_diameter: float = 0.92,
              z12: np.ndarray | None = None) -> Path:
    """A canonical run with ``z`` as Z11 (and ``z12`` as Z12: the other wheel of the axle), constant ``speed``,
    position from 0."""
    from app.io import parse_metadata
    from app.io.canonical import CanonicalWriter

    n = z.size
    if z12 is not None and z12.shape != z.shape:
        raise ValueError(f"z12 must have the shape of z {z.shape}, got {z12.shape}")
    meta = parse_metadata({"vehicle_id": "PHYS", "line_id": "PHYS", "km_start": 0.0, "km_increasing": True,
                           "start_time": "2024-01-01T00:00:00+00:00", "track": "1", "direction": "up",
                           "sleeper_spacing": D_S, "sample_rate_hz": fs,
                           "wheel_diameters": {w: wheel_diameter for w in ("11", "12", "41", "42")}})
    with h5py.File(path, "w") as h5:
        channels = ["Z11", *(["Z12"] if z12 is not None else []), "speed", "position"]
        w = CanonicalWriter(h5, fs=fs, metadata=meta, channels=channels, n_samples=n,
                            compression=None, source_format="simulated")
        w.write("Z11", 0, z)
        if z12 is not None:
            w.write("Z12", 0, z12)
        w.write("speed", 0, np.full(n, speed))
        w.write("position", 0, np.arange(n) * speed / fs)
        w.finish(n)
    return path


#: the rough runs (Added 2026-11-26): one rail, or two rails of one track (rail 1 = Z11, rail 2 = Z12)
ROUGH_SINGLE = ("rough_k80_v35", "rough_k80_v35_severe")
ROUGH_PAIRS = ("rail2_k80_v35", "rail2_trans_v42")


def rough_run(name: str) -> dict[str, np.ndarray | float]:
    """A rough physics run as written: ``z11`` (and ``z12`` for a two-rail pair), ``fs``, ``speed``,
    the smooth twin's per-bay truth ``x_bay`` / ``A_bay_smooth`` and the stiffness ``edges``."""
    pair = (PHYSICS / f"{name}_r1.npz").is_file()
    d1 = np.load(PHYSICS / (f"{name}_r1.npz" if pair else f"{name}.npz"))
    out: dict[str, np.ndarray | float] = {"z11": d1["a_axle"], "fs": float(d1["fs"]), "speed": float(d1["speed"]),
                                          "x_bay": d1["x_bay"], "A_bay_smooth": d1["A_bay_smooth"],
                                          "edges": d1["edges"], "ks": d1["ks"], "welds": d1["welds"]}
    if pair:
        out["z12"] = np.load(PHYSICS / f"{name}_r2.npz")["a_axle"]
    return out


#: the filter's start-up at the beginning of a physics run, m: segments before it are not scored
START_M = 4.2


def segment_scores(r: dict, p, column: str, level: float, offset: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Per ``level`` m segment of a processed rough run after the start-up: (estimate / truth − 1,
    whether |estimate − truth| ≤ the stated 1-σ of ``sleeper_amp``), against the smooth twin's
    per-bay truth ``A_bay_smooth``. ``p``: one wheel's profile rows; ``column``: the amplitude scored;
    ``offset``: the segments start at ``offset + g·level`` m (a multiple of the 0.25 m bin)."""
    from app.analysis.uncertainty import segment_sd

    bins = p["bin"].to_numpy()
    x = (bins + 0.5) * 0.25
    shift = int(round(offset / 0.25))
    segs, sd = segment_sd(bins - shift, p["sleeper_amp_sd"].to_numpy(), level,
                          shared=p["sleeper_amp_sd_shared"].to_numpy())
    ratio, covered = [], []
    for g, s in zip(segs, sd, strict=True):
        lo = g * level + shift * 0.25
        if lo < START_M or lo + level > x.max():
            continue
        tb = (r["x_bay"] >= lo) & (r["x_bay"] < lo + level)
        truth = float(np.mean(r["A_bay_smooth"][tb]))
        est = float(np.mean(p[column].to_numpy()[(x >= lo) & (x < lo + level)]))
        ratio.append(est / truth - 1.0)
        covered.append(abs(est - truth) <= s)
    return np.array(ratio), np.array(covered)


#: a Gaussian 1-σ interval covers 68.27 % of the time
ONE_SIGMA = 0.6827


def coverage(r: dict, p, level: float = 10.0, step: float = 2.5) -> dict[str, float]:
    """How often the stated 1-σ of ``level`` m means covers the smooth truth, with its binomial scatter.

    ``k``/``n`` on the segment grid from 0 m; ``share_offsets`` pooled over the grids shifted by
    ``step``, ``2·step`` … < ``level`` (more segments, the same track: they overlap, so their scatter is
    not smaller than one grid's); ``sigma`` the binomial 1-σ of a share of ``n`` independent segments
    around 68.27 %; ``z`` = (share_offsets − 68.27 %) / sigma.
    """
    _, c0 = segment_scores(r, p, "sleeper_amp", level)
    pooled = np.concatenate([segment_scores(r, p, "sleeper_amp", level, o)[1] for o in np.arange(0.0, level, step)])
    n = int(c0.size)
    sigma = float(np.sqrt(ONE_SIGMA * (1.0 - ONE_SIGMA) / n))
    share = float(np.mean(pooled))
    return {"k": int(c0.sum()), "n": n, "share": float(np.mean(c0)), "share_offsets": share,
            "n_offsets": int(pooled.size), "sigma": sigma, "z": (share - ONE_SIGMA) / sigma}


def polygon(n: int, fs: float, speed: float, rho_um: float = 90.0, order: int = 5,
            wheel_diameter: float = 0.92, phase: float = 0.3) -> np.ndarray:
    """Axle-box acceleration of a wheel polygon of ``rho_um`` at ``order`` at constant speed, m/s².

    ``ρ ω_l² cos(l θ + ψ)`` with ``θ = 2x/d_w``, ``ω_l = 2 l v / d_w``.
    """
    x = np.arange(n) * speed / fs
    omega = 2.0 * order * speed / wheel_diameter
    return rho_um * 1e-6 * omega**2 * np.cos(order * 2.0 * x / wheel_diameter + phase)
