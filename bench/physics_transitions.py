"""Stiffness transitions as the physics makes them: test signals, truth and metrics (issue 26).

Signals
-------
* :func:`physics_run` — a transition run of ../shared/physics as it is (``trans2_v30.npz``:
  60 / 150 / 60 / 150 MN/m at 30 m/s; ``trans2_v42.npz``: 120 / 30 / 120 / 60 MN/m at 42.5 m/s;
  edges at 40 / 80 / 120 m, 160 m long), with its per-bay truth ``A_bay``.
* :func:`embedded_run` — *constructed*: the same physics run between ``lead_m`` of its own first
  and last segment (whole steady bays of that segment, tiled; resampled to a whole number of samples
  per bay, 0.13 % faster at 42.5 m/s). It stands for the transitions inside a long run, which is
  what the service processes (60 s chunks, 1.5–3 km).
* :func:`blended_run` — *constructed*: steady bays of two uniform physics runs (grid_k*_v*.npz) of one
  speed, joined by a transition over ``blend_bays`` bays in which both responses are cross-faded
  (raised cosine), so that the fundamental's amplitude and phase turn over metres as in the
  transition runs (1–5 m there), not at one sample as in a splice. Its truth is the per-bay lock-in
  of the constructed signal itself (:func:`per_bay_amplitude`), like ``A_bay``.

Metrics (:func:`edge_metrics`, :func:`level_errors`), on ``s = (a − L1) / (L2 − L1)`` within
±20 m of an edge, ``L1``, ``L2`` the segments' steady levels:

* **10–90 % width** (settling form): from where ``s`` first leaves [−0.1, 0.1] to where it last
  leaves [0.9, 1.1]; ringing longer than the step counts in it (the issue's measure);
* **rise width**: from the last crossing of 0.1 before the 50 % point to the first crossing of 0.9
  after it (the filter's own step width);
* **50 % point**: the crossing of 0.5 nearest the edge, minus the edge;
* **ringing**: the largest excursion of ``s`` beyond [0, 1];
* **level error**: the mean of ``a`` 10–20 m from each edge of a segment against its level.

The physics' own widths are the same measures on ``A_bay`` (one value per 0.6 m bay).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from physics_runs import D_S, PHYSICS, steady_unit
from scipy.interpolate import CubicSpline

#: half window around an edge for the edge metrics, m
HALF_WINDOW_M = 20.0
#: bays after a stiffness edge (and at a run's start) that are transient, as the physics README says
TRANSIENT_BAYS = 7
#: targets of issue 26
TARGETS = {"width_m": 6.0, "width_over_physics_m": 1.0, "offset_m": 2.0, "ringing": 0.10, "level": 0.03}


@dataclass
class TransitionRun:
    """A signal with stiffness edges and its truth.

    Attributes
    ----------
    name : str
    z : ndarray
        Axle-box acceleration, m/s² (sample 0 at x = 0).
    fs, speed : float
        Hz, m/s.
    edges : ndarray
        Positions of the stiffness edges, m.
    levels : ndarray
        Steady sleeper-passage amplitude of every segment (len(edges) + 1), m/s².
    bounds : ndarray
        Segment boundaries: 0, edges, end, m.
    x_bay, a_bay : ndarray
        Per-bay truth: bay centres (m) and the sleeper-passage amplitude over that bay alone, m/s².
    constructed : str
        Empty for a physics run as it is; otherwise how it was built.
    """

    name: str
    z: np.ndarray
    fs: float
    speed: float
    edges: np.ndarray
    levels: np.ndarray
    bounds: np.ndarray
    x_bay: np.ndarray
    a_bay: np.ndarray
    constructed: str = ""
    extra: dict = field(default_factory=dict)


def _segment_levels(x_bay: np.ndarray, a_bay: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """Mean per-bay amplitude over the steady bays of every segment (from 7 bays after its start)."""
    out = []
    for lo, hi in zip(bounds[:-1], bounds[1:], strict=True):
        sel = (x_bay - D_S / 2 >= lo + TRANSIENT_BAYS * D_S - 1e-9) & (x_bay + D_S / 2 <= hi + 1e-9)
        out.append(float(np.mean(a_bay[sel])))
    return np.array(out)


def physics_run(name: str) -> TransitionRun:
    """A transition run of ../shared/physics as it is, with its per-bay truth."""
    d = np.load(PHYSICS / name)
    z, fs, v = d["a_axle"], float(d["fs"]), float(d["speed"])
    edges = np.asarray(d["edges"], dtype=float)
    bounds = np.r_[0.0, edges, float(d["x"][-1])]
    x_bay, a_bay = np.asarray(d["x_bay"]), np.asarray(d["A_bay"])
    return TransitionRun(name, z, fs, v, edges, _segment_levels(x_bay, a_bay, bounds), bounds, x_bay, a_bay)


def embedded_run(name: str, lead_m: float = 1000.0, unit_bays: int = 40) -> TransitionRun:
    """Constructed: a physics transition run between ``lead_m`` of its own first and last segment.

    The run is resampled onto a whole number of samples per bay; its bays from 4.2 m on (the start-up
    transient left out) follow ``lead_m`` of tiled steady bays of its first segment (the ``unit_bays``
    bays before 1.2 m ahead of the first edge) and are followed by tiled steady bays of its last
    segment (the bays up to 1.2 m before its end).
    """
    base = physics_run(name)
    d = np.load(PHYSICS / name)
    x, a = d["x"], d["a_axle"]
    m = int(round(D_S * base.fs / base.speed))
    v = D_S * base.fs / m
    spline = CubicSpline(x, a)
    j_end = int(np.floor(x[-1] / D_S + 1e-9))

    def bays(j0: int, count: int) -> np.ndarray:
        return spline(j0 * D_S + np.arange(count * m) * (D_S / m))

    first = bays(int(round(base.edges[0] / D_S)) - 2 - unit_bays, unit_bays)
    last = bays(j_end - 2 - unit_bays, unit_bays)
    reps = int(round(lead_m / (unit_bays * D_S)))
    body = bays(TRANSIENT_BAYS, j_end - TRANSIENT_BAYS)
    z = np.concatenate([np.tile(first, reps), body, np.tile(last, reps)])
    shift = reps * unit_bays * D_S - TRANSIENT_BAYS * D_S
    length = z.size * v / base.fs
    keep = base.x_bay > TRANSIENT_BAYS * D_S
    return TransitionRun(
        f"{name} in {lead_m:g} m", z, base.fs, v, base.edges + shift, base.levels, np.r_[0.0, base.edges + shift, length],
        base.x_bay[keep] + shift, base.a_bay[keep],
        constructed=f"the physics run between {lead_m:g} m of its own first and last segment (tiled steady bays)",
    )


def per_bay_amplitude(z: np.ndarray, fs: float, speed: float, x0: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Sleeper-passage amplitude over every whole bay alone (the README's ``A_bay``), m/s².

    Bay ``j`` = [0.6 j, 0.6 j + 0.6) m, ``A = 2 |mean(z e^{−i 2π x / 0.6})|`` over its samples.
    """
    x = x0 + np.arange(z.size) * speed / fs
    j = np.floor(x / D_S + 1e-9).astype(np.int64)
    ph = np.exp(-2j * np.pi * x / D_S)
    n = np.bincount(j)
    s = np.bincount(j, (z * ph).real) + 1j * np.bincount(j, (z * ph).imag)
    full = n >= 0.99 * D_S * fs / speed
    jj = np.flatnonzero(full)
    return (jj + 0.5) * D_S, 2.0 * np.abs(s[jj] / n[jj])


def blended_run(speed: int, k_a: int, k_b: int, segments_m: list[float], lead_m: float = 500.0,
                blend_bays: int = 5) -> TransitionRun:
    """Constructed: ``lead_m`` of k_a, then segments alternating k_b, k_a, … of ``segments_m``, then
    ``lead_m`` of the other; each edge a cross-fade over ``blend_bays`` bays centred on it.

    The steady units are the uniform physics runs ``grid_k{k}_v{speed}.npz`` (bench/physics_runs.py).
    """
    ua, va, fs, na = steady_unit(f"grid_k{k_a}_v{speed}.npz")
    ub, _, _, nb = steady_unit(f"grid_k{k_b}_v{speed}.npz")
    m = ua.size // na
    if ub.size // nb != m:
        raise ValueError("units of one speed must have equal samples per bay")

    def tiled(u: np.ndarray, n_units: int, count: int) -> np.ndarray:
        return np.tile(u, -(-count // n_units) + 1)

    lengths = [int(round(lead_m / D_S))] + [int(round(s / D_S)) for s in segments_m] + [int(round(lead_m / D_S))]
    total = sum(lengths) * m
    sig = {k_a: tiled(ua, na, sum(lengths))[:total], k_b: tiled(ub, nb, sum(lengths))[:total]}
    w = np.zeros(total)  # weight of k_b
    edges_bay = np.cumsum(lengths)[:-1]
    which = [(i % 2) for i in range(len(lengths))]  # 0: k_a, 1: k_b
    for i, (a, b) in enumerate(zip(np.r_[0, edges_bay], np.r_[edges_bay, sum(lengths)], strict=True)):
        w[a * m : b * m] = which[i]
    ramp = 0.5 - 0.5 * np.cos(np.pi * (np.arange(blend_bays * m) + 0.5) / (blend_bays * m))
    for i, e in enumerate(edges_bay):
        lo = (e - blend_bays // 2) * m - (m // 2 if blend_bays % 2 else 0)
        seg = slice(lo, lo + blend_bays * m)
        w[seg] = ramp if which[i + 1] == 1 else 1.0 - ramp
    z = (1.0 - w) * sig[k_a] + w * sig[k_b]
    x_bay, a_bay = per_bay_amplitude(z, fs, va)
    edges = edges_bay * D_S
    bounds = np.r_[0.0, edges, sum(lengths) * D_S]
    # steady level of every segment: the lock-in of its unit (a short segment has no steady bays of its own)
    lock = {k_a: per_bay_amplitude(ua, fs, va)[1].mean(), k_b: per_bay_amplitude(ub, fs, va)[1].mean()}
    levels = np.array([lock[k_b] if which[i] else lock[k_a] for i in range(len(lengths))])
    return TransitionRun(
        f"grid v{speed}: {k_a}/{k_b} MN/m, segments {'/'.join(f'{s:g}' for s in segments_m)} m", z, fs, va, edges,
        levels, bounds, x_bay, a_bay,
        constructed=f"uniform physics runs k{k_a} and k{k_b} at {speed} m/s cross-faded over {blend_bays} bays at each edge",
    )


def _crossing(xs: np.ndarray, s: np.ndarray, i: int, level: float) -> float:
    """x where s crosses ``level`` between samples i − 1 and i (linear)."""
    if s[i] == s[i - 1]:
        return float(xs[i])
    return float(np.interp(level, *((s[i - 1 : i + 1], xs[i - 1 : i + 1]) if s[i] > s[i - 1]
                                   else (s[i - 1 : i + 1][::-1], xs[i - 1 : i + 1][::-1]))))


def edge_metrics(x: np.ndarray, a: np.ndarray, edge: float, l1: float, l2: float,
                 half: float = HALF_WINDOW_M) -> dict[str, float]:
    """Widths, 50 % point and ringing of one edge (see the module notes)."""
    sel = (x > edge - half) & (x < edge + half) & np.isfinite(a)
    xs, s = x[sel], (a[sel] - l1) / (l2 - l1)
    up = np.flatnonzero((s[:-1] < 0.5) & (s[1:] >= 0.5)) + 1
    if up.size == 0:
        return {"width": np.nan, "rise": np.nan, "offset": np.nan, "ringing": np.nan}
    i50 = int(up[np.argmin(np.abs(xs[up] - edge))])
    x50 = _crossing(xs, s, i50, 0.5)
    below = np.flatnonzero(s[:i50] < 0.1)
    i10 = int(below[-1]) + 1 if below.size else 1
    above = np.flatnonzero(s[i50:] >= 0.9)
    i90 = i50 + int(above[0]) if above.size else len(s) - 1
    rise = _crossing(xs, s, i90, 0.9) - _crossing(xs, s, i10, 0.1)
    out0 = np.flatnonzero(np.abs(s) > 0.1)
    out1 = np.flatnonzero(np.abs(s - 1.0) > 0.1)
    if out0.size and out0[0] > 0:
        k = int(out0[0])
        xa = _crossing(xs, s, k, 0.1 if s[k] > 0 else -0.1)
    else:
        xa = float(xs[0])
    if out1.size and out1[-1] < len(s) - 1:
        k = int(out1[-1]) + 1
        xb = _crossing(xs, s, k, 0.9 if s[k - 1] < 1 else 1.1)
    else:
        xb = float(xs[-1])
    ringing = max(float(s.max()) - 1.0, -float(s.min()), 0.0)
    return {"width": xb - xa, "rise": rise, "offset": x50 - edge, "ringing": ringing}


def level_errors(x: np.ndarray, a: np.ndarray, run: TransitionRun, near: tuple[float, float] = (10.0, 20.0)
                 ) -> list[float]:
    """Per segment: the largest relative error of the mean of ``a`` ``near`` m from its edges
    (an edge at a run end does not count; a segment shorter than 2 × ``near[1]`` is skipped: NaN)."""
    out = []
    for i, (lo, hi) in enumerate(zip(run.bounds[:-1], run.bounds[1:], strict=True)):
        if hi - lo < 2 * near[1]:
            out.append(np.nan)
            continue
        errs = []
        for p, q, real in ((lo + near[0], lo + near[1], i > 0), (hi - near[1], hi - near[0], i < len(run.levels) - 1)):
            if real:
                sel = (x > p) & (x < q)
                errs.append(float(np.mean(a[sel])) / run.levels[i] - 1.0)
        out.append(max(errs, key=abs) if errs else np.nan)
    return out


def evaluate(x: np.ndarray, a: np.ndarray, run: TransitionRun) -> dict:
    """Edge metrics of the product profile and of the per-bay truth, and the level errors."""
    edges = []
    for j, e in enumerate(run.edges):
        l1, l2 = run.levels[j], run.levels[j + 1]
        edges.append({"edge": float(e), "product": edge_metrics(x, a, e, l1, l2),
                      "physics": edge_metrics(run.x_bay, run.a_bay, e, l1, l2)})
    return {"edges": edges, "levels": level_errors(x, a, run)}


def meets_targets(result: dict) -> dict[str, bool]:
    """Which of the issue's targets a result meets (NaN levels do not count)."""
    t = TARGETS
    width = all(e["product"]["width"] <= max(t["width_m"], e["physics"]["width"] + t["width_over_physics_m"])
                for e in result["edges"])
    offset = all(abs(e["product"]["offset"]) <= t["offset_m"] for e in result["edges"])
    ringing = all(e["product"]["ringing"] <= t["ringing"] for e in result["edges"])
    levels = all(abs(v) <= t["level"] for v in result["levels"] if np.isfinite(v))
    return {"width": width, "offset": offset, "ringing": ringing, "levels": levels}


def wheel5_projection(run: TransitionRun, wheel_diameter: float = 0.92) -> float:
    """|Projection of the whole signal on the wheel-order-5 line|, m/s² (peak): the track's own
    content at that line over the record, which a wheel order estimated from this record takes."""
    t = np.arange(1, run.z.size + 1) / run.fs
    f5 = 5.0 * run.speed / (np.pi * wheel_diameter)
    return float(2.0 * np.abs(np.mean(run.z * np.exp(-2j * np.pi * f5 * t))))


def lockin_less_line(run: TransitionRun, line_amp: float, lo: float, hi: float,
                     wheel_diameter: float = 0.92) -> float:
    """Mean per-bay lock-in at ``f_s`` over the bays in [lo, hi) m of the signal less a wheel-order-5 line
    of peak amplitude ``line_amp`` with the phase of the record's own content at that line
    (:func:`wheel5_projection`): what the physics gives where a stationary wheel order of that size
    was taken out of the record, m/s²."""
    t = np.arange(1, run.z.size + 1) / run.fs
    f5 = 5.0 * run.speed / (np.pi * wheel_diameter)
    proj = 2.0 * np.mean(run.z * np.exp(-2j * np.pi * f5 * t))
    z = run.z - np.real(line_amp * proj / abs(proj) * np.exp(2j * np.pi * f5 * t))
    x = t * run.speed
    ref = np.exp(-2j * np.pi * (run.speed / D_S) * t)
    out = []
    for xc in run.x_bay[(run.x_bay >= lo) & (run.x_bay < hi)]:
        sel = (x >= xc - D_S / 2) & (x < xc + D_S / 2)
        out.append(abs(2.0 * np.mean(z[sel] * ref[sel])))
    return float(np.mean(out))


def soft_level_cause(work_dir, lo_hi=((50.0, 60.0), (60.0, 70.0), (50.0, 70.0))) -> dict:
    """Why the 30 MN/m level of ``trans2_v42`` reads high (issue 26 (b)): per window, the product's mean
    ``sleeper_amp``, the physics' per-bay truth ``A_bay`` and the physics' lock-in of the signal less
    the product's stationary wheel-order-5 line (``order_amp_05``), plus that line and the record's own
    content at it."""
    from pathlib import Path

    from physics_runs import write_run

    from app.analysis.settings import ProcessingSettings
    from app.pipeline import run_pipeline

    run = physics_run("trans2_v42.npz")
    work = Path(work_dir)
    work.mkdir(parents=True, exist_ok=True)
    res = run_pipeline(write_run(work / "run.h5", run.z, run.fs, run.speed), ProcessingSettings(), work / "chunks")
    p = res.profiles[res.profiles["wheel"] == "11"].sort_values("bin")
    x = (p["bin"].to_numpy() + 0.5) * 0.25
    line = float(np.median(p["order_amp_05"]))
    rows = []
    for lo, hi in lo_hi:
        sel = (x > lo) & (x < hi)
        bays = (run.x_bay > lo) & (run.x_bay < hi)
        rows.append({"window": (lo, hi), "product": float(np.mean(p["sleeper_amp"].to_numpy()[sel])),
                     "a_bay": float(np.mean(run.a_bay[bays])),
                     "lockin_less_line": lockin_less_line(run, line, lo, hi)})
    return {"line": line, "record_content": wheel5_projection(run), "level": float(run.levels[1]), "rows": rows}


def pipeline_profile(run: TransitionRun, work_dir, settings=None) -> tuple[np.ndarray, np.ndarray]:
    """(bin centres m, ``sleeper_amp`` m/s²) of wheel 11 from the real pipeline (``run_pipeline``) with
    ``settings`` (default: the product's defaults), the signal written as a canonical run."""
    from pathlib import Path

    from physics_runs import write_run

    from app.analysis.settings import ProcessingSettings
    from app.pipeline import run_pipeline

    work = Path(work_dir)
    work.mkdir(parents=True, exist_ok=True)
    res = run_pipeline(write_run(work / "run.h5", run.z, run.fs, run.speed), settings or ProcessingSettings(),
                       work / "chunks")
    p = res.profiles[res.profiles["wheel"] == "11"].sort_values("bin")
    return (p["bin"].to_numpy() + 0.5) * 0.25, p["sleeper_amp"].to_numpy()
