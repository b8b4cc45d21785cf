"""Speed conditioning (issue 15 items 4, 5, 7): resonance model vs physics, index agreement, power law.

Parts (all printed as Markdown tables; plots written to ``--img-dir``):

physics   the wheel-on-discretely-supported-rail model (app.analysis.stiffness.track_dynamics)
          against the independent FE runs of ``--physics`` (cases.csv amplitudes, frf.npz);
index     two simulated runs of one line at different random speed profiles (resonance model),
          processed by the real pipeline: stiffness index agreement vs raw amplitude, with and
          without superstructure classes, two noise levels, and a same-speed-profile baseline;
powerlaw  the power-law option on the same runs: exponents, intervals, instability flags;
wheels    per-wheel offsets, with and without a 20 % gain error injected on Z41;
demo      the demo's single run: power-law exponents per superstructure type;
timing    the reference-curve fit on the runs above and on 640 000 synthetic rows;
stiffness support stiffness (MN/m) from passes at several speeds on the physics sweeps.

Usage::

    .venv/bin/python bench/bench_speed_conditioning.py --physics ../shared/physics --img-dir docs/img
    .venv/bin/python bench/bench_speed_conditioning.py --parts physics,stiffness
"""

from __future__ import annotations

import argparse
import csv
import itertools
import math
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from app.analysis.settings import ProcessingSettings
from app.analysis.stiffness.reference_curve import fit_reference_from_rows
from app.analysis.stiffness.speed_norm import (
    MAX_POWER_LAW_MISFIT,
    fit_speed_exponent,
    power_law_misfit,
)
from app.analysis.stiffness.stiffness_index import stiffness_index
from app.analysis.stiffness.superstructure import section_classes
from app.analysis.stiffness.support_stiffness import (
    estimate_support_stiffness,
    model_log_amplitudes,
)
from app.analysis.stiffness.track_dynamics import (
    TrackParameters,
    resonance_frequency,
    sleeper_passage_amplitude,
    wheel_accelerance,
)
from app.pipeline import run_pipeline
from app.simulate.run import simulate_run
from app.simulate.speed import SpeedProfile
from app.simulate.track import SUPERSTRUCTURE_TYPES, generate_line

WHEELS = ("11", "12", "41", "42")
EDGE_TRIM_M = 50.0
MIN_SPEED_MPS = 25 / 3.6


def _table(header: list[str], rows: list[list]) -> str:
    def f(x):
        if isinstance(x, float):
            return "–" if not math.isfinite(x) else f"{x:.3g}" if abs(x) < 1000 else f"{x:.0f}"
        return str(x)

    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(f(x) for x in r) + " |" for r in rows]
    return "\n".join(out)


# --- physics -------------------------------------------------------------------------------


def _cases(physics: Path) -> list[dict]:
    with open(physics / "cases.csv") as fh:
        return [{k: (v if k == "file" else float(v)) for k, v in r.items()} for r in csv.DictReader(fh)]


def part_physics(physics: Path, img: Path | None) -> None:
    cases = _cases(physics)
    rows, ratios = [], {1: [], 2: [], 3: []}
    for c in sorted(cases, key=lambda c: (c["k_MNm"], c["v"])):
        p = TrackParameters(ballast_stiffness=c["k_MNm"] * 1e6)
        a = [float(sleeper_passage_amplitude(p, np.array([c["v"]]), h)[0]) for h in (1, 2, 3)]
        r = [a[0] / c["A_lockin"], a[1] / c["A2"], a[2] / c["A3"]]
        for h in (1, 2, 3):
            ratios[h].append(r[h - 1])
        rows.append([int(c["k_MNm"]), c["v"], c["A_lockin"], a[0], r[0], c["A2"], a[1], r[1], c["A3"], a[2], r[2]])
    print("\n### Sleeper-passage amplitudes: own model vs physics runs (cases.csv)\n")
    print(_table(["k MN/m", "v m/s", "A1 physics", "A1 model", "ratio", "A2 physics", "A2 model", "ratio",
                  "A3 physics", "A3 model", "ratio"], rows))
    print("\n| harmonic | median ratio | range | within ±20 % |\n|---|---|---|---|")
    for h, r in ratios.items():
        r = np.array(r)
        print(f"| {h} | {np.median(r):.3f} | {r.min():.2f} … {r.max():.2f} | "
              f"{np.mean(np.abs(r - 1) <= 0.2):.0%} of {r.size} |")
    frf = np.load(physics / "frf.npz")
    f = frf["freqs"]
    print("\n### Coupled wheel–track resonance (lowest local maximum of the wheel accelerance a/r, 20–150 Hz)\n")
    res_rows = []
    for k in (20, 40, 60, 80, 110, 160, 320):
        h = frf[f"H_{k}_sleeper"]
        band = (f >= 20) & (f <= 150)
        fb, hb = f[band], h[band]
        peaks = np.flatnonzero((hb[1:-1] > hb[:-2]) & (hb[1:-1] >= hb[2:])) + 1
        mine = resonance_frequency(TrackParameters(ballast_stiffness=k * 1e6))
        model_h = wheel_accelerance(TrackParameters(ballast_stiffness=k * 1e6), np.array([30.0, 60.0, 100.0, 200.0]),
                                    position_m=0.0)
        phys_h = np.interp([30.0, 60.0, 100.0, 200.0], f, h)
        res_rows.append([k, float(fb[peaks[0]]) if peaks.size else float("nan"), mine,
                         *[float(m / q) for m, q in zip(model_h, phys_h, strict=True)]])
    print(_table(["k MN/m", "physics Hz", "model Hz", "a/r model/physics 30 Hz", "60 Hz", "100 Hz", "200 Hz"], res_rows))
    if img is None:
        return
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.6))
    v = np.linspace(12, 62, 200)
    for k, color in ((40, "tab:green"), (80, "tab:blue"), (160, "tab:orange"), (320, "tab:red")):
        p = TrackParameters(ballast_stiffness=k * 1e6)
        axes[0].plot(v * 3.6, sleeper_passage_amplitude(p, v), color=color, label=f"model {k} MN/m")
        pts = [c for c in cases if c["k_MNm"] == k]
        axes[0].plot([c["v"] * 3.6 for c in pts], [c["A_lockin"] for c in pts], "o", color=color, mfc="none",
                     label=f"physics {k} MN/m")
    axes[0].set_yscale("log")
    axes[0].set_xlabel("Speed (km/h)")
    axes[0].set_ylabel("Sleeper-passage amplitude (m/s²)")
    axes[0].set_title("A(k, v): a resonance swept by f_s = v / 0.6 m")
    axes[0].legend(fontsize=7, ncol=2)
    for k, color in ((20, "tab:purple"), (80, "tab:blue"), (320, "tab:red")):
        axes[1].plot(f, frf[f"H_{k}_sleeper"], color=color, lw=2, alpha=0.4, label=f"physics {k} MN/m")
        axes[1].plot(f, wheel_accelerance(TrackParameters(ballast_stiffness=k * 1e6), f, position_m=0.0), "--",
                     color=color, label=f"model {k} MN/m")
    axes[1].set_yscale("log")
    axes[1].set_xlabel("Frequency (Hz)")
    axes[1].set_ylabel("|a / r| wheel above a sleeper (m/s² per m)")
    axes[1].set_title("Wheel accelerance to roughness")
    axes[1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(img / "resonance-vs-physics.png", dpi=110)
    plt.close(fig)


# --- simulated runs through the pipeline ---------------------------------------------------


def _line(one_type: bool):
    if one_type:
        from app.simulate.track import TrackSection

        return generate_line(11_900.0, 16_100.0, np.random.default_rng([9, 7]), anomaly_range_m=(12_100.0, 15_950.0),
                             sections=[TrackSection(11_900.0, 16_100.0, "b91_no_pads")])
    return generate_line(11_900.0, 16_100.0, np.random.default_rng([9, 7]), anomaly_range_m=(12_100.0, 15_950.0))


def _process(work: Path, line, tag: str, noise: float, profile_seeds: tuple[int, int],
             track_resolution_m: float | None = None) -> pd.DataFrame:
    frames = []
    for name, seed, ps in (("A", 31, profile_seeds[0]), ("B", 32, profile_seeds[1])):
        path = work / f"{tag}-{name}.h5"
        prof = SpeedProfile.random(ps, length_m=4100.0, v_min_kmh=60.0, v_max_kmh=180.0)
        simulate_run(path, length_km=4.0, fs=2000.0, seed=seed, line=line, noise_std=noise, speed_profile=prof)
        settings = ProcessingSettings() if track_resolution_m is None else \
            ProcessingSettings(track_resolution_m=track_resolution_m)
        res = run_pipeline(path, settings, work / f"work-{tag}-{name}")
        df = res.profiles.copy()
        lo = df.groupby("wheel")["bin"].transform("min")
        hi = df.groupby("wheel")["bin"].transform("max")
        k = EDGE_TRIM_M / 0.25
        df = df[(df["bin"] >= lo + k) & (df["bin"] <= hi - k) & (df["speed_mean"] >= MIN_SPEED_MPS)]
        frames.append(df.assign(run=name))
    return pd.concat(frames, ignore_index=True)


def _classes(line, x: np.ndarray, with_sections: bool) -> np.ndarray:
    if not with_sections:
        return np.full(x.size, "", dtype=object)
    return section_classes(x, np.array([s.track_from_m for s in line.sections]),
                           np.array([s.track_to_m for s in line.sections]),
                           np.array([s.type for s in line.sections], dtype=object), boundary_margin_m=50.0)


def _index(df: pd.DataFrame, line, with_sections: bool, gain: dict[str, float] | None = None):
    amp = df["sleeper_amp"].to_numpy().copy()
    for w, g in (gain or {}).items():
        amp[df["wheel"].to_numpy() == w] *= g
    x = (df["bin"].to_numpy() + 0.5) * 0.25
    cls = _classes(line, x, with_sections)
    wheel = df["wheel"].astype(str).to_numpy(dtype=object)
    t0 = time.perf_counter()
    ref = fit_reference_from_rows(amp, df["speed_mean"].to_numpy(), x, df["run"].to_numpy(), wheel,
                                  np.array([w[-1] for w in wheel], dtype=object), cls)
    fit_s = time.perf_counter() - t0
    idx = stiffness_index(amp, df["speed_mean"].to_numpy(), cls, ref)
    return ref, df.assign(idx=idx.index, la=np.log(amp), se=idx.se), fit_s


def _agreement(df: pd.DataFrame) -> list[list]:
    rows = []
    for w in WHEELS:
        a = df[(df.run == "A") & (df.wheel == w)].set_index("bin")
        b = df[(df.run == "B") & (df.wheel == w)].set_index("bin")
        j = a.index.intersection(b.index)
        ia, ib = a.loc[j, "idx"], b.loc[j, "idx"]
        ok = np.isfinite(ia) & np.isfinite(ib)
        ra, rb = a.loc[j, "la"][ok], b.loc[j, "la"][ok]
        seg = j.to_numpy()[ok.to_numpy()] // int(100 / 0.25)  # 100 m segments: the index's mean per run
        sa, sb = ia[ok].groupby(seg).mean(), ib[ok].groupby(seg).mean()
        rows.append([w, float(ok.mean()), float(np.corrcoef(ia[ok], ib[ok])[0, 1]),
                     float(np.median(np.abs(ia[ok] - ib[ok]))), float(np.corrcoef(sa, sb)[0, 1]),
                     float(np.corrcoef(ra, rb)[0, 1]),
                     float(np.median(np.abs(ra - rb))), float(np.median(a.loc[j, "se"][ok]))])
    return rows


def part_index(work: Path, img: Path | None, only: list[str] | None = None) -> dict:
    out = {}
    mixed, one = _line(False), _line(True)
    scenarios = [
        ("mixed line, sections imported, noise 0.5 m/s²", "n05", mixed, True, 0.5, (31, 32)),
        ("mixed line, no sections (one line curve), noise 0.5 m/s²", "n05", mixed, False, 0.5, (31, 32)),
        ("one superstructure type, no sections, noise 0.5 m/s²", "one", one, False, 0.5, (31, 32)),
        ("mixed line, sections imported, noise 1.0 m/s²", "n10", mixed, True, 1.0, (31, 32)),
        ("baseline: SAME speed profile, sections, noise 1.0 m/s²", "same", mixed, True, 1.0, (31, 31)),
        ("baseline: SAME speed profile, sections, noise 0.5 m/s²", "same05", mixed, True, 0.5, (31, 31)),
        ("mixed line, sections, noise 0.5 m/s², track_resolution_m 6", "n05r6", mixed, True, 0.5, (31, 32), 6.0),
        ("baseline: SAME speed profile, sections, noise 0.5 m/s², track_resolution_m 6", "same05r6", mixed, True,
         0.5, (31, 31), 6.0),
    ]
    if only:
        scenarios = [s for s in scenarios if s[1] in only]
    cache: dict[str, pd.DataFrame] = {}
    for title, tag, line, sections, noise, seeds, *res in scenarios:
        if tag not in cache:
            t0 = time.perf_counter()
            cache[tag] = _process(work, line, tag, noise, seeds, *res)
            print(f"\n(simulated and processed two 4 km runs [{tag}] in {time.perf_counter() - t0:.1f} s)")
        ref, df, fit_s = _index(cache[tag], line, sections)
        out[(tag, sections)] = (ref, df, line)
        print(f"\n### Index agreement: {title} (reference fit {fit_s:.1f} s)\n")
        for c, cu in ref.curves.items():
            lo, hi = cu.speed_range_mps
            print(f"- curve {c or 'line'}: {cu.method}, {cu.n_samples} block passes, {lo * 3.6:.0f}–{hi * 3.6:.0f} km/h, "
                  f"spread {cu.spread:.3f}, repeatability {cu.repeatability:.3f}, "
                  f"median se {np.nanmedian(cu.log_amp_se):.3f}")
        print()
        print(_table(["wheel", "index coverage", "index Pearson", "index median abs Δ", "index Pearson 100 m",
                      "raw ln A Pearson",
                      "raw median abs Δ ln A", "median index se"], _agreement(df)))
    if img is not None:
        _plots_index(out, img)
    return out


def _plots_index(out: dict, img: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ref, df, line = out[("n05", True)]
    fig, axes = plt.subplots(3, 1, figsize=(12, 9), sharex=True)
    for run, color in (("A", "tab:blue"), ("B", "tab:orange")):
        d = df[(df.run == run) & (df.wheel == "11")]
        km = (d["bin"] + 0.5) * 0.25 / 1000
        axes[0].plot(km, d["speed_mean"] * 3.6, color=color, label=f"run {run}")
        axes[1].plot(km, d["sleeper_amp"], color=color, lw=0.8, label=f"run {run}")
        axes[2].plot(km, d["idx"], color=color, lw=0.8, label=f"run {run}")
    x = line.centres()
    axes[2].plot(x / 1000, np.log(line.factor[0]) - np.median(np.log(line.factor[0])), color="k", lw=0.6,
                 alpha=0.6, label="simulator's ln(stiffness factor), rail 1")
    for s in line.sections:
        for ax in axes:
            ax.axvline(s.track_from_m / 1000, color="grey", lw=0.5, ls=":")
        axes[1].text((s.track_from_m + s.track_to_m) / 2000, 0.2, s.type, ha="center", fontsize=8, color="grey")
    axes[0].set_ylabel("Speed (km/h)")
    axes[1].set_ylabel("Raw amplitude Z11 (m/s²)")
    axes[1].set_yscale("log")
    axes[2].set_ylabel("Stiffness index ln(A/A_ref) (–)")
    axes[2].set_xlabel("Track position (km)")
    axes[0].set_title("Two runs over one line at different speed profiles: raw amplitude differs, the index agrees")
    for ax in axes:
        ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    fig.savefig(img / "index-vs-raw.png", dpi=110)
    plt.close(fig)

    from app.simulate.amplitude import ResonanceResponse

    resp = ResonanceResponse()
    fig, ax = plt.subplots(figsize=(8, 5))
    colors = {"slab": "tab:red", "b91_no_pads": "tab:blue", "b91_pads": "tab:green"}
    for c, cu in ref.curves.items():
        ok = np.isfinite(cu.log_amp)
        v = np.exp(cu.log_speed[ok])
        ax.fill_between(v * 3.6, np.exp(cu.log_amp_low[ok]), np.exp(cu.log_amp_high[ok]), color=colors.get(c, "k"),
                        alpha=0.25)
        ax.plot(v * 3.6, np.exp(cu.log_amp[ok]), color=colors.get(c, "k"), label=f"A_ref {c} ({cu.method})")
        code = SUPERSTRUCTURE_TYPES.index(c)
        vv = np.linspace(15, 52, 200)
        truth = line.amplitude_vref[c] * resp.factor(np.full(vv.size, code), vv)
        ax.plot(vv * 3.6, truth, ls="--", color=colors.get(c, "k"), lw=0.8, label=f"simulator {c} (typical location)")
    ax.set_yscale("log")
    ax.set_xlabel("Speed (km/h)")
    ax.set_ylabel("Sleeper-passage amplitude (m/s²)")
    ax.set_title("Reference curves from two runs (band: 90 %) vs the simulator's speed response")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(img / "reference-curves.png", dpi=110)
    plt.close(fig)


def part_powerlaw(out: dict) -> None:
    rows = []
    for tag, title in (("n05", "noise 0.5"), ("n10", "noise 1.0")):
        ref, df, line = out[(tag, True)]
        x = (df["bin"].to_numpy() + 0.5) * 0.25
        cls = _classes(line, x, True)
        loc = df["wheel"].astype(str).to_numpy() + ":" + df["bin"].astype(str).to_numpy()
        for runs in (("A",), ("B",), ("A", "B")):
            m_run = df["run"].isin(runs).to_numpy()
            for c in [*sorted(ref.curves), "*"]:
                m = m_run & ((cls == c) if c != "*" else np.ones(len(df), bool))
                f = fit_speed_exponent(df["sleeper_amp"].to_numpy()[m], df["speed_mean"].to_numpy()[m], loc[m],
                                       reference_speed_mps=100 / 3.6, hac_lag=400)
                mis = power_law_misfit(ref.curves[c].log_speed, ref.curves[c].log_amp, f.exponent) \
                    if c in ref.curves else float("nan")
                if mis > MAX_POWER_LAW_MISFIT:
                    f = f.with_reason("not_power_law")
                rows.append([title, "+".join(runs), c, f.method, f.exponent, f"{f.exponent_ci[0]:.2f} … {f.exponent_ci[1]:.2f}",
                             mis, "stable" if f.stable else ", ".join(f.unstable_reasons)])
    print("\n### The power-law option on the same runs (truth: a resonance, no single exponent)\n")
    print(_table(["runs", "which", "class", "method", "exponent", "95 % interval", "curve misfit (ln)", "assessment"],
                 rows))


def part_wheels(out: dict) -> None:
    rows = []
    for label, gain in (("no gain error", None), ("Z41 gain +20 %", {"41": 1.2})):
        ref, _, _ = _index(out[("n05", True)][1].drop(columns=["idx", "la", "se"]), out[("n05", True)][2], True,
                           gain)
        for o in ref.wheel_offsets:
            rows.append([label, o.wheel, o.offset, f"{o.low:.3f} … {o.high:.3f}", o.n_samples])
        rows.append([label, "rail 2 − rail 1", ref.rail_difference, "", ""])
    print("\n### Per-wheel offsets (median residual against the other wheel of the rail, ln units)\n")
    print(_table(["case", "wheel", "offset", "90 % interval", "block passes"], rows))


def part_timing() -> None:
    rng = np.random.default_rng(0)
    x = (np.arange(40_000) + 0.5) * 0.25
    parts = {k: [] for k in ("a", "v", "x", "r", "w")}
    for r in range(4):
        v = 25 + 15 * np.sin(x / (2000 + 300 * r) + r)
        for w in WHEELS:
            parts["a"].append(v**1.5 * np.exp(0.1 * np.sin(x / 300) + 0.03 * rng.standard_normal(x.size)))
            parts["v"].append(v)
            parts["x"].append(x)
            parts["r"].append(np.full(x.size, r))
            parts["w"].append(np.full(x.size, w, dtype=object))
    d = {k: np.concatenate(v) for k, v in parts.items()}
    t0 = time.perf_counter()
    fit_reference_from_rows(d["a"], d["v"], d["x"], d["r"], d["w"], np.array([w[-1] for w in d["w"]], dtype=object),
                            np.full(d["a"].size, "", dtype=object))
    print(f"\n### Timing\n\nreference curves from {d['a'].size} rows (4 runs × 10 km × 4 wheels): "
          f"{time.perf_counter() - t0:.1f} s")


def part_demo(work: Path) -> None:
    """The demo's run (3 km, seed 7, resonance model; 2 kHz here instead of 10 kHz): one run, pooled fits."""
    path = work / "demo.h5"
    truth = simulate_run(path, length_km=3.0, fs=2000.0, seed=7, with_forces=False)
    df = run_pipeline(path, ProcessingSettings(), work / "work-demo").profiles
    lo = df.groupby("wheel")["bin"].transform("min")
    hi = df.groupby("wheel")["bin"].transform("max")
    df = df[(df["bin"] >= lo + 200) & (df["bin"] <= hi - 200) & (df["speed_mean"] >= MIN_SPEED_MPS)]
    x = (df["bin"].to_numpy() + 0.5) * 0.25
    cls = _classes(truth.line, x, True)
    loc = df["wheel"].astype(str).to_numpy() + ":" + df["bin"].astype(str).to_numpy()
    rows = []
    for c in [*sorted({s.type for s in truth.line.sections}), "*"]:
        m = (cls == c) if c != "*" else np.ones(len(df), bool)
        if m.sum() < 100:
            continue
        f = fit_speed_exponent(df["sleeper_amp"].to_numpy()[m], df["speed_mean"].to_numpy()[m], loc[m],
                               reference_speed_mps=100 / 3.6, hac_lag=400)
        v = df["speed_mean"].to_numpy()[m] * 3.6
        rows.append([c, f.method, f.exponent, f"{f.exponent_ci[0]:.2f} … {f.exponent_ci[1]:.2f}",
                     f"{v.min():.0f}–{v.max():.0f}", "stable" if f.stable else ", ".join(f.unstable_reasons)])
    print("\n### The demo run (one run, 3 km, resonance model): power-law exponents per type\n")
    print(_table(["type", "method", "exponent", "95 % interval", "speeds km/h", "assessment"], rows))


def part_stiffness(physics: Path) -> None:
    cases = _cases(physics)
    rows = []
    misspec = TrackParameters(pad_stiffness=150e6, pad_damping=56e3, ballast_damping=94e3)
    rng = np.random.default_rng(5)
    for k in (40, 80, 160):
        pts = sorted([c for c in cases if c["k_MNm"] == k], key=lambda c: c["v"])
        v = np.array([c["v"] for c in pts])
        a = np.array([c["A_lockin"] for c in pts])
        model = model_log_amplitudes(TrackParameters(), v)
        for label, kw in (("free scale", {"model": model}), ("absolute", {"model": model, "scale": "absolute"}),
                          ("free, pads 150 MN/m + damping ×2", {"params": misspec})):
            e = estimate_support_stiffness(v, a, **kw)
            rows.append([k, len(v), label, e.k_mnm, f"{e.k_interval_mnm[0]:.0f} … {e.k_interval_mnm[1]:.0f}",
                         e.k_mnm / k - 1, e.rms_log_residual])
        est3 = [estimate_support_stiffness(v[list(s)], a[list(s)], model=model[:, list(s)]).k_mnm
                for s in itertools.combinations(range(v.size), 3)]
        est3 = np.array(est3)
        rows.append([k, 3, f"free, every 3 of {v.size} speeds (median; share within ±25 %)", float(np.median(est3)),
                     f"{np.mean(np.abs(est3 / k - 1) <= 0.25):.0%} of {est3.size}", float(np.median(est3)) / k - 1, ""])
        noisy = [estimate_support_stiffness(v, a * np.exp(0.1 * rng.standard_normal(v.size)), model=model).k_mnm
                 for _ in range(50)]
        rows.append([k, len(v), "free, 10 % noise on each amplitude (median of 50; share within ±25 %)",
                     float(np.median(noisy)), f"{np.mean(np.abs(np.array(noisy) / k - 1) <= 0.25):.0%}",
                     float(np.median(noisy)) / k - 1, ""])
    print("\n### Support stiffness from passes at several speeds (physics lock-in amplitudes)\n")
    print(_table(["true k MN/m", "passes", "fit", "estimate MN/m", "interval / hits", "error", "rms ln residual"],
                 rows))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--physics", type=Path, default=Path("../shared/physics"))
    ap.add_argument("--img-dir", type=Path, default=None, help="write the PNG plots here (e.g. docs/img)")
    ap.add_argument("--parts", default="physics,index,powerlaw,wheels,demo,timing,stiffness")
    ap.add_argument("--index-runs", default=None,
                    help="only these run pairs of the index part (n05,one,n10,same,same05,n05r6,same05r6)")
    args = ap.parse_args()
    parts = set(args.parts.split(","))
    if args.img_dir is not None:
        args.img_dir.mkdir(parents=True, exist_ok=True)
    if "physics" in parts:
        part_physics(args.physics, args.img_dir)
    if parts & {"index", "powerlaw", "wheels"}:
        with tempfile.TemporaryDirectory(prefix="trackvkf-speed-") as tmp:
            out = part_index(Path(tmp), args.img_dir, args.index_runs.split(",") if args.index_runs else None)
            if "powerlaw" in parts:
                part_powerlaw(out)
            if "wheels" in parts:
                part_wheels(out)
    if "demo" in parts:
        with tempfile.TemporaryDirectory(prefix="trackvkf-demo-") as tmp:
            part_demo(Path(tmp))
    if "timing" in parts:
        part_timing()
    if "stiffness" in parts:
        part_stiffness(args.physics)


if __name__ == "__main__":
    main()
