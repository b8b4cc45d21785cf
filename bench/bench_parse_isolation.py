"""Cost of parsing an upload in a child process with a budget (app.io.isolation) vs in-process.

    .venv/bin/python bench/bench_parse_isolation.py [--length-km 1.2] [--repeat 5]

Writes a simulated recorder run (MDF4, about 26 MB at the default length) and the same run as
canonical HDF5, then ingests each alternately in this process and through
:func:`app.io.isolation.ingest_bounded` (a child forked from the fork server), ``--repeat`` times,
and prints the median wall time of each, the overhead, the first isolated call (which starts the
fork server) and the time of the structure checks alone. Baseline and isolated run side by side
in one process, so their ratio holds on a busy machine.
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from functools import partial
from pathlib import Path

from app.io import ingest
from app.io.isolation import ParseBudget, ingest_bounded, run_bounded
from app.io.limits import DEFAULT_LIMITS
from app.io.sources.mdf4_blocks import check_mdf4
from app.simulate.recorder import simulate_recorder_run


def _timed(fn) -> float:  # noqa: ANN001
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--length-km", type=float, default=1.2)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    budget = ParseBudget(600.0, 4 << 30)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        rec = simulate_recorder_run(tmp / "run.mf4", "mdf4", length_km=args.length_km)
        src = tmp / "run.mf4"
        meta = json.loads((tmp / "run.metadata.json").read_text())
        cmap = json.loads((tmp / "run.channel-map.json").read_text())
        canonical = tmp / "run.canonical.h5"
        print(f"MDF4 {src.stat().st_size / 1e6:.1f} MB, canonical HDF5 {canonical.stat().st_size / 1e6:.1f} MB "
              f"({type(rec).__name__})")
        start = _timed(lambda: run_bounded("os:getpid", budget=budget, what="nothing"))
        first = _timed(lambda: ingest_bounded(src, "mdf4", meta, tmp / "first.h5", budget=budget, channel_map=cmap))
        rows = []
        for name, path, kwargs in (("mdf4", src, {"channel_map": cmap}), ("hdf5", canonical, {})):
            fmt = name
            md = meta if name == "mdf4" else None
            here, there = [], []
            for k in range(args.repeat):
                here.append(_timed(partial(ingest, path, fmt, md, tmp / f"a{k}.h5", **kwargs)))
                there.append(_timed(partial(ingest_bounded, path, fmt, md, tmp / f"b{k}.h5", budget=budget,
                                            **kwargs)))
            rows.append((name, path.stat().st_size / 1e6, statistics.median(here), statistics.median(there)))
        with open(src, "rb") as fh:
            checks = statistics.median(_timed(lambda: check_mdf4(fh, src.stat().st_size, DEFAULT_LIMITS))
                                       for _ in range(args.repeat))
    print(f"starting the fork server (once per API process, at its first upload): {start:.2f} s; "
          f"first isolated ingest after it: {first:.2f} s")
    print(f"MDF4 structure check alone: {checks * 1000:.0f} ms")
    print("| file | MB | in-process s | isolated s | overhead s | overhead % |")
    print("|---|---|---|---|---|---|")
    for name, mb, here, there in rows:
        print(f"| {name} | {mb:.1f} | {here:.2f} | {there:.2f} | {there - here:+.2f} | {100 * (there / here - 1):+.0f} |")


if __name__ == "__main__":
    main()
