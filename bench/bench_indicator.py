"""Indicator benchmark: spatial resolution and accuracy of the sleeper-passage amplitude (issues 15, 26).

Usage::

    .venv/bin/python bench/bench_indicator.py                  # transitions, then the spliced sweep
    .venv/bin/python bench/bench_indicator.py --only transitions
    .venv/bin/python bench/bench_indicator.py --only spliced --resolutions 2,3,4
    .venv/bin/python bench/bench_indicator.py --diagnose       # controlled experiments: why it rang
    .venv/bin/python bench/bench_indicator.py --plot           # docs/img/indicator-resolution.png and
                                                               # docs/img/indicator-transitions.png
                                                               # (needs matplotlib: pip install -e .[bench])

**Transitions as physics makes them** (issue 26; bench/physics_transitions.py): the transition runs
of ../shared/physics (trans2_v30, trans2_v42) as they are, the same runs inside 1000 m of their own
first and last segment (constructed: the service's chunks are 1.5–3 km long), and transitions
constructed from the uniform runs at 35 and 50 m/s with the two responses cross-faded over 3 m
(the phase turns over metres). Each is written as a canonical run and processed by the real
pipeline with the default settings; the profile is compared with the per-bay truth (10–90 %
width, rise width, 50 % point, ringing, level errors 10–20 m from the edges; the physics' own widths
from ``A_bay``), and the track's content at the wheel-order-5 line over the record is printed (what
a wheel order estimated from that record cannot tell from a polygon).

**Spliced steps** (issue 15):

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
from physics_transitions import (  # noqa: E402
    _segment_levels,
    blended_run,
    edge_metrics,
    embedded_run,
    evaluate,
    meets_targets,
    physics_run,
    pipeline_profile,
    soft_level_cause,
    wheel5_projection,
)

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


#: constructed transitions from the uniform runs: (speed, k_a, k_b), segments 37.2 / 24.6 / 60 m inside 500 m
BLENDED = ((35, 40, 160), (35, 80, 20), (50, 40, 160), (50, 20, 80))
BLENDED_SEGMENTS_M = [37.2, 24.6, 60.0]


def transition_cases() -> list:
    """The transition test signals of the bench (and of tests/pipeline/test_indicator_physics.py)."""
    runs = [physics_run("trans2_v30.npz"), physics_run("trans2_v42.npz"),
            embedded_run("trans2_v30.npz"), embedded_run("trans2_v42.npz")]
    runs += [blended_run(v, ka, kb, BLENDED_SEGMENTS_M) for v, ka, kb in BLENDED]
    return runs


def transitions() -> None:
    """Print the transitions table (Markdown) for BENCHMARKS.md."""
    import tempfile

    print("| case | wheel-5 line content m/s² | edge | 10–90 % width m (physics') | rise width m (physics') | "
          "50 % point m | ringing (physics') | level error 10–20 m from the edges, per segment | targets met |")
    print("|---|---|---|---|---|---|---|---|---|")
    for run in transition_cases():
        with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
            warnings.simplefilter("ignore")
            x, a = pipeline_profile(run, tmp)
        res = evaluate(x, a, run)
        met = meets_targets(res)
        levels = " / ".join("–" if not np.isfinite(v) else f"{v:+.1%}" for v in res["levels"])
        ok = ", ".join(k for k, v in met.items() if v) or "none"
        miss = ", ".join(k for k, v in met.items() if not v)
        name = run.name + (" (constructed)" if run.constructed else "")
        for j, e in enumerate(res["edges"]):
            p, q = e["product"], e["physics"]
            head = (f"{name} | {wheel5_projection(run):.3f} | " if j == 0 else " | | ")
            tail = f"{levels} | {ok}{'; not ' + miss if miss else ''} |" if j == 0 else " | |"
            print(f"| {head}{e['edge']:.1f} | {p['width']:.1f} ({q['width']:.1f}) | {p['rise']:.1f} ({q['rise']:.1f}) | "
                  f"{p['offset']:+.1f} | {p['ringing']:.1%} ({q['ringing']:.1%}) | {tail}")
    with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cause = soft_level_cause(tmp)
    print()
    print(f"trans2_v42, the 30 MN/m segment (level {cause['level']:.3f} m/s²): the stationary wheel order 5 of the record "
          f"{cause['line']:.3f} m/s² (the record's own content at that line {cause['record_content']:.3f} m/s²)")
    print()
    print("| window m | product `sleeper_amp` | physics A_bay | physics lock-in of the signal less that line |")
    print("|---|---|---|---|")
    for r in cause["rows"]:
        lo, hi = r["window"]
        print(f"| {lo:g}–{hi:g} | {r['product']:.3f} ({r['product'] / r['a_bay'] - 1:+.1%}) | {r['a_bay']:.3f} | "
              f"{r['lockin_less_line']:.3f} ({r['lockin_less_line'] / r['a_bay'] - 1:+.1%}) |")


def weak_steps(fe_files: list[Path], sigmas: tuple[float, ...] = (0.0, 0.5, 1.0, 2.0), seeds: tuple[int, ...] = (5, 6, 7),
               kappa: float = 8.0) -> None:
    """Small steps where the signal is weak (issue 33): FE step runs of the harness (``--ks 80 52 --edges 200
    --speed 50 --length 400``: 1.5 → 1.0 m/s²) with band-limited measurement noise of ``sigmas`` m/s² (the
    simulator's, 2 Hz … 0.4 fs), processed once per noise draw and assembled without and with the
    edge-preserving smoothing (``edge_preserving_sd`` 0 and ``kappa``)."""
    import tempfile

    from physics_runs import write_run

    from app.pipeline import assemble
    from app.pipeline import run_pipeline as run_pl
    from app.simulate.noise import BandLimitedNoise

    default = float(kappa)
    print(f"| FE run | noise m/s² | draws | 10–90 % width m, off → edge-preserving {default:g} σ (max) | ringing "
          "(max) | rise width m (max) | level error 10–190 m / 210–390 m (max) |")
    print("|---|---|---|---|---|---|---|")
    for path in fe_files:
        d = np.load(path)
        z0, fs, v = d["a_axle"], float(d["fs"]), float(d["speed"])
        edges = np.asarray(d["edges"], dtype=float)
        bounds = np.r_[0.0, edges, float(d["x"][-1])]
        levels = _segment_levels(np.asarray(d["x_bay"]), np.asarray(d["A_bay"]), bounds)
        for sigma in sigmas:
            rows: dict[float, list[dict]] = {0.0: [], default: []}
            for seed in (seeds if sigma > 0 else seeds[:1]):
                noise = BandLimitedNoise(np.random.default_rng(seed), fs, sigma, (2.0, 0.4 * fs)).next(z0.size) \
                    if sigma > 0 else 0.0
                with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    run = write_run(Path(tmp) / "run.h5", z0 + noise, fs, v)
                    run_pl(run, ProcessingSettings(), Path(tmp) / "c")
                    for kappa in rows:
                        res = assemble(run, ProcessingSettings(edge_preserving_sd=kappa),
                                       sorted((Path(tmp) / "c").glob("chunk-*.npz")))
                        p = res.profiles[res.profiles["wheel"] == "11"].sort_values("bin")
                        x, a = (p["bin"].to_numpy() + 0.5) * 0.25, p["sleeper_amp"].to_numpy()
                        m = edge_metrics(x, a, float(edges[0]), levels[0], levels[1])
                        m["level"] = max(abs(float(np.mean(a[(x > lo) & (x < hi)])) / lv - 1.0) for (lo, hi), lv in
                                         zip(((10.0, edges[0] - 10.0), (edges[0] + 10.0, bounds[-1] - 10.0)), levels,
                                             strict=True))
                        rows[kappa].append(m)

            def worst(k: str, kappa: float, rows: dict[float, list[dict]] = rows) -> float:
                return max(r[k] for r in rows[kappa])
            print(f"| {path.name} ({levels[0]:.2f} → {levels[1]:.2f} m/s²) | {sigma:g} | {len(rows[0.0])} | "
                  f"{worst('width', 0.0):.1f} → {worst('width', default):.1f} | {worst('ringing', 0.0):.1%} → "
                  f"{worst('ringing', default):.1%} | {worst('rise', 0.0):.1f} → {worst('rise', default):.1f} | "
                  f"{worst('level', 0.0):.1%} → {worst('level', default):.1%} |", flush=True)


def _binned(env: np.ndarray, idx: np.ndarray, fs: float, v: float) -> tuple[np.ndarray, np.ndarray]:
    """25 cm bin means of |env| at sample indices ``idx`` (constant speed ``v``)."""
    b = np.floor(idx * v / fs / BIN).astype(int)
    return (np.arange(b.max() + 1) + 0.5) * BIN, np.bincount(b, np.abs(env)) / np.maximum(np.bincount(b), 1)


def diagnose() -> None:
    """Controlled experiments on the two transition runs (why the joint solve rang; issue 26).

    One solve per variant (``vkf`` on the run as it is, the default recipe's orders and bandwidths unless
    said), and an independent sparse solve of Eq. 20 (tests/vkf/reference_vkf.py: scipy.sparse + SuperLU,
    refined in extended precision) of the signal decimated to 2 kHz.
    """
    from scipy.signal import decimate

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "vkf"))
    from reference_vkf import carrier_phase, reference_vkf, weight_from_bandwidth

    from app.analysis.vkf import vkf

    recipe = order_recipe(0.92, D_S, ProcessingSettings())
    labels = list(recipe.labels)
    wheel = [i for i, x in enumerate(labels) if x.isdigit()]
    print("| run | variant | ringing per edge | level error per segment (10–20 m from the edges) |")
    print("|---|---|---|---|")
    for name in ("trans2_v30.npz", "trans2_v42.npz"):
        run = physics_run(name)
        v = np.full(run.z.size, run.speed)
        step = max(1, int(run.fs * 0.05 / run.speed))
        idx = np.arange(0, run.z.size, step)
        f, b = recipe.multipliers * run.speed, recipe.bandwidths(v)[:, 0]

        def joint(rows: list[int], bw: np.ndarray = b, real: bool = True, run=run, f=f, idx=idx) -> np.ndarray:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                res = vkf(run.z, run.fs, f[rows], bw[rows], recipe.filter_order, chunk_duration=np.inf,
                          phase0=np.zeros(len(rows)), real_signal=real)
            return res.envelope_at(idx)[0]

        narrow = b.copy()
        narrow[wheel] *= 0.1
        variants = [
            ("product (wheel orders in the track band stationary)",
             recipe.solve(run.z, run.fs, v).envelope_at(idx)[recipe.sleeper_row]),
            ("joint solve of the 14 orders (before issue 26)", joint(list(range(len(labels))))),
            ("joint, no wheel orders", joint([i for i in range(len(labels)) if i not in wheel])),
            ("joint, all but wheel order 5", joint([i for i in range(len(labels)) if labels[i] != "5"])),
            ("joint, f_s and wheel order 5 only", joint([0, labels.index("5")])),
            ("joint, Eq. 20 as written (no mirror images, no image refinement)",
             joint(list(range(len(labels))), real=False)),
            ("joint, wheel orders 0.01 orders wide", joint(list(range(len(labels))), narrow)),
        ]
        rows = [(label, *_binned(env, idx, run.fs, run.speed)) for label, env in variants]
        dec = 5
        y = decimate(run.z, dec, ftype="fir", zero_phase=True)
        fs2, n2 = run.fs / dec, y.size
        for label, sel in (("sparse reference of Eq. 20, f_s and wheel order 5", [0, labels.index("5")]),
                           ("sparse reference of Eq. 20, f_s alone", [0])):
            phi = carrier_phase(np.repeat(f[sel][:, None], n2, axis=1), fs2)
            a = reference_vkf(y, phi, weight_from_bandwidth(b[sel], fs2, recipe.filter_order), recipe.filter_order,
                              refine=3)
            rows.append((label, *_binned(2.0 * a[0], np.arange(n2) * dec, run.fs, run.speed)))
        for label, x, a in rows:
            res = evaluate(x, a, run)
            ring = " / ".join(f"{e['product']['ringing']:.1%}" for e in res["edges"])
            lv = " / ".join(f"{v:+.1%}" for v in res["levels"])
            print(f"| {name} | {label} | {ring} | {lv} |")


def plot_transitions(path: Path) -> None:
    """The two transition runs as they are (left) and inside 1000 m of their own track (right): per-bay
    truth, the product, and wheel order 5 solved jointly with the track orders (before issue 26)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from app.analysis.vkf import vkf

    recipe = order_recipe(0.92, D_S, ProcessingSettings())
    fig, axes = plt.subplots(2, 2, figsize=(14, 7.5), sharey="row")
    for row, name in enumerate(("trans2_v30.npz", "trans2_v42.npz")):
        for col, run in enumerate((physics_run(name), embedded_run(name))):
            ax = axes[row, col]
            v = np.full(run.z.size, run.speed)
            step = max(1, int(run.fs * 0.05 / run.speed))
            x0 = run.edges[0] - 40.0
            idx = np.arange(0, run.z.size, step)
            idx = idx[(idx * run.speed / run.fs > x0) & (idx * run.speed / run.fs < x0 + 160.0)]
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                now = recipe.solve(run.z, run.fs, v).envelope_at(idx)[recipe.sleeper_row]
                joint = vkf(run.z, run.fs, recipe.frequencies(v), recipe.bandwidths(v), recipe.filter_order,
                            chunk_duration=np.inf, phase0=recipe.phase0(0.0)).envelope_at(idx)[recipe.sleeper_row]
            x = idx * run.speed / run.fs - x0
            ax.plot(run.x_bay - x0, run.a_bay, "k.", ms=3, label="physics: per-bay amplitude (A_bay)")
            ax.plot(x, np.abs(joint), ":", lw=1.3, label="wheel order 5 solved jointly (before issue 26)")
            ax.plot(x, np.abs(now), "-", lw=1.5, label="product: wheel orders in the track band stationary")
            for lo, hi, lv in zip(run.bounds[:-1], run.bounds[1:], run.levels, strict=True):
                ax.hlines(lv, max(lo - x0, 0.0), min(hi - x0, 160.0), colors="r", lw=0.6)
            where = "the 160 m run as it is" if col == 0 else "inside 1000 m of its own track (constructed)"
            ax.set_title(f"{name} ({run.speed:.3g} m/s): {where}", fontsize=10)
            ax.set_xlim(0, 160)
            ax.grid(alpha=0.3)
            if "v42" in name:
                ax.set_yscale("log")
        axes[row, 0].set_ylabel("sleeper-passage amplitude, m/s²")
    for ax in axes[1]:
        ax.set_xlabel("position along the transition run, m (edges at 40 / 80 / 120 m; red: steady lock-in)")
    axes[0, 0].legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--resolutions", default="2,3,4,5,6,legacy")
    ap.add_argument("--only", choices=("transitions", "spliced", "weak-steps"), default=None)
    ap.add_argument("--fe-step", type=Path, nargs="*", default=[],
                    help="--only weak-steps: FE step runs of the harness (../shared/physics/harness)")
    ap.add_argument("--diagnose", action="store_true",
                    help="only the controlled experiments on the two transition runs (why the joint solve rang)")
    ap.add_argument("--plot", action="store_true",
                    help="write docs/img/indicator-resolution.png and docs/img/indicator-transitions.png only")
    args = ap.parse_args()
    if args.plot:
        img = Path(__file__).resolve().parents[1] / "docs" / "img"
        plot(img / "indicator-resolution.png")
        plot_transitions(img / "indicator-transitions.png")
        print(f"wrote {img}/indicator-resolution.png, indicator-transitions.png")
        return
    if args.diagnose:
        diagnose()
        return
    if args.only == "weak-steps":
        weak_steps(args.fe_step)
        return
    if args.only != "spliced":
        transitions()
        print()
    if args.only == "transitions":
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
