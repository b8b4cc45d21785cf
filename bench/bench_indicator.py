"""Indicator benchmark: spatial resolution and accuracy of the sleeper-passage amplitude (issue 15).

Usage::

    .venv/bin/python bench/bench_indicator.py            # sweep + the default through the pipeline
    .venv/bin/python bench/bench_indicator.py --plot     # only docs/img/indicator-resolution.png
                                                         # (needs matplotlib: pip install -e .[bench])

Signals are built from the physics reference runs (bench/physics_runs.py: steady bays tiled,
stiffness steps and 6 m soft spots spliced at a sleeper, optionally a 90 µm order-5 wheel polygon
added). For every ``track_resolution_m`` of the sweep (and the old shared 0.1-order band) the order
recipe of those settings extracts the orders (the product's VKF, one solve), the sleeper amplitude is
averaged per 25 cm bin, and the targets are measured:

* step: 10–90 % width (≤ 6 m), 50 % point offset from the splice (≤ 2 m), ringing = largest
  excursion beyond the two levels as a share of the step (≤ 10 %);
* 6 m soft spot: share of its true amplitude change kept at its centre (≥ 70 %);
* uniform track: the amplitude with the polygon present against the lock-in truth (≤ 5 %).

Prints Markdown tables for BENCHMARKS.md.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from physics_runs import D_S, cases, polygon, steady_unit  # noqa: E402

from app.analysis.recipe import order_recipe  # noqa: E402
from app.analysis.settings import LEGACY_VALUES, ProcessingSettings  # noqa: E402

BIN = 0.25
LEAD_M = 60.0  # track before and after a feature, m
SPEEDS = (20, 35, 50)
#: (normal, other) ballast stiffness pairs, MN/m
PAIRS = ((40, 160), (160, 40), (80, 20), (20, 80))


def _units(v: int, k: int) -> tuple[np.ndarray, float, float, int]:
    return steady_unit(f"grid_k{k}_v{v}.npz")


def _bays(unit: np.ndarray, nb: int, count: int) -> np.ndarray:
    """``count`` whole bays cut from a tiled unit."""
    m = unit.size // nb
    reps = -(-count // nb)
    return np.tile(unit, reps)[: count * m]


def build(v: int, k_a: int, k_b: int, feature_bays: int | None) -> tuple[np.ndarray, float, float, float]:
    """Signal of k_a track, then k_b (a step; or ``feature_bays`` of k_b and k_a again: a spot).

    Returns (z, fs, speed, x of the splice in m).
    """
    ua, va, fs, na = _units(v, k_a)
    ub, _, _, nb = _units(v, k_b)
    lead = int(round(LEAD_M / D_S))
    parts = [_bays(ua, na, lead)]
    parts.append(_bays(ub, nb, lead if feature_bays is None else feature_bays))
    if feature_bays is not None:
        parts.append(_bays(ua, na, lead))
    if parts[1].size // (lead if feature_bays is None else feature_bays) != parts[0].size // lead:
        raise ValueError("units of one speed must have equal samples per bay")
    return np.concatenate(parts), fs, va, lead * D_S


def profile(z: np.ndarray, fs: float, v: float, settings: ProcessingSettings) -> tuple[np.ndarray, np.ndarray]:
    """(bin centres m, sleeper amplitude per 25 cm bin m/s²) of one solve with the settings' recipe."""
    recipe = order_recipe(0.92, D_S, settings)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = recipe.solve(z, fs, np.full(z.size, v))
    step = max(1, int(fs * 0.05 / v))
    idx = np.arange(0, z.size, step)
    amp = np.abs(res.envelope_at(idx)[recipe.sleeper_row])
    x = idx * v / fs
    b = np.floor(x / BIN).astype(int)
    sums = np.bincount(b, amp)
    cnt = np.bincount(b)
    return (np.arange(sums.size) + 0.5) * BIN, sums / np.maximum(cnt, 1)


def step_metrics(x: np.ndarray, a: np.ndarray, x0: float, a1: float, a2: float) -> dict[str, float]:
    """10–90 % width, 50 % offset and ringing of a step from a1 to a2 at x0.

    ``s = (a − a1)/(a2 − a1)`` over ±30 m; the 90 % point is where ``s`` first reaches 0.9, the
    10 % point where it last was below 0.1 before that, the 50 % point between them; ringing is
    the largest excursion of ``s`` beyond [0, 1] (a dip of the amplitude where the envelope's
    phase jumps at the splice counts too).
    """
    sel = (x > x0 - 30) & (x < x0 + 30)
    xs, s = x[sel], (a[sel] - a1) / (a2 - a1)
    i90 = int(np.argmax(s >= 0.9))
    below = np.flatnonzero(s[:i90] < 0.1)
    i10 = int(below[-1]) if below.size else 0
    x10 = float(np.interp(0.1, [s[i10], s[i10 + 1]], [xs[i10], xs[i10 + 1]]))
    x90 = float(np.interp(0.9, [s[i90 - 1], s[i90]], [xs[i90 - 1], xs[i90]]))
    seg = slice(i10, i90 + 1)
    i50 = i10 + int(np.argmax(s[seg] >= 0.5))
    x50 = float(np.interp(0.5, [s[i50 - 1], s[i50]], [xs[i50 - 1], xs[i50]]))
    ring = max(float(s.max() - 1.0), float(-s.min()), 0.0)
    return {"width": x90 - x10, "offset": x50 - x0, "ringing": ring}


def spot_depth(x: np.ndarray, a: np.ndarray, x0: float, length: float, a1: float, a2: float) -> float:
    """Share of the true change a1 → a2 kept at the centre of a spot [x0, x0 + length]."""
    c = (x > x0 + length / 2 - 0.5) & (x < x0 + length / 2 + 0.5)
    return float((np.mean(a[c]) - a1) / (a2 - a1))


def settings_for(res_m: float | None) -> ProcessingSettings:
    if res_m is None:
        return ProcessingSettings(**LEGACY_VALUES)
    return ProcessingSettings(track_resolution_m=res_m)


def sweep(resolutions: list[float | None], with_polygon: bool) -> list[dict]:
    c = cases()
    rows = []
    for res_m in resolutions:
        st = settings_for(res_m)
        widths, offsets, rings, depths, errs = [], [], [], [], []
        for v in SPEEDS:
            for k_a, k_b in PAIRS:
                a1, a2 = c[f"grid_k{k_a}_v{v}.npz"]["A_lockin"], c[f"grid_k{k_b}_v{v}.npz"]["A_lockin"]
                if abs(a2 - a1) < 0.25 * max(a1, a2):
                    continue  # no amplitude step to resolve at this speed (the indicator is blind here)
                z, fs, sp, x0 = build(v, k_a, k_b, None)
                if with_polygon:
                    z = z + polygon(z.size, fs, sp)
                x, a = profile(z, fs, sp, st)
                m = step_metrics(x, a, x0, a1, a2)
                widths.append(m["width"])
                offsets.append(abs(m["offset"]))
                rings.append(m["ringing"])
                z, fs, sp, x0 = build(v, k_a, k_b, 10)  # a 6 m spot
                if with_polygon:
                    z = z + polygon(z.size, fs, sp)
                x, a = profile(z, fs, sp, st)
                depths.append(spot_depth(x, a, x0, 10 * D_S, a1, a2))
            for k in (40, 160):  # uniform track: amplitude against the lock-in truth
                u, sp, fs, nb = _units(v, k)
                z = _bays(u, nb, 200)
                if with_polygon:
                    z = z + polygon(z.size, fs, sp)
                x, a = profile(z, fs, sp, st)
                inner = (x > 20) & (x < x[-1] - 20)
                errs.append(abs(np.mean(a[inner]) / c[f"grid_k{k}_v{v}.npz"]["A_lockin"] - 1))
        rows.append({"resolution": res_m, "polygon": with_polygon, "n": len(widths),
                     "width_max": max(widths), "width_med": float(np.median(widths)),
                     "offset_max": max(offsets), "ringing_max": max(rings), "depth_min": min(depths),
                     "uniform_err_max": max(errs)})
    return rows


def plot(path: Path) -> None:
    """Step and 6 m soft spot at 35 m/s (40 → 160 MN/m), default 3 m and the old 0.1-order band."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    c = cases()
    a1, a2 = c["grid_k40_v35.npz"]["A_lockin"], c["grid_k160_v35.npz"]["A_lockin"]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    for ax, bays, title in ((axes[0], None, "stiffness step 40 → 160 MN/m at x = 0"),
                            (axes[1], 10, "6 m soft spot: 40 MN/m inside 160 MN/m")):
        ka, kb = (40, 160) if bays is None else (160, 40)
        z, fs, sp, x0 = build(35, ka, kb, bays)
        true_x = np.array([-30.0, 0.0, 0.0, 30.0]) if bays is None else np.array([-20, 0, 0, 6, 6, 26.0])
        lv = (a1, a2) if bays is None else (a2, a1)
        true_a = [lv[0], lv[0], lv[1], lv[1]] if bays is None else [lv[0], lv[0], lv[1], lv[1], lv[0], lv[0]]
        ax.plot(true_x, true_a, "k--", lw=1, label="truth (lock-in of the physics runs)")
        for res_m, style in ((2.0, "-"), (3.0, "-"), (6.0, "-"), (None, ":")):
            x, a = profile(z, fs, sp, settings_for(res_m))
            name = "0.1 wheel orders (before)" if res_m is None else f"track_resolution_m = {res_m:g}"
            sel = (x - x0 > -30) & (x - x0 < 30)
            ax.plot(x[sel] - x0, a[sel], style, lw=1.5, label=name)
        ax.set_title(title)
        ax.set_xlabel("position along the track, m")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("sleeper-passage amplitude, m/s²  (35 m/s, 25 cm bins)")
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--resolutions", default="2,3,4,5,6,legacy")
    ap.add_argument("--plot", action="store_true", help="write docs/img/indicator-resolution.png only")
    args = ap.parse_args()
    if args.plot:
        out = Path(__file__).resolve().parents[1] / "docs" / "img" / "indicator-resolution.png"
        plot(out)
        print(f"wrote {out}")
        return
    res = [None if r == "legacy" else float(r) for r in args.resolutions.split(",")]
    print("| track_resolution_m | 90 µm order-5 polygon | steps | 10–90 % width max / median m | "
          "50 % offset max m | ringing max | 6 m spot depth kept min | uniform amplitude error max |")
    print("|---|---|---|---|---|---|---|---|")
    for poly in (False, True):
        for r in sweep(res, poly):
            name = "legacy (0.1 orders)" if r["resolution"] is None else f"{r['resolution']:g}"
            print(f"| {name} | {'yes' if poly else 'no'} | {r['n']} | {r['width_max']:.2f} / {r['width_med']:.2f} | "
                  f"{r['offset_max']:.2f} | {r['ringing_max']:.1%} | {r['depth_min']:.0%} | {r['uniform_err_max']:.2%} |")


if __name__ == "__main__":
    main()
