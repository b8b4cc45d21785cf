"""Run-to-run repeatability of the segment condition index, measured on the real pipeline.

Simulates several runs over the same simulated line at nearly the same speed
(other seeds: other measurement noise, other wheel out-of-roundness), runs
the real pipeline (VKF → 25 cm bins) and aggregates every wheel into 10 m and
100 m segments (:func:`app.analysis.condition.segment_stats`, index = ln of the
amplitude). Prints, per segment length, the robust run-to-run spread of the
segment index (1.4826 · MAD of the differences between two runs, / √2) and how
strongly the wheels' deviations are correlated. The synthetic fleet generator
(:mod:`app.simulate.fleet`) takes its default repeatability from these numbers.

Usage: ``.venv/bin/python bench/bench_condition_noise.py [--runs 4] [--length-km 3] [--fs 10000]``
"""

from __future__ import annotations

import argparse
import itertools
import tempfile
import time
from pathlib import Path

import numpy as np

from app.analysis.condition import segment_stats
from app.analysis.robust import mad_sd
from app.analysis.settings import ProcessingSettings
from app.analysis.units import KMH_PER_MPS
from app.pipeline import run_pipeline
from app.simulate.run import simulate_run
from app.simulate.speed import SpeedProfile
from app.simulate.track import generate_line

EDGE_TRIM_M = 50.0


def _segments(profiles, seg_m: float) -> dict[str, dict[int, float]]:
    out: dict[str, dict[int, float]] = {}
    for wheel, g in profiles.groupby("wheel"):
        g = g.sort_values("bin")
        pos = (g["bin"].to_numpy() + 0.5) * 0.25
        keep = (pos >= pos.min() + EDGE_TRIM_M) & (pos <= pos.max() - EDGE_TRIM_M)
        amp = g["sleeper_amp"].to_numpy(dtype=float)[keep]
        st = segment_stats(pos[keep], amp, g["speed_mean"].to_numpy(dtype=float)[keep],
                           np.log(np.where(amp > 0, amp, np.nan)), segment_m=seg_m)
        # interior segments only (whole segments inside the trimmed run)
        out[str(wheel)] = dict(zip(st.seg.tolist(), st.index.tolist(), strict=True))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=4)
    ap.add_argument("--length-km", type=float, default=3.0)
    ap.add_argument("--fs", type=float, default=10_000.0)
    ap.add_argument("--speed-kmh", type=float, default=100.0)
    ap.add_argument("--speed-jitter", type=float, default=0.0,
                    help="relative speed spread between runs (uniform ±), default 0: equal speed")
    args = ap.parse_args()
    km0 = 12.0
    line = generate_line(km0 * 1000 - 200, (km0 + args.length_km) * 1000 + 400, seed=7)
    rng = np.random.default_rng(0)
    per_run = []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.runs):
            v = args.speed_kmh * (1 + rng.uniform(-args.speed_jitter, args.speed_jitter)) / KMH_PER_MPS
            path = Path(tmp) / f"run{i}.h5"
            t0 = time.perf_counter()
            simulate_run(path, length_km=args.length_km, fs=args.fs, seed=100 + i, line=line,
                         speed_profile=SpeedProfile.constant(v), km_start=km0, with_forces=False)
            res = run_pipeline(path, ProcessingSettings(), Path(tmp) / f"work{i}")
            print(f"run {i}: {v * KMH_PER_MPS:.1f} km/h, simulated + processed in {time.perf_counter() - t0:.1f} s")
            per_run.append(res.profiles)
    print(f"{args.runs} runs, {args.length_km} km, {args.fs:.0f} Hz, {args.speed_kmh:.0f} km/h ± {100 * args.speed_jitter:.0f} %")
    print("| segment | run-to-run σ of the index (log units) | pairs × segments | wheel-to-wheel correlation of the deviations |")
    print("|---|---|---|---|")
    for seg_m in (10.0, 100.0):
        segs = [_segments(p, seg_m) for p in per_run]
        wheels = sorted(segs[0])
        diffs, dev_by_wheel = [], {w: [] for w in wheels}
        for a, b in itertools.combinations(range(len(segs)), 2):
            common = set.intersection(*(set(segs[r][w]) for r in (a, b) for w in wheels))
            for w in wheels:
                d = np.array([segs[a][w][s] - segs[b][w][s] for s in sorted(common)])
                diffs.append(d)
                dev_by_wheel[w].append(d)
        d = np.concatenate(diffs)
        sigma = mad_sd(d) / np.sqrt(2)
        mats = np.array([np.concatenate(dev_by_wheel[w]) for w in wheels])
        corr = np.corrcoef(mats)
        off = corr[~np.eye(len(wheels), dtype=bool)]
        print(f"| {seg_m:.0f} m | {sigma:.4f} | {d.size} | {off.mean():.2f} (min {off.min():.2f}, max {off.max():.2f}) |")


if __name__ == "__main__":
    main()
