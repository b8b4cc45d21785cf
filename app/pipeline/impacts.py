"""Isolated impacts in the pipeline: dips per chunk, track impacts and wheel flats per run.

* In a chunk (:func:`chunk_dip_member`): the surface under each wheel is
  estimated from its acceleration less its wheel orders as the VKF extracted
  them (:func:`wheel_orders_at`; their bands are narrow: they take almost
  nothing of a dip), with the sleeper-passage lines notched out (the VKF's
  track orders are wide: they would take much of a weld), and its dips are
  kept as candidates, with the crossfade weight of the chunk where they lie
  (:mod:`app.analysis.impacts`).
* At assembly (:func:`run_impacts`): the candidates of all chunks are merged
  (each dip from the chunk that weighs most there), wheel flats are the dips
  that repeat every circumference of one wheel (with its refined diameter),
  track impacts the dips that the wheels meet at one track position.
  :func:`impact_extents` measures how far each track impact reaches (its size
  relative to the local level, the track order's impulse response),
  :func:`mask_track_impacts` bridges the profile's track columns there and
  writes the column ``track_impact_mm``; :func:`impacts_meta` is what the
  job's results keep of them (``meta["track_impacts"]``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from app.analysis.chunking import Chunk
from app.analysis.impacts import surface_estimate
from app.analysis.impacts.classify import (
    TrackImpactFinding,
    WheelDips,
    WheelFlatFinding,
    one_per_dip,
    track_impacts,
    wheel_flats,
)
from app.analysis.impacts.dips import scan_dips
from app.analysis.impacts.mask import bridge, impact_mask, impact_response, mask_half_width
from app.analysis.impacts.welds import WheelTrace, combined_track_dips
from app.analysis.recipe import OrderRecipe
from app.analysis.settings import ProcessingSettings

__all__ = [
    "IMPACT_COLUMN",
    "BRIDGED_COLUMNS",
    "DIP_FIELDS",
    "TRACE_FIELDS",
    "OOR_SMOOTH_M",
    "wheel_orders_at",
    "chunk_dip_member",
    "read_dips",
    "read_traces",
    "run_impacts",
    "impact_extents",
    "mask_track_impacts",
    "impacts_meta",
    "flat_result",
]

#: The profile column of track impacts: estimated dip depth (mm) at the impact's bin, NaN elsewhere.
IMPACT_COLUMN = "track_impact_mm"
#: Profile columns bridged around a track impact (the sleeper-passage indicator, its single-wheel
#: amplitude and 1-σ, and its force).
BRIDGED_COLUMNS: tuple[str, ...] = ("sleeper_amp", "sleeper_amp_raw", "sleeper_amp_sd", "sleeper_amp_sd_shared",
                                    "sleeper_2_amp", "sleeper_3_amp", "sleeper_rms", "sleeper_force_amp")
#: Moving mean of the wheel orders' envelopes before they are taken out of the surface, m of travel. A
#: wheel's out-of-roundness is fixed to the wheel: its response changes only with the speed, over
#: hundreds of metres. The VKF's own wheel-order bands (0.1 wheel orders, ≈ 0.035 1/m each) also hold
#: the roughness's and a weld's content at 11 lines across a weld's band; averaged over 40 m they are
#: several times narrower, and a weld on rough rail keeps that much more of its score (the share of
#: 0.3 mm welds found: 77 → 83 %, bench_impacts.py --case sim, 6 lines).
OOR_SMOOTH_M = 40.0
#: Harmonics of the sleeper passage notched out of the surface under a wheel (``h / d_s``, h = 1 …): the
#: sleeper passage is periodic in the track, not a dip, and real track has many harmonics (the physics'
#: smooth 100 MN/m track at 30 m/s: the 4th–10th, not extracted by the VKF, were the weld filters' whole
#: background there, their spread 0.065 mm for a 1 m dip, so that a 0.25 mm weld on one wheel scored 4.9
#: against the one-rail threshold 6.5 — not reported; notched, 56). Up to 10 (16.7 1/m): the weld
#: filters' band ends near 2 1/m, the harmonics above the 10th hardly move the spread.
SLEEPER_NOTCH_HARMONICS = 10
#: Rows of a chunk file's ``dips_<wheel>`` member.
DIP_FIELDS: tuple[str, ...] = ("track_m", "s_m", "length_m", "depth_m", "score", "speed_mps", "weight")
#: Rows of a chunk file's ``dipx_<wheel>`` member (float32, track position less the float64 origin in
#: ``dipo_<wheel>``), beside ``dipz_<wheel>`` (float16: the weld filters' scores per length, then their
#: depths in mm) and ``dipl_<wheel>`` (the lengths, m): the weld trace, every 8 cm of travel where the
#: chunk weighs most (crossfade weight >= 0.5). ~1.2 MB per km of a four-wheel run (the rest of a chunk
#: file ~8 MB).
TRACE_FIELDS: tuple[str, ...] = ("track_m",)


def _member(wheel: str) -> str:
    return f"dips_{wheel}"


def _trace_members(wheel: str) -> tuple[str, str, str, str]:
    return f"dipx_{wheel}", f"dipz_{wheel}", f"dipl_{wheel}", f"dipo_{wheel}"


def wheel_orders_at(env: np.ndarray, out_idx: np.ndarray, travelled_m: np.ndarray, recipe: OrderRecipe,
                    lo: int, smooth_m: float = OOR_SMOOTH_M) -> Callable[[np.ndarray], np.ndarray]:
    """The wheel orders as the VKF extracted them, as a function of travelled distance (m → m/s²).

    Order ``n`` is ``Re(env_n e^(i 2 pi multiplier_n s))`` (the recipe's phase
    convention with ``psi = 2 pi s``), its envelope averaged over ``smooth_m``
    of travel (:data:`OOR_SMOOTH_M`) and interpolated between the output grid's
    points.

    Parameters
    ----------
    env : numpy.ndarray
        The wheel's order envelopes on the output grid ``out_idx`` (rows of ``recipe``).
    out_idx : numpy.ndarray
        Output grid (global samples).
    travelled_m : numpy.ndarray
        Travelled distance per sample of the chunk (from ``lo``), m.
    recipe : OrderRecipe
    lo : int
        Global index of the chunk's first sample.
    smooth_m : float
        Length of the moving mean of the envelopes, m of travel (0: as the VKF gave them).
    """
    if not (np.isfinite(smooth_m) and smooth_m >= 0):
        raise ValueError(f"smooth_m: must be a finite length >= 0 m, got {smooth_m!r}")
    rows = recipe.wheel_rows
    s_out = travelled_m[out_idx - lo]
    mult = recipe.multipliers[rows]
    powers = recipe.powers[rows]  # order l: multiplier = l × (that of order 1)
    base = float(mult[0] / powers[0]) if mult.size else 0.0
    env_w = np.ascontiguousarray(env[rows])
    if smooth_m > 0 and s_out.size > 2:  # moving mean over smooth_m of travel (the grid is uneven in s)
        c = np.concatenate([np.zeros((env_w.shape[0], 1)), np.cumsum(env_w, axis=1)], axis=1)
        lo_i = np.searchsorted(s_out, s_out - 0.5 * smooth_m, side="left")
        hi_i = np.searchsorted(s_out, s_out + 0.5 * smooth_m, side="right")
        env_w = (c[:, hi_i] - c[:, lo_i]) / (hi_i - lo_i)

    def at(s: np.ndarray) -> np.ndarray:
        s = np.asarray(s, dtype=np.float64)
        out = np.zeros(s.shape)
        if env_w.shape[0] == 0 or s_out.size < 2:
            return out
        # envelopes linear between the grid's points (clamped at its ends); phasors by recurrence
        j = np.clip(np.searchsorted(s_out, s, side="right"), 1, s_out.size - 1)
        w = np.clip((s - s_out[j - 1]) / np.maximum(s_out[j] - s_out[j - 1], 1e-12), 0.0, 1.0)
        z1 = np.exp(2j * np.pi * base * s)
        zl = np.ones(s.shape, dtype=np.complex128)
        level = 0
        for k in np.argsort(powers):
            while level < powers[k]:
                zl *= z1
                level += 1
            c = env_w[k, j - 1] * (1.0 - w) + env_w[k, j] * w
            out += (c * zl).real
        return out

    return at


def chunk_dip_member(
    wheel: str,
    accel: np.ndarray,
    travelled_m: np.ndarray,
    speed_mps: np.ndarray,
    track_m: np.ndarray,
    recipe: OrderRecipe,
    wheel_orders: Callable[[np.ndarray], np.ndarray],
    chunk: Chunk,
    lo: int,
    fs: float | None = None,
) -> dict[str, np.ndarray]:
    """The chunk-file member of one wheel's dip candidates in a chunk.

    Parameters
    ----------
    wheel : str
    accel : numpy.ndarray
        The wheel's axle-box acceleration over the chunk's samples ``lo …``, m/s².
    travelled_m, speed_mps, track_m : numpy.ndarray
        Per sample of the chunk: travelled distance (the phase reference), absolute speed, track position.
    recipe : OrderRecipe
        The wheel's orders: the sleeper-passage lines are notched out of the surface.
    wheel_orders : callable
        The wheel orders at travelled distances (:func:`wheel_orders_at`), taken out first.
    chunk : Chunk
    lo : int
        Global index of the chunk's first sample.
    fs : float, optional
        The run's sampling rate, Hz (a coarse recording's surface is estimated below 0.4 ``fs``).

    Returns
    -------
    dict
        ``{"dips_<wheel>": (len(DIP_FIELDS), n) float array}``: the dips inside the chunk's output
        range, with the chunk's crossfade weight there; ``dipx_``, ``dipz_``, ``dipl_``, ``dipo_<wheel>``:
        the weld trace where the chunk weighs most (:data:`TRACE_FIELDS`,
        :class:`app.analysis.impacts.dips.DipTrace`).
    """
    empty = {_member(wheel): np.zeros((len(DIP_FIELDS), 0))}
    # the whole chunk, padding included (the wheel orders are stationary: their envelopes held at the
    # output range's ends are right there), so that the estimate's own edges lie outside the output range
    a, b = 0, accel.size
    if b - a < 2:
        return empty
    base = float(recipe.multipliers[recipe.sleeper_row])
    lines = tuple(sorted({*(float(recipe.multipliers[r]) for r in recipe.track_rows),
                          *(h * base for h in range(1, SLEEPER_NOTCH_HARMONICS + 1))}))
    est = surface_estimate(accel[a:b], travelled_m[a:b], speed_mps[a:b], lines_per_m=lines, subtract=wheel_orders,
                           fs=fs)
    dips, trace = scan_dips(est)
    out = dict(empty)
    if len(trace):
        idx = np.clip(np.searchsorted(travelled_m[a:b], trace.s_m), 0, b - a - 1) + a
        weight = chunk.weight(idx + lo)
        kx, kz, kl, ko = _trace_members(wheel)
        x = track_m[idx]
        keep = (weight >= 0.5) & np.any(np.isfinite(trace.score), axis=0) & np.isfinite(x)
        origin = float(x[keep][0]) if keep.any() else 0.0
        out[kx] = (x[keep] - origin)[None, :].astype(np.float32)
        out[kz] = np.vstack([trace.score, 1e3 * trace.depth_m])[:, keep].astype(np.float16)
        out[kl] = trace.lengths_m.astype(np.float64)
        out[ko] = np.array([origin])
    if len(dips) == 0:
        return out
    idx = np.clip(np.searchsorted(travelled_m[a:b], dips.s_m), 0, b - a - 1) + a
    weight = chunk.weight(idx + lo)
    inside = weight > 0
    rows = np.vstack([track_m[idx], dips.s_m, dips.length_m, dips.depth_m, dips.score, dips.speed_mps, weight])
    out[_member(wheel)] = rows[:, inside].astype(np.float64)
    return out


def read_dips(paths: Sequence[Path], wheels: Sequence[str]) -> dict[str, WheelDips]:
    """Every wheel's dips over a run from its chunk files: each dip once, from the chunk weighing most there.

    Files without dip members (written before them) add nothing.
    """
    parts: dict[str, list[np.ndarray]] = {w: [] for w in wheels}
    for path in sorted(paths, key=lambda p: str(p)):
        with np.load(path) as npz:
            for w in wheels:
                key = _member(w)
                if key in npz.files:
                    arr = np.asarray(npz[key], dtype=np.float64)
                    if arr.ndim == 2 and arr.shape[0] == len(DIP_FIELDS) and arr.shape[1]:
                        parts[w].append(arr)
    out: dict[str, WheelDips] = {}
    for w, arrs in parts.items():
        if not arrs:
            continue
        rows = np.hstack(arrs)
        rows = rows[:, rows[6] >= 0.5]  # the chunk that weighs most at the dip (crossfades: ≥ 0.5 in one)
        order = np.argsort(rows[1], kind="stable")
        rows = rows[:, order]
        # a dip at a seam found by both chunks (weight 0.5 each): keep the higher score
        keep = np.ones(rows.shape[1], dtype=bool)
        for i in range(1, rows.shape[1]):
            if rows[1, i] - rows[1, i - 1] < 0.2:
                worse = i if rows[4, i] <= rows[4, i - 1] else i - 1
                keep[worse] = False
        rows = rows[:, keep]
        out[w] = WheelDips(*(rows[k] for k in range(6)))
    return out


def read_traces(paths: Sequence[Path], wheels: Sequence[str]) -> dict[str, WheelTrace]:
    """Every wheel's long-filter score trace over a run from its chunk files (where a chunk weighs most).

    Files without trace members (written before them) add nothing.
    """
    parts: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {w: [] for w in wheels}
    lengths: dict[str, np.ndarray] = {}
    for path in sorted(paths, key=lambda p: str(p)):
        with np.load(path) as npz:
            for w in wheels:
                kx, kz, kl, ko = _trace_members(w)
                if all(k in npz.files for k in (kx, kz, kl, ko)):
                    ln = np.asarray(npz[kl], dtype=np.float64)
                    x = np.asarray(npz[kx], dtype=np.float64)
                    z = np.asarray(npz[kz], dtype=np.float64)
                    if not (x.ndim == 2 and x.shape[0] == len(TRACE_FIELDS) and x.shape[1]
                            and z.shape == (2 * ln.size, x.shape[1])):
                        continue
                    if w in lengths and not np.array_equal(lengths[w], ln):
                        continue  # chunks of another bank (not expected within a run)
                    lengths[w] = ln
                    parts[w].append((x[0] + float(np.asarray(npz[ko]).reshape(-1)[0]), z))
    out: dict[str, WheelTrace] = {}
    for w, arrs in parts.items():
        if not arrs:
            continue
        x = np.concatenate([p[0] for p in arrs])
        z = np.hstack([p[1] for p in arrs])
        order = np.argsort(x, kind="stable")
        k = lengths[w].size
        out[w] = WheelTrace(x[order], lengths[w], z[:k][:, order], 1e-3 * z[k:][:, order])
    return out


def run_impacts(
    chunk_paths: Sequence[Path], wheels: Sequence[Mapping[str, Any]]
) -> tuple[list[TrackImpactFinding], dict[str, WheelFlatFinding]]:
    """Track impacts and wheel flats of a run from its chunk files.

    Parameters
    ----------
    chunk_paths : sequence of Path
    wheels : sequence of dict
        The wheel results (``wheel``, ``refined_diameter_m`` or ``wheel_diameter_m``).
    """
    names = [str(w["wheel"]) for w in wheels]
    dips = read_dips(chunk_paths, names)
    diam = {}
    for w in wheels:
        d = w.get("refined_diameter_m") or w.get("wheel_diameter_m")
        if d is not None and np.isfinite(float(d)) and float(d) > 0:
            diam[str(w["wheel"])] = float(d)
    flats, used = wheel_flats(dips, diam)
    # welds: the single-wheel candidates' test (clear dips: smooth rail, joints) and the weld filters'
    # evidence combined over the wheels (welds on rough rail, app.analysis.impacts.welds)
    combined = one_per_dip(combined_track_dips(read_traces(chunk_paths, names), wheels_measured=tuple(names)))
    single = one_per_dip(track_impacts(dips, exclude=used, wheels_measured=tuple(names)))
    # where both found one, the single-wheel test's (its length and depth fit one wheel's dip alone)
    merged = list(single)
    for imp in combined:
        if all(abs(imp.track_m - c.track_m) > 1.5 + 0.5 * max(imp.length_m, c.length_m) for c in single):
            merged.append(imp)
    return sorted(merged, key=lambda i: i.track_m), flats


def impact_extents(profiles: pd.DataFrame, impacts: Sequence[TrackImpactFinding],
                   settings: ProcessingSettings, resolution_m: float | None = None) -> list[tuple[float, float]]:
    """Per track impact its size relative to the local sleeper-passage level and its mask's half width.

    The ratio and the offset of the largest disturbance (:func:`app.analysis.impacts.mask.impact_response`)
    are the largest over the wheels' own amplitude (``sleeper_amp_raw``, else ``sleeper_amp``) before
    bridging, the other impacts' cores left out of the level; the half width
    (:func:`app.analysis.impacts.mask.mask_half_width`) follows from them, the dip's length and the track
    orders' resolution and filter order.

    Parameters
    ----------
    resolution_m : float, optional
        The track orders' resolution the wheels were solved with, m (the widest of the wheels'); default
        ``settings.track_resolution_m``. Needed when that is None (the track orders on the wheel orders'
        band, whose resolution depends on the wheel diameter).

    Returns
    -------
    list of (ratio, half_width_m)
        In the order of ``impacts``; ratio NaN where it could not be measured (the default ratio's width).
    """
    if not impacts:
        return []
    if resolution_m is None:
        if settings.track_resolution_m is None:
            raise ValueError("resolution_m: needed when settings.track_resolution_m is None")
        resolution_m = settings.track_resolution_m
    res = float(resolution_m)
    q = int(settings.filter_order)
    col = "sleeper_amp_raw" if "sleeper_amp_raw" in profiles.columns else "sleeper_amp"
    ratios = np.full(len(impacts), np.nan)
    offsets = np.full(len(impacts), np.nan)
    if not profiles.empty and col in profiles.columns:
        bl = float(settings.bin_length_m)
        for _, sub in profiles.groupby(profiles["wheel"].astype(str), sort=False):
            sub = sub.sort_values("bin")
            x = (sub["bin"].to_numpy() + 0.5) * bl
            v = sub[col].to_numpy(dtype=np.float64)
            for i, imp in enumerate(impacts):
                others = impact_mask(x, [o.track_m for j, o in enumerate(impacts) if j != i],
                                     [0.5 * o.length_m + res for j, o in enumerate(impacts) if j != i])
                r, off = impact_response(x, v, imp.track_m, imp.length_m, res, exclude=others)
                ratios[i], offsets[i] = np.fmax(ratios[i], r), np.fmax(offsets[i], off)  # NaN: not measured
    return [(float(r), mask_half_width(imp.length_m, res, r, q, offset_m=float(o)))
            for r, o, imp in zip(ratios, offsets, impacts, strict=True)]


def mask_track_impacts(profiles: pd.DataFrame, impacts: Sequence[TrackImpactFinding],
                       settings: ProcessingSettings,
                       extents: Sequence[tuple[float, float]] | None = None) -> pd.DataFrame:
    """Profiles with the track columns bridged around every track impact and ``track_impact_mm`` written.

    Every wheel's bins within the impact's mask half width (:func:`impact_extents`, or ``extents``
    given) are replaced by the straight line between the undisturbed bins beside them
    (:data:`BRIDGED_COLUMNS`); the bin holding the impact gets its estimated depth in
    ``track_impact_mm`` (that rail's estimate where it was found there, else the mean), all others NaN.
    """
    out = profiles.copy()
    out[IMPACT_COLUMN] = np.nan
    if not impacts or out.empty:
        return out
    if extents is None:
        extents = impact_extents(profiles, impacts, settings)
    bl = float(settings.bin_length_m)
    pos = [i.track_m for i in impacts]
    half = [h for _, h in extents]
    for wheel, rows in out.groupby(out["wheel"].astype(str), sort=False).indices.items():
        sub = out.iloc[rows]
        order = np.argsort(sub["bin"].to_numpy())
        idx = rows[order]
        bins = out["bin"].to_numpy()[idx]
        x = (bins + 0.5) * bl
        mask = impact_mask(x, pos, half)
        for col in BRIDGED_COLUMNS:
            if col in out.columns:
                out.iloc[idx, out.columns.get_loc(col)] = bridge(x, out[col].to_numpy(dtype=np.float64)[idx], mask)
        side = int(str(wheel)[1]) if len(str(wheel)) == 2 else 0
        col = out.columns.get_loc(IMPACT_COLUMN)
        for imp in impacts:
            b = int(np.floor(imp.track_m / bl))
            j = np.searchsorted(bins, b)
            if j < bins.size and bins[j] == b:
                out.iloc[idx[j], col] = 1e3 * imp.depth_by_side.get(side, imp.depth_m)
    return out


def impacts_meta(impacts: Sequence[TrackImpactFinding], extents: Sequence[tuple[float, float]]) -> list[dict[str, Any]]:
    """The run's track impacts as stored with its results (JSON): position, dip, ratio, mask half width."""
    return [{"track_m": float(i.track_m), "length_m": float(i.length_m), "depth_mm": 1e3 * float(i.depth_m),
             "depth_mm_by_side": {str(k): 1e3 * float(v) for k, v in i.depth_by_side.items()},
             "score": float(i.score), "wheels": list(i.wheels),
             "ratio": None if not np.isfinite(r) else float(r), "mask_half_width_m": float(h)}
            for i, (r, h) in zip(impacts, extents, strict=True)]


def flat_result(flat: WheelFlatFinding | None) -> dict[str, Any] | None:
    """A wheel flat as stored with the wheel's results (JSON: mm, degrees, km)."""
    if flat is None:
        return None
    d = asdict(flat)
    return {
        "angle_deg": d["angle_deg"],
        "angle_spread_deg": d["angle_spread_deg"],
        "depth_mm": 1e3 * d["depth_m"],
        "length_mm": 1e3 * d["length_m"],
        "n_hits": d["n_hits"],
        "n_revolutions": d["n_revolutions"],
        "first_km": d["first_track_m"] / 1000.0,
        "last_km": d["last_track_m"] / 1000.0,
    }
