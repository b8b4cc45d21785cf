"""Accuracy of GNSS positioning: simulated recorder runs placed on the line by ingest.

For each seed: a recorder run (MDF4) with drifting odometry (0.4 % scale error, 1 m slow
wander) and GNSS (10 Hz, 3 m noise per axis, 30 s outages every 240 s, 0.5 % multipath
jumps of 80 m) on a synthetic line geometry is ingested exactly as an upload is
(map matching + odometry/GNSS fusion), and the line km of the position reference is
compared with the truth at every 50th sample.

    .venv/bin/python bench/bench_positioning.py --seeds 8 --length-km 20
    .venv/bin/python bench/bench_positioning.py --noise-corr-s 2   # time-correlated GNSS errors

Prints per seed and overall: largest |error| where GNSS is good (outside outages), largest
|error| inside outages, RMS error (m). Results: docs/positioning.md.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from app.io import ingest, open_run
from app.simulate.recorder import GnssSimulation, simulate_recorder_run


def measure(seed: int, length_km: float, noise_corr_s: float, work: Path) -> tuple[float, float, float]:
    rec = simulate_recorder_run(work / f"run-{seed}.mf4", "mdf4", seed=seed, length_km=length_km,
                                fs=2000.0, with_forces=False,
                                gnss=GnssSimulation(noise_corr_s=noise_corr_s))
    out = work / f"run-{seed}.h5"
    summary = ingest(rec.path, None, rec.metadata, out, channel_map=rec.channel_map, geometry=rec.geometry)
    with open_run(out) as run:
        k = np.arange(0, run.n_samples, 50)
        km = np.concatenate([run.km(a, min(a + 1_000_000, run.n_samples))
                             for a in range(0, run.n_samples, 1_000_000)])[k]
    t = k / summary.fs
    err = 1000.0 * km - rec.true_chainage_m(t)
    good = np.ones(t.size, dtype=bool)
    for a, b in rec.outages:
        good &= (t < a) | (t > b)
    bridged = float(np.abs(err[~good]).max()) if (~good).any() else 0.0
    return float(np.abs(err[good]).max()), bridged, float(np.sqrt(np.mean(err**2)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument("--length-km", type=float, default=20.0)
    parser.add_argument("--noise-corr-s", type=float, default=0.0)
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.seeds):
            good, bridged, rms = measure(seed, args.length_km, args.noise_corr_s, Path(tmp))
            rows.append((good, bridged, rms))
            print(f"seed {seed}: max |err| GNSS good {good:.2f} m, in outages {bridged:.2f} m, rms {rms:.2f} m")
    r = np.array(rows)
    print(f"all {args.seeds} runs of {args.length_km:g} km (GNSS noise correlation {args.noise_corr_s:g} s): "
          f"max |err| GNSS good {r[:, 0].max():.2f} m (mean of maxima {r[:, 0].mean():.2f} m), "
          f"in outages {r[:, 1].max():.2f} m, rms {r[:, 2].mean():.2f} m")


if __name__ == "__main__":
    main()
