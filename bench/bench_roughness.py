"""Roughness benchmark (issue 26 items 2–3): what the sleeper amplitude measures on rough rail, and its 1-σ.

Usage::

    .venv/bin/python bench/bench_roughness.py                       # accuracy on every rough / smooth physics run
    .venv/bin/python bench/bench_roughness.py --speed --base ../main  # + chunk CPU, base checkout vs this one

Accuracy: every rough physics run of ../shared/physics ("Added 2026-11-26") is written as a canonical run
(bench/physics_runs.py: rail 1 as Z11 and, for the two-rail pairs, rail 2 as Z12) and processed by the real
pipeline with the default settings. Against the smooth twin's per-bay truth ``A_bay_smooth``, per 10 m and
40 m segment after the 4.2 m start-up: the median of estimate / truth − 1, its RMS, and the share of the
segments whose stated 1-σ (``sleeper_amp_sd`` aggregated by app.analysis.uncertainty.segment_sd) covers the
truth; for ``sleeper_amp_raw`` (the single wheel's VKF amplitude, today's figure) and ``sleeper_amp``.
Smooth: the 39 uniform physics runs (steady bays tiled to 100 m): ``sleeper_amp`` against
``sleeper_amp_raw`` and ``A_lockin``, and the 1-σ of 10 m means.

Speed (``--speed``): a 60 s two-wheel run at 24 kHz (40 → 200 km/h and back, the sleeper order and broadband
noise), planned and processed chunk by chunk (``process_chunk``) in a fresh process per repetition, base
and this checkout alternating; CPU seconds and x real time per core (60 s / CPU s per wheel).

Assembly (``--assembly``): CPU seconds of the per-bin estimates (``two_rail_estimate``,
``single_wheel_estimate``) and of ``segment_sd`` with and without a shared part, on 100 km of random sums of
one wheel (400 000 bins), in this process.

Prints Markdown tables for BENCHMARKS.md.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from physics_runs import (  # noqa: E402
    D_S,
    ROUGH_PAIRS,
    ROUGH_SINGLE,
    START_M,
    cases,
    coverage,
    rough_run,
    segment_scores,
    steady_unit,
    write_run,
)

SPEED_FS = 24_000.0
SPEED_S = 60.0


def _pipeline(path: Path, work: Path):
    from app.analysis.settings import ProcessingSettings
    from app.pipeline import run_pipeline

    return run_pipeline(path, ProcessingSettings(), work)


def rough_rows(tmp: Path) -> list[dict]:
    """One row per (run, wheels, column); rail 2 of a pair also alone (as Z11), for more one-rail segments."""
    rows = []
    configs = ([(name, "pair") for name in ROUGH_PAIRS] + [(name, "rail 1") for name in ROUGH_PAIRS]
               + [(name, "one") for name in ROUGH_SINGLE] + [(name, "rail 2") for name in ROUGH_PAIRS])
    for name, mode in configs:
        r = rough_run(name)
        pair = mode == "pair"
        z11 = r["z12"] if mode == "rail 2" else r["z11"]
        tag = f"{name}-{mode.replace(' ', '')}"
        res = _pipeline(write_run(tmp / f"{tag}.h5", z11, r["fs"], r["speed"],
                                  z12=r["z12"] if pair else None), tmp / f"w-{tag}")
        p = res.profiles[res.profiles["wheel"] == "11"].sort_values("bin").reset_index(drop=True)
        what = {"pair": "rails 1 + 2 (Z11, Z12)", "rail 1": "rail 1 only", "rail 2": "rail 2 only",
                "one": "one rail"}[mode]
        for column in ("sleeper_amp_raw", "sleeper_amp"):
            row = {"run": name, "wheels": what, "column": column}
            for level in (10.0, 40.0):
                ratio, covered = segment_scores(r, p, column, level)
                row[f"median_{level:g}"] = float(np.median(ratio))
                row[f"rms_{level:g}"] = float(np.sqrt(np.mean(ratio**2)))
                row[f"cover_{level:g}"] = float(np.mean(covered))
                row[f"n_{level:g}"] = int(ratio.size)
            if column == "sleeper_amp":
                row["coverage"] = {level: coverage(r, p, level) for level in (10.0, 5.0)}
                after = (p["bin"].to_numpy() + 0.5) * 0.25 > START_M
                row["zero_bins"] = int(np.sum(p["sleeper_amp"].to_numpy()[after] == 0.0))
                row["n_bins"] = int(np.sum(after))
            if np.asarray(r["edges"]).size:
                x = (p["bin"].to_numpy() + 0.5) * 0.25
                edges = [START_M, *np.asarray(r["edges"]).tolist(), float(x.max())]
                amp = p[column].to_numpy()
                row["sections"] = [float(amp[(x > a + 5) & (x < b - 5)].mean()) for a, b in zip(edges[:-1], edges[1:], strict=True)]
                tb = r["x_bay"]
                row["truth_sections"] = [float(r["A_bay_smooth"][(tb > a + 5) & (tb < b - 5)].mean())
                                         for a, b in zip(edges[:-1], edges[1:], strict=True)]
            rows.append(row)
    return rows


def smooth_rows(tmp: Path) -> list[dict]:
    from app.analysis.uncertainty import segment_sd

    rows = []
    for name, c in sorted(cases().items()):
        unit, v, fs, nb = steady_unit(name)
        z = np.tile(unit, -(-100 // int(nb * D_S)))
        res = _pipeline(write_run(tmp / "u.h5", z, fs, v), tmp / f"w-{name}")
        p = res.profiles
        x = (p["bin"].to_numpy() + 0.5) * 0.25
        inner = p[(x > 15) & (x < x.max() - 15)]
        segs, sd = segment_sd(p["bin"].to_numpy(), p["sleeper_amp_sd"].to_numpy(), 10.0,
                          shared=p["sleeper_amp_sd_shared"].to_numpy())
        rows.append({"run": name, "amp_vs_raw": float(inner["sleeper_amp"].mean() / inner["sleeper_amp_raw"].mean() - 1),
                     "amp_vs_lockin": float(inner["sleeper_amp"].mean() / c["A_lockin"] - 1),
                     "raw_vs_lockin": float(inner["sleeper_amp_raw"].mean() / c["A_lockin"] - 1),
                     "sd10_rel": float(np.median(sd) / c["A_lockin"])})
        (tmp / "u.h5").unlink()
    return rows


# ---------------------------------------------------------------- speed

def _speed_run(path: Path) -> None:
    """60 s, Z11 and Z12 at 24 kHz, 40 → 200 km/h and back, sleeper order + broadband noise."""
    import h5py

    from app.io import parse_metadata
    from app.io.canonical import CanonicalWriter

    n = int(SPEED_S * SPEED_FS)
    t = np.arange(n) / SPEED_FS
    v = (40.0 + 160.0 * 0.5 * (1.0 - np.cos(2.0 * np.pi * t / SPEED_S))) / 3.6
    s = np.cumsum(v) / SPEED_FS
    rng = np.random.default_rng(0)
    meta = parse_metadata({"vehicle_id": "B", "line_id": "B", "km_start": 0.0, "km_increasing": True,
                           "start_time": "2024-01-01T00:00:00+00:00", "track": "1", "direction": "up",
                           "sleeper_spacing": D_S, "sample_rate_hz": SPEED_FS,
                           "wheel_diameters": {w: 0.92 for w in ("11", "12", "41", "42")}})
    with h5py.File(path, "w") as h5:
        w = CanonicalWriter(h5, fs=SPEED_FS, metadata=meta, channels=["Z11", "Z12", "speed", "position"],
                            n_samples=n, compression=None, source_format="simulated")
        for ch in ("Z11", "Z12"):
            w.write(ch, 0, 2.0 * np.cos(2 * np.pi * s / D_S) + rng.normal(0.0, 3.0, n))
        w.write("speed", 0, v)
        w.write("position", 0, s)
        w.finish(n)


def _time_chunks(run: str) -> dict:
    """In this process: plan and process every chunk of ``run``; CPU and wall seconds (numba warmed first)."""
    from app.analysis.settings import ProcessingSettings
    from app.pipeline.chunk import process_chunk
    from app.pipeline.plan import plan_chunks

    settings = ProcessingSettings()
    chunks = plan_chunks(Path(run), settings)
    with tempfile.TemporaryDirectory() as d:
        process_chunk(Path(run), settings, chunks[0], Path(d) / "warm.npz")  # compile / load the kernels
        c0, t0 = time.process_time(), time.perf_counter()
        for ch in chunks:
            process_chunk(Path(run), settings, ch, Path(d) / f"c{ch.index}.npz")
        return {"cpu_s": time.process_time() - c0, "wall_s": time.perf_counter() - t0, "n_chunks": len(chunks),
                "first_chunk_counted": True}


def speed(base: Path | None, reps: int) -> list[dict]:
    out = []
    with tempfile.TemporaryDirectory() as d:
        run = Path(d) / "speed.h5"
        _speed_run(run)
        builds = [("this branch", ROOT)] + ([("base " + str(base), base)] if base is not None else [])
        for rep in range(reps):
            for name, root in (builds if rep % 2 == 0 else builds[::-1]):
                env = dict(os.environ, PYTHONPATH=str(root))
                cmd = [sys.executable, str(Path(__file__).resolve()), "--time-chunks", str(run)]
                res = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True, cwd=str(root))
                row = json.loads(res.stdout.strip().splitlines()[-1])
                row.update({"build": name, "pass": rep + 1})
                out.append(row)
    return out


def assembly() -> list[str]:
    """CPU seconds of the per-bin estimates and of segment_sd on 100 km of random sums (400 000 bins)."""
    from app.analysis import roughness
    from app.analysis.uncertainty import segment_sd

    n = 400_000
    rng = np.random.default_rng(0)
    b = np.arange(n)
    e1 = 5 + rng.normal(0, 5, n) + 1j * rng.normal(0, 5, n)
    e2 = 5 + rng.normal(0, 5, n) + 1j * rng.normal(0, 5, n)
    x, p1, p2 = np.real(e1 * np.conj(e2)), np.abs(e1) ** 2, np.abs(e2) ** 2
    sides = np.abs(rng.normal(0, 3, (2, n))) ** 2
    out = []
    c0 = time.process_time()
    roughness.two_rail_estimate(b[:100], x[:100], p1[:100], p2[:100])
    out.append(f"first call (tables): {time.process_time() - c0:.2f} s")
    for _ in range(2):
        c0 = time.process_time()
        roughness.two_rail_estimate(b, x, p1, p2)
        c1 = time.process_time()
        _, sd, shared = roughness.single_wheel_estimate(b, p1, sides, e1)
        c2 = time.process_time()
        out.append(f"two_rail_estimate {c1 - c0:.2f} s, single_wheel_estimate {c2 - c1:.2f} s")
    for level in (10.0, 100.0):
        c0 = time.process_time()
        segment_sd(b, sd, level)
        c1 = time.process_time()
        segment_sd(b, sd, level, shared=0.4 * sd)
        out.append(f"segment_sd at {level:g} m: {c1 - c0:.2f} s without a shared part, "
                   f"{time.process_time() - c1:.2f} s with")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--speed", action="store_true", help="also time the chunks (base vs this checkout)")
    ap.add_argument("--base", type=Path, help="a checkout of the base (e.g. main) for --speed")
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--no-accuracy", action="store_true")
    ap.add_argument("--assembly", action="store_true", help="also time the per-bin estimates and segment_sd")
    ap.add_argument("--time-chunks", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.time_chunks:
        print(json.dumps(_time_chunks(args.time_chunks)))
        return
    if not args.no_accuracy:
        with tempfile.TemporaryDirectory() as d:
            rows = rough_rows(Path(d))
            smooth = smooth_rows(Path(d))
        print("| run | wheels | column | 10 m: median bias | RMS | 1-σ covers | 40 m: median bias | RMS | 1-σ covers |")
        print("|---|---|---|---|---|---|---|---|---|")
        for r in rows:
            raw = r["column"] != "sleeper_amp"  # the 1-σ is sleeper_amp's
            c10 = "–" if raw else f"{r['cover_10']:.0%} ({r['n_10']})"
            c40 = "–" if raw else f"{r['cover_40']:.0%} ({r['n_40']})"
            print(f"| {r['run']} | {r['wheels']} | `{r['column']}` | {r['median_10']:+.1%} | {r['rms_10']:.0%} | "
                  f"{c10} | {r['median_40']:+.1%} | {r['rms_40']:.0%} | {c40} |")
        print()
        for r in rows:
            if "sections" in r:
                print(f"{r['run']} {r['wheels']} `{r['column']}` section means (edges ± 5 m): "
                      + ", ".join(f"{a:.2f}" for a in r["sections"]) + "  truth: "
                      + ", ".join(f"{a:.2f}" for a in r["truth_sections"]))
        print()
        for label, keep in (("two rails", lambda r: "rails 1 + 2" in r["wheels"]),
                            ("one rail", lambda r: "rails 1 + 2" not in r["wheels"]), ("all", lambda r: True)):
            sel = [r for r in rows if r["column"] == "sleeper_amp" and keep(r)]
            n = sum(r["n_10"] for r in sel)
            k = sum(round(r["cover_10"] * r["n_10"]) for r in sel)
            print(f"`sleeper_amp`, {label}: the 1-σ of 10 m means covers the truth in {k} of {n} segments "
                  f"({k / n:.0%}; 68 % ± {2 * np.sqrt(0.6827 * 0.3173 / n):.0%} at twice the binomial scatter)")
        print()
        print("| run | wheels | 10 m: covered (grid from 0 m) | over 4 grids (2.5 m steps) | z | 5 m: covered | "
              "over 2 grids | z | bins at 0 |")
        print("|---|---|---|---|---|---|---|---|---|")
        for r in rows:
            if "coverage" not in r:
                continue
            c10, c5 = r["coverage"][10.0], r["coverage"][5.0]
            print(f"| {r['run']} | {r['wheels']} | {c10['k']}/{c10['n']} = {c10['share']:.0%} (±{c10['sigma']:.0%}) | "
                  f"{c10['share_offsets']:.0%} ({c10['n_offsets']}) | {c10['z']:+.1f} | "
                  f"{c5['k']}/{c5['n']} = {c5['share']:.0%} (±{c5['sigma']:.0%}) | {c5['share_offsets']:.0%} "
                  f"({c5['n_offsets']}) | {c5['z']:+.1f} | {r['zero_bins']} of {r['n_bins']} |")
        for label, keep in (("two rails", lambda r: "rails 1 + 2" in r["wheels"]),
                            ("one rail", lambda r: "rails 1 + 2" not in r["wheels"]), ("all", lambda r: True)):
            for level in (10.0, 5.0):
                sel = [r["coverage"][level] for r in rows if "coverage" in r and keep(r)]
                n = sum(c["n"] for c in sel)
                k = sum(c["k"] for c in sel)
                share = sum(c["share_offsets"] * c["n_offsets"] for c in sel) / sum(c["n_offsets"] for c in sel)
                sig = np.sqrt(0.6827 * 0.3173 / n)
                print(f"coverage of {level:g} m means, {label}: {k} of {n} ({k / n:.0%}, grid from 0 m); over the shifted "
                      f"grids {share:.0%}; binomial 1-σ of {n} segments ±{sig:.0%} (z = {(share - 0.6827) / sig:+.1f})")
        print()
        worst = max(smooth, key=lambda r: abs(r["amp_vs_raw"]))
        worst_l = max(smooth, key=lambda r: abs(r["amp_vs_lockin"]))
        worst_sd = max(smooth, key=lambda r: r["sd10_rel"])
        print(f"smooth uniform runs ({len(smooth)}): |sleeper_amp / sleeper_amp_raw − 1| max "
              f"{abs(worst['amp_vs_raw']):.4%} ({worst['run']}); |sleeper_amp / A_lockin − 1| max "
              f"{abs(worst_l['amp_vs_lockin']):.4%} ({worst_l['run']}; raw {worst_l['raw_vs_lockin']:+.4%}); "
              f"1-σ of 10 m means / A_lockin: median {np.median([r['sd10_rel'] for r in smooth]):.2%}, "
              f"max {worst_sd['sd10_rel']:.2%} ({worst_sd['run']})")
    if args.assembly:
        print()
        for line in assembly():
            print(f"assembly, 100 km of one wheel: {line}")
    if args.speed:
        rows = speed(args.base, args.reps)
        print()
        print("| pass | build | chunks | CPU s | wall s | x real time per core per wheel |")
        print("|---|---|---|---|---|---|")
        for r in rows:
            print(f"| {r['pass']} | {r['build']} | {r['n_chunks']} | {r['cpu_s']:.2f} | {r['wall_s']:.2f} | "
                  f"{2 * SPEED_S / r['cpu_s']:.0f} |")


if __name__ == "__main__":
    main()
