"""Small steps where the signal is weak (issue 33 item 7): FE step runs through the real pipeline, the
profile as stored (``sleeper_amp``) against its piecewise-constant estimate (app.analysis.steps).

    .venv/bin/python bench/bench_weak_steps.py RUN.npz [RUN.npz ...] [--sigmas 0,1] [--seeds 5,6,7]
    .venv/bin/python bench/bench_weak_steps.py --transitions     # the issue-26 transition cases, noise-free

RUN.npz: a step run of the railFE harness (../shared/physics/harness), e.g.
``run_railfe.py --ks 80 52 --edges 200 --speed 50 --length 400`` (1.51 → 0.99 m/s²). Noise: the
simulator's band-limited measurement noise (2 Hz … 0.4 fs) of ``sigma`` m/s², one draw per seed.
Measures (bench/physics_transitions.py): 10–90 % width in its settling form, rise width, 50 % point,
ringing, and the level error 10 m from the ends and the edge.
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
    """(bin centres m, ``sleeper_amp``, ``sleeper_amp_sd``) of wheel 11 from the real pipeline."""
    with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = run_pipeline(write_run(Path(tmp) / "run.h5", z, fs, v), settings, Path(tmp) / "c")
    p = res.profiles[res.profiles["wheel"] == "11"].sort_values("bin")
    return ((p["bin"].to_numpy() + 0.5) * settings.bin_length_m, p["sleeper_amp"].to_numpy(),
            p["sleeper_amp_sd"].to_numpy())


def transitions(settings: ProcessingSettings, res_bins: float) -> None:
    """The issue-26 transition cases (noise-free): ``sleeper_amp`` → the step estimate, per edge."""
    print("| case | edge m | 10–90 % width m | 50 % point m | ringing | level error per segment |")
    print("|---|---|---|---|---|---|")
    for run in (physics_run("trans2_v30.npz"), physics_run("trans2_v42.npz"),
                blended_run(35, 40, 160, [37.2, 24.6, 60.0]), blended_run(50, 20, 80, [37.2, 24.6, 60.0])):
        x, a, sd = _profile(run.z, run.fs, run.speed, settings)
        ev = [evaluate(x, q, run) for q in (a, step_levels(a, sd, res_bins))]
        for i, (e0, e1) in enumerate(zip(ev[0]["edges"], ev[1]["edges"], strict=True)):
            m0, m1 = e0["product"], e1["product"]
            lv = " / ".join(f"{p:+.1%} → {q:+.1%}" for p, q in zip(ev[0]["levels"], ev[1]["levels"], strict=True)
                            if np.isfinite(p))
            print(f"| {run.name if i == 0 else ''} | {e0['edge']:.1f} | {m0['width']:.1f} → {m1['width']:.1f} | "
                  f"{m0['offset']:+.1f} → {m1['offset']:+.1f} | {m0['ringing']:.1%} → {m1['ringing']:.1%} | "
                  f"{lv if i == 0 else ''} |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", type=Path, nargs="*")
    ap.add_argument("--sigmas", default="0,1")
    ap.add_argument("--seeds", default="5,6,7")
    ap.add_argument("--transitions", action="store_true", help="the issue-26 transition cases instead")
    args = ap.parse_args()
    settings = ProcessingSettings()
    res_bins = 3.0 / settings.bin_length_m if settings.track_resolution_m is None \
        else float(settings.track_resolution_m) / settings.bin_length_m
    if args.transitions:
        transitions(settings, res_bins)
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
                x, a, sd = _profile(z0 + noise, fs, v, settings)
                u = step_levels(a, sd, res_bins)
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
