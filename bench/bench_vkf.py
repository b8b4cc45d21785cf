"""VKF engine benchmark: speed, accuracy and memory (issue 2, point 6 and 3).

Usage::

    .venv/bin/python bench/bench_vkf.py            # 60 s, 12 orders, 24 kHz
    .venv/bin/python bench/bench_vkf.py --memory   # + 30-minute memory-mapped run

Prints a Markdown table for BENCHMARKS.md. Each case runs in its own
process so that peak memory (ru_maxrss) belongs to that case alone.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

FS = 24_000.0
D_W = 0.92


def speed_profile(t: np.ndarray, duration: float) -> np.ndarray:
    """40 → 200 km/h and back, raised cosine, m/s."""
    return (40.0 + 160.0 * 0.5 * (1.0 - np.cos(2.0 * np.pi * t / duration))) / 3.6


def railway_case(duration: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    from app.analysis.orders import railway_multipliers

    n = int(duration * FS)
    t = np.arange(n) / FS
    v = speed_profile(t, duration)
    mult = railway_multipliers(D_W, 0.6, 11)
    phi = 2.0 * np.pi * np.outer(mult, np.cumsum(v)) / FS
    amp = np.vstack([1.0 + 0.5 * np.sin(2 * np.pi * t / 17.0)] + [np.full(n, 0.5)] * 11)
    truth = amp * np.cos(phi)
    rng = np.random.default_rng(seed)
    y = truth.sum(axis=0) + rng.normal(0.0, 3.0, n)
    return y, v, mult, amp


def _warm_up() -> float:
    """One short solve first: the engine's compiled (numba) kernels are loaded once per
    process (≈ 0.4 s), as in the service's long-lived chunk processes. Returns its seconds."""
    from app.analysis.recipe import order_recipe
    from app.analysis.settings import ProcessingSettings

    y, v, _, _ = railway_case(2.0, seed=1)
    t0 = time.perf_counter()
    order_recipe(D_W, 0.6, ProcessingSettings()).solve(y, FS, v)
    return time.perf_counter() - t0


def case_engine(duration: float) -> dict:
    from app.analysis.orders import OrderTrack
    from app.analysis.vkf import vkf

    y, v, mult, amp = railway_case(duration)
    bw = OrderTrack(v, np.full(mult.size, 0.1 / (np.pi * D_W)))
    warm_s = _warm_up()
    t0 = time.perf_counter()
    c0 = time.process_time()
    res = vkf(y, FS, OrderTrack(v, mult), bw, 2)
    grid = np.arange(0, y.size, 24)
    env = res.envelope_at(grid)
    solve_s = time.perf_counter() - t0
    cpu_s = time.process_time() - c0
    t1 = time.perf_counter()
    wave = res.waveform
    full_s = time.perf_counter() - t1
    edge = int(2 * FS)
    m = slice(edge, y.size - edge)
    a_true = amp[:, grid]
    g = (grid >= edge) & (grid < y.size - edge)
    sleeper_err = float(np.sqrt(np.mean((np.abs(env[0, g]) - a_true[0, g]) ** 2) / np.mean(a_true[0, g] ** 2)))
    _ = wave[:, m]
    return {
        "case": f"vkf, 12 orders, {duration:g} s @ 24 kHz",
        "seconds": solve_s,
        "rtf": duration / solve_s,
        "cpu_s": cpu_s,
        "warm_up_2s_solve_s": warm_s,
        "full_rate_waveforms_s": full_s,
        "sleeper_rms_err": sleeper_err,
        "decimation": res.info["chunks"][0]["decimation"],
        "refinement_iterations": res.info["chunks"][0]["refinement_iterations"],
        "maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }


def case_sparse(duration: float) -> dict:
    """Direct sparse solve of Eq. 20 as written (scipy.sparse + spsolve)."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spl

    from app.analysis.vkf._weights import weight_squared

    y, v, mult, _ = railway_case(duration)
    n = y.size
    f = np.outer(mult, v)
    phi = 2.0 * np.pi * np.cumsum(f, axis=1) / FS
    bw = 0.1 / (np.pi * D_W) * v
    t0 = time.perf_counter()
    c = sp.hstack([sp.diags(np.exp(1j * p)) for p in phi]).tocsc()
    d = sp.eye(n, format="csr")
    for _ in range(2):
        d = d[1:] - d[:-1]
    r = np.sqrt(weight_squared(bw[2:], FS, 2))
    s = sp.block_diag([sp.diags(r) @ d for _ in range(mult.size)]).tocsc()
    m = (c.conj().T @ c + s.T @ s).tocsc()
    spl.spsolve(m, c.conj().T @ y.astype(complex))
    sec = time.perf_counter() - t0
    return {
        "case": f"direct sparse Eq. 20, 12 orders, {duration:g} s @ 24 kHz",
        "seconds": sec,
        "rtf": duration / sec,
        "maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }


def case_recipe(duration: float) -> dict:
    """The product's default recipe (``ProcessingSettings()``): sleeper order + 2 harmonics
    (3 m resolution) and 11 wheel orders (0.1 orders), solved jointly, one channel."""
    from app.analysis.recipe import order_recipe
    from app.analysis.settings import ProcessingSettings

    y, v, _, amp = railway_case(duration)
    recipe = order_recipe(D_W, 0.6, ProcessingSettings())
    warm_s = _warm_up()
    t0 = time.perf_counter()
    c0 = time.process_time()
    res = recipe.solve(y, FS, v)
    grid = np.arange(0, y.size, 24)
    env = res.envelope_at(grid)
    solve_s = time.perf_counter() - t0
    cpu_s = time.process_time() - c0
    edge = int(2 * FS)
    g = (grid >= edge) & (grid < y.size - edge)
    a_true = amp[0, grid]
    sleeper_err = float(np.sqrt(np.mean((np.abs(env[0, g]) - a_true[g]) ** 2) / np.mean(a_true[g] ** 2)))
    chunk = res.info["chunks"][0]
    return {
        "case": f"recipe, {len(recipe.labels)} orders (default settings), {duration:g} s @ 24 kHz",
        "seconds": solve_s,
        "rtf": duration / solve_s,
        "cpu_s": cpu_s,
        "warm_up_2s_solve_s": warm_s,
        "sleeper_rms_err": sleeper_err,
        "decimation": chunk["decimation"],
        "refinement_iterations": chunk["refinement_iterations"],
        "maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }


def case_memory(duration: float) -> dict:
    """Memory-mapped input, 1 kHz amplitude output into a memory-mapped array, block by block."""
    from app.analysis.orders import OrderTrack, railway_multipliers
    from app.analysis.vkf import vkf_stream

    n = int(duration * FS)
    tmp = Path(tempfile.mkdtemp(prefix="vkfbench-"))
    y = np.lib.format.open_memmap(tmp / "y.npy", mode="w+", dtype=np.float64, shape=(n,))
    v = np.lib.format.open_memmap(tmp / "v.npy", mode="w+", dtype=np.float64, shape=(n,))
    mult = railway_multipliers(D_W, 0.6, 11)
    rng = np.random.default_rng(0)
    block = 1 << 20
    cum = 0.0
    for a in range(0, n, block):
        b = min(a + block, n)
        t = np.arange(a, b) / FS
        vb = speed_profile(t, duration)
        v[a:b] = vb
        ph = 2.0 * np.pi * (cum + np.cumsum(vb)) / FS
        cum += float(vb.sum())
        y[a:b] = np.cos(np.outer(mult, ph)).sum(axis=0) + rng.normal(0.0, 3.0, b - a)
    y.flush()
    v.flush()
    del y, v
    y = np.load(tmp / "y.npy", mmap_mode="r")
    v = np.load(tmp / "v.npy", mmap_mode="r")
    step = 24
    out = np.lib.format.open_memmap(tmp / "amp.npy", mode="w+", dtype=np.float32, shape=(mult.size, -(-n // step)))
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    t0 = time.perf_counter()
    bw = OrderTrack(v, np.full(mult.size, 0.1 / (np.pi * D_W)))
    for block in vkf_stream(y, FS, OrderTrack(v, mult), bw, 2):  # the recipe of docs/vkf.md
        k = np.arange(-(-block.start // step) * step, block.stop, step)
        out[:, k // step] = np.abs(block.envelope_at(k - block.start))
    sec = time.perf_counter() - t0
    interior = np.asarray(out[0, 2000:-2000])
    for p in tmp.iterdir():
        p.unlink()
    tmp.rmdir()
    return {
        "case": f"vkf_stream, memory-mapped, 12 orders, {duration / 60:g} min @ 24 kHz, 1 kHz output",
        "seconds": sec,
        "rtf": duration / sec,
        "sleeper_amp_interior_mean": float(interior.mean()),
        "maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "maxrss_before_mb": base,
    }


CASES = {"engine": case_engine, "recipe": case_recipe, "sparse": case_sparse, "memory": case_memory}


def run_isolated(name: str, duration: float) -> dict:
    out = subprocess.run(
        [sys.executable, __file__, "--case", name, "--duration", str(duration)],
        check=True, capture_output=True, text=True, env={**os.environ, "OPENBLAS_NUM_THREADS": "1"},
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--case", choices=sorted(CASES))
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--sparse-duration", type=float, default=5.0)
    ap.add_argument("--memory", action="store_true", help="also run the 30-minute memory-mapped case")
    ap.add_argument("--no-sparse", action="store_true", help="leave out the direct sparse solve (21 s)")
    args = ap.parse_args()
    if args.case:
        print(json.dumps(CASES[args.case](args.duration)))
        return
    if args.no_sparse:
        for name in ("engine", "recipe"):
            r = run_isolated(name, args.duration)
            print(f"| {r['case']} | {r['seconds']:.2f} | {r['rtf']:.1f} | {r['cpu_s']:.2f} | "
                  f"{r['decimation']} | {r['refinement_iterations']} | {r['sleeper_rms_err']:.4f} |")
        return
    rows = [run_isolated("engine", args.duration), run_isolated("sparse", args.sparse_duration),
            run_isolated("recipe", args.duration)]
    if args.memory:
        rows.append(run_isolated("memory", 1800.0))
    eng, sps = rows[0], rows[1]
    sparse_per_s = sps["seconds"] / args.sparse_duration
    print("| case | wall s | x real time | peak RSS MB | notes |")
    print("|---|---|---|---|---|")
    for r in rows:
        notes = {k: (round(v, 4) if isinstance(v, float) else v) for k, v in r.items()
                 if k not in ("case", "seconds", "rtf", "maxrss_mb")}
        print(f"| {r['case']} | {r['seconds']:.2f} | {r['rtf']:.1f} | {r['maxrss_mb']:.0f} | {notes} |")
    print()
    print(f"direct sparse solve extrapolated linearly to {args.duration:g} s: {sparse_per_s * args.duration:.1f} s; "
          f"speed-up of the engine: {sparse_per_s * args.duration / eng['seconds']:.0f}x")


if __name__ == "__main__":
    main()
