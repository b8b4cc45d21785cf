"""Small steps where the signal is weak (issue 33 item 7): FE step runs through the real pipeline, the
profile as stored (``sleeper_amp``) against its piecewise-constant estimate (app.analysis.steps).

    .venv/bin/python bench/bench_weak_steps.py RUN.npz [RUN.npz ...] [--sigmas 0,1] [--seeds 5,6,7]
    .venv/bin/python bench/bench_weak_steps.py --transitions     # the issue-26 transition cases, noise-free
    .venv/bin/python bench/bench_weak_steps.py --blended         # the FE uniform runs' 80 ↔ 40 MN/m at 50 m/s
    .venv/bin/python bench/bench_weak_steps.py --cost 30         # CPU of the stored step estimate, 30 min run

RUN.npz: a step run of the railFE harness (../shared/physics/harness), e.g.
``run_railfe.py --ks 80 52 --edges 200 --speed 50 --length 400`` (1.51 → 0.99 m/s²). Noise: the
simulator's band-limited measurement noise (2 Hz … 0.4 fs) of ``sigma`` m/s², one draw per seed.
Measures (bench/physics_transitions.py): 10–90 % width in its settling form, rise width, 50 % point,
ringing, and the level error 10 m from the ends and the edge. The step estimate is the stored column
``sleeper_step`` of the pipeline's profile (app.pipeline.assemble.sleeper_step).

``--cost MINUTES``: a simulated run (default line, random rail surface, 3 km, 10 kHz) through the real
pipeline; each wheel's stored ``sleeper_amp`` / ``sleeper_amp_sd`` tiled to the bins of a MINUTES long run at
the run's mean speed, and the CPU seconds of ``sleeper_step`` on it (one process, BLAS on one thread, the
compiled kernel loaded first; the median of ``--repeat`` calls per wheel). ``--cost MINUTES --full``: the
run simulated MINUTES long (10 kHz) and processed whole, the pipeline's CPU beside the step estimate's.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from physics_runs import write_run  # noqa: E402
from physics_transitions import _segment_levels, blended_run, edge_metrics, evaluate, physics_run  # noqa: E402

from app.analysis.settings import ProcessingSettings  # noqa: E402
from app.analysis.steps import step_levels  # noqa: E402
from app.pipeline import run_pipeline  # noqa: E402
from app.simulate.noise import BandLimitedNoise  # noqa: E402


def _profile(z: np.ndarray, fs: float, v: float, settings: ProcessingSettings) -> tuple[np.ndarray, ...]:
    """(bin centres m, ``sleeper_amp``, ``sleeper_amp_sd``, ``sleeper_step``) of wheel 11 from the real
    pipeline."""
    with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = run_pipeline(write_run(Path(tmp) / "run.h5", z, fs, v), settings, Path(tmp) / "c")
    p = res.profiles[res.profiles["wheel"] == "11"].sort_values("bin")
    return ((p["bin"].to_numpy() + 0.5) * settings.bin_length_m, p["sleeper_amp"].to_numpy(),
            p["sleeper_amp_sd"].to_numpy(), p["sleeper_step"].to_numpy())


def _stored_is_step_levels(a: np.ndarray, sd: np.ndarray, step: np.ndarray, res_bins: float) -> None:
    """The stored column is the step estimate of the stored amplitude (else the bench stops)."""
    if not np.array_equal(step, step_levels(a, sd, res_bins), equal_nan=True):
        raise SystemExit("sleeper_step is not step_levels(sleeper_amp, sleeper_amp_sd) of the stored profile")


def transitions(settings: ProcessingSettings, res_bins: float, blended: bool = False) -> None:
    """The issue-26 transition cases (noise-free): ``sleeper_amp`` → the stored step estimate, per edge;
    ``blended``: the 80 ↔ 40 MN/m run at 50 m/s of the uniform FE runs under 1 m/s² of noise, seeds 5–7."""
    print("| case | edge m | 10–90 % width m | 50 % point m | ringing | level error per segment |")
    print("|---|---|---|---|---|---|")
    if blended:
        base = blended_run(50, 80, 40, [37.2, 24.6, 60.0])
        cases = []
        for seed in (5, 6, 7):
            noise = BandLimitedNoise(np.random.default_rng(seed), base.fs, 1.0, (2.0, 0.4 * base.fs)).next(base.z.size)
            cases.append((f"{base.name}, 1 m/s², seed {seed}", base, base.z + noise))
    else:
        cases = [(r.name, r, r.z) for r in (physics_run("trans2_v30.npz"), physics_run("trans2_v42.npz"),
                                            blended_run(35, 40, 160, [37.2, 24.6, 60.0]),
                                            blended_run(50, 20, 80, [37.2, 24.6, 60.0]))]
    for name, run, z in cases:
        x, a, sd, step = _profile(z, run.fs, run.speed, settings)
        _stored_is_step_levels(a, sd, step, res_bins)
        ev = [evaluate(x, q, run) for q in (a, step)]
        for i, (e0, e1) in enumerate(zip(ev[0]["edges"], ev[1]["edges"], strict=True)):
            m0, m1 = e0["product"], e1["product"]
            lv = " / ".join(f"{p:+.1%} → {q:+.1%}" for p, q in zip(ev[0]["levels"], ev[1]["levels"], strict=True)
                            if np.isfinite(p))
            print(f"| {name if i == 0 else ''} | {e0['edge']:.1f} | {m0['width']:.1f} → {m1['width']:.1f} | "
                  f"{m0['offset']:+.1f} → {m1['offset']:+.1f} | {m0['ringing']:.1%} → {m1['ringing']:.1%} | "
                  f"{lv if i == 0 else ''} |", flush=True)


def cost(minutes: float, repeat: int, full: bool = False) -> None:
    """CPU seconds of the stored step estimate per wheel of a ``minutes`` long run (see the module's doc);
    ``full``: the run simulated ``minutes`` long and processed whole (no tiling), with the pipeline's CPU."""
    import os
    import time

    import pandas as pd

    from app.pipeline.assemble import sleeper_step
    from app.simulate.run import simulate_run

    settings = ProcessingSettings()
    with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        extent = {"duration_s": 60.0 * minutes} if full else {"length_km": 3.0}
        truth = simulate_run(Path(tmp) / "run.h5", fs=10_000.0, seed=3, rail_surface=True, with_forces=False,
                             **extent)
        c0 = time.process_time()
        res = run_pipeline(truth.run_path, settings, Path(tmp) / "c")
        if full:
            print(f"pipeline (chunks and assembly, one process): {time.process_time() - c0:.1f} CPU s")
    mean_speed = truth.distance_m / truth.duration_s
    n_bins = int(round(minutes * 60.0 * mean_speed / settings.bin_length_m))
    print(f"run: {truth.distance_m / 1000:.2f} km in {truth.duration_s:.0f} s (mean {mean_speed:.1f} m/s); "
          f"{minutes:g} min = {n_bins} bins of {settings.bin_length_m} m per wheel; "
          f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS', 'unset')}")
    sleeper_step(pd.DataFrame({"bin": np.arange(40), "sleeper_amp": np.ones(40), "sleeper_amp_sd": np.ones(40)}),
                 3.0, 0.25)  # the compiled kernel loaded (once per process)
    print(f"| wheel | valid bins | levels | CPU s per call (median of {repeat}) | µs per bin |")
    print("|---|--:|--:|--:|--:|")
    total = 0.0
    for wheel, p in res.profiles.groupby("wheel"):
        p = p.sort_values("bin")
        reps = -(-n_bins // len(p))
        tiled = p if full else pd.DataFrame({"bin": np.arange(reps * len(p))[:n_bins],
                                             "sleeper_amp": np.tile(p["sleeper_amp"].to_numpy(), reps)[:n_bins],
                                             "sleeper_amp_sd": np.tile(p["sleeper_amp_sd"].to_numpy(), reps)[:n_bins]})
        times = []
        for _ in range(repeat):
            c0 = time.process_time()
            out = sleeper_step(tiled, 3.0, settings.bin_length_m)
            times.append(time.process_time() - c0)
        t = float(np.median(times))
        total += t
        ok = np.isfinite(out)
        print(f"| {wheel} | {int(ok.sum())} | {np.unique(out[ok]).size} | {t:.3f} | {1e6 * t / len(tiled):.2f} |",
              flush=True)
        if full:
            np.testing.assert_array_equal(out, p["sleeper_step"].to_numpy())  # what the pipeline stored
    print(f"all wheels: {total:.3f} CPU s; per wheel and minute of run: {total / res.profiles['wheel'].nunique() / minutes:.4f} s")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", type=Path, nargs="*")
    ap.add_argument("--sigmas", default="0,1")
    ap.add_argument("--seeds", default="5,6,7")
    ap.add_argument("--transitions", action="store_true", help="the issue-26 transition cases instead")
    ap.add_argument("--blended", action="store_true",
                    help="the 80 <-> 40 MN/m run at 50 m/s of the uniform FE runs under 1 m/s² of noise")
    ap.add_argument("--cost", type=float, metavar="MINUTES", help="CPU of the step estimate on a run this long")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--full", action="store_true", help="with --cost: simulate and process the whole run")
    args = ap.parse_args()
    if args.cost:
        cost(args.cost, args.repeat, args.full)
        return
    settings = ProcessingSettings()
    res_bins = 3.0 / settings.bin_length_m if settings.track_resolution_m is None \
        else float(settings.track_resolution_m) / settings.bin_length_m
    if args.transitions or args.blended:
        transitions(settings, res_bins, blended=args.blended)
        return
    print("| FE run | noise m/s² | seed | stated 1-σ / step | 10–90 % width m: sleeper_amp → step estimate "
          "(physics') | rise m | 50 % point m | ringing (physics') | level error max |")
    print("|---|---|---|---|---|---|---|---|---|")
    for path in args.runs:
        d = np.load(path)
        z0, fs, v = d["a_axle"], float(d["fs"]), float(d["speed"])
        edges = np.asarray(d["edges"], dtype=float)
        bounds = np.r_[0.0, edges, float(d["x"][-1])]
        lv = _segment_levels(np.asarray(d["x_bay"]), np.asarray(d["A_bay"]), bounds)
        ph = edge_metrics(np.asarray(d["x_bay"]), np.asarray(d["A_bay"]), float(edges[0]), lv[0], lv[1])
        for sigma in (float(s) for s in args.sigmas.split(",")):
            for seed in ((5,) if sigma == 0 else tuple(int(s) for s in args.seeds.split(","))):
                noise = BandLimitedNoise(np.random.default_rng(seed), fs, sigma, (2.0, 0.4 * fs)).next(z0.size) \
                    if sigma > 0 else 0.0
                x, a, sd, u = _profile(z0 + noise, fs, v, settings)
                _stored_is_step_levels(a, sd, u, res_bins)
                m0, m = (edge_metrics(x, q, float(edges[0]), lv[0], lv[1]) for q in (a, u))
                lvl = []
                for q in (a, u):
                    lvl.append(max(abs(float(np.nanmean(q[(x > lo + 10) & (x < hi - 10)])) / L - 1.0)
                                   for lo, hi, L in zip(bounds[:-1], bounds[1:], lv, strict=True)))
                step = abs(lv[1] - lv[0])
                print(f"| {path.name} ({lv[0]:.2f} → {lv[1]:.2f}) | {sigma:g} | {seed if sigma else '–'} | "
                      f"{np.nanmedian(sd) / step:.0%} | {m0['width']:.1f} → {m['width']:.1f} ({ph['width']:.1f}) | "
                      f"{m0['rise']:.1f} → {m['rise']:.1f} | {m0['offset']:+.1f} → {m['offset']:+.1f} | "
                      f"{m0['ringing']:.1%} → {m['ringing']:.1%} ({ph['ringing']:.1%}) | "
                      f"{lvl[0]:.1%} → {lvl[1]:.1%} |", flush=True)


if __name__ == "__main__":
    main()
