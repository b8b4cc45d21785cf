"""The stated uncertainty in the condition store, the change tests and the places: a grinding read as
a stiffness change or not (issue 26 items 3 and 5), through the real service.

Per seed a rough line (:func:`app.simulate.history.grinding_history`: 1.2 km, random rail roughness
fixed to the track, 10 runs a week apart at 126 km/h) is uploaded, processed by the local worker and
published (condition store, places) run by run; between the last two runs a grinding over 200 m
(recorded in the maintenance records before the last run is uploaded) and a real −30 % support change
over 20 m 250 m beside it. On the last run it compares, on the same stored rows:

* **before**: the change tests and places as they were before issue 26 item 3 — no stated 1-σ, no
  rail-surface interventions (the store's flags recomputed in a rolled-back transaction with the
  history's ``index_sd`` and the maintenance records removed; the places from ``find_places`` without
  the 1-σ);
* **no record**: the stated 1-σ, the grinding not recorded;
* **after**: what the service did (stated 1-σ, the grinding recorded).

Usage::

    .venv/bin/python bench/bench_uncertainty.py [--seeds 21 22] [--workdir /tmp/uncertainty-bench]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sqlalchemy import select  # noqa: E402

from app.simulate.history import grinding_history  # noqa: E402


def _inside(seg: int, extent: tuple[float, float], margin_m: float = 0.0) -> bool:
    return extent[0] - margin_m <= (seg + 0.5) * 10.0 < extent[1] + margin_m


def one(seed: int, workdir: Path) -> dict:
    from app.db.models import ConditionFlag, PlaceObservation
    from app.db.models import SegmentCondition as SC
    from app.db.session import Database
    from tests.condition.history_support import (
        history_service,
        places_without_sd,
        process_history,
        store_flags_without,
    )

    spec, info = grinding_history(seed=seed)
    ground, soft = info["ground"], info["soft"]
    n = len(spec.runs)
    root = Path(tempfile.mkdtemp(prefix=f"seed{seed}-", dir=workdir))
    t0 = time.perf_counter()
    with history_service(root) as client:
        first = process_history(client, spec, workdir / "files", runs=slice(0, n - 1))
        r = info["maintenance"]
        csv = root / "grinding.csv"
        csv.write_text("line_id,track,km_from,km_to,type,date\n"
                       f"{r['line_id']},{r['track']},{r['km_from']:.3f},{r['km_to']:.3f},{r['type']},{r['date']}\n")
        with open(csv, "rb") as fh:
            resp = client.post("/api/v1/reference/maintenance", params={"mode": "append"},
                               files={"file": (csv.name, fh)})
        assert resp.status_code in (200, 201), resp.text
        last = process_history(client, spec, workdir / "files", runs=slice(n - 1, n), reference=False)
        url = client.settings.database_url
    wall = time.perf_counter() - t0
    run_ids, job_id = first.run_ids + last.run_ids, last.jobs[-1]["id"]
    db = Database(url)
    try:
        with db.read() as s:
            after = [(int(f.seg), int(f.direction)) for f in s.scalars(select(ConditionFlag).where(
                ConditionFlag.run_id == run_ids[-1], ConditionFlag.kind == "step", ConditionFlag.seg_m == 10))]
            sd10 = np.array(s.scalars(select(SC.condition_index_sd).where(SC.seg_m == 10, SC.run_id.in_(run_ids))).all(),
                            dtype=float)
            obs = list(s.scalars(select(PlaceObservation).where(PlaceObservation.run_id == run_ids[-1])))
            earlier = [(int(f.seg), int(f.direction)) for f in s.scalars(select(ConditionFlag).where(
                ConditionFlag.run_id.in_(run_ids[:-1]), ConditionFlag.kind == "step", ConditionFlag.seg_m == 10))]
        norec, _ = store_flags_without(db, run_ids[-1], job_id, line_id=spec.line_id, track=spec.track)
        before, _ = store_flags_without(db, run_ids[-1], job_id, line_id=spec.line_id, track=spec.track,
                                        stated_sd=False)
        places_before = places_without_sd(db, run_ids[-1])
    finally:
        db.dispose()

    def flags(fl: list) -> dict:
        return {"ground": sum(1 for f in fl if _inside(f[0], ground, 15.0)),
                "soft found": any(_inside(f[0], soft) and f[1] == -1 for f in fl),
                "elsewhere": sum(1 for f in fl if not _inside(f[0], ground, 15.0) and not _inside(f[0], soft, 10.0))}

    def over(a: float, b: float, ext: tuple[float, float]) -> bool:
        return a < ext[1] and b > ext[0]

    pl_after = [(o.start_m, o.end_m, o.evidence) for o in obs]
    return {
        "seed": seed, "wall_s": round(wall), "median 10 m index_sd": float(np.nanmedian(sd10)),
        "store before": flags([(f[0], f[1]) for f in before]), "store no record": flags([(f[0], f[1]) for f in norec]),
        "store after": flags(after), "earlier runs' flags": len(earlier),
        "places before": {"all": len(places_before),
                          "step over ground": sum(1 for p in places_before if p[2] & 2 and over(p[0], p[1], ground)),
                          "soft found": any(p[2] & 2 and over(p[0], p[1], soft) for p in places_before)},
        "places after": {"all": len(pl_after),
                         "step over ground": sum(1 for p in pl_after if p[2] & 2 and over(p[0], p[1], ground)),
                         "soft found": any(p[2] & 2 and over(p[0], p[1], soft) for p in pl_after)},
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[21])
    ap.add_argument("--workdir", type=Path, default=Path("/tmp/uncertainty-bench"))
    args = ap.parse_args(argv)
    args.workdir.mkdir(parents=True, exist_ok=True)
    print("| seed | median 10 m index_sd | step flags over the ground stretch (±15 m): before / no record / after "
          "| −30 % change flagged: before / after | other step flags, last run: before / after | places on the last "
          "run: before / after | step places over the ground: before / after | wall |")
    print("|---|---|---|---|---|---|---|---|")
    for seed in args.seeds:
        r = one(seed, args.workdir)
        b, nr, a = r["store before"], r["store no record"], r["store after"]
        pb, pa = r["places before"], r["places after"]
        print(f"| {seed} | {r['median 10 m index_sd']:.3f} | {b['ground']} / {nr['ground']} / {a['ground']} | "
              f"{'yes' if b['soft found'] else 'no'} / {'yes' if a['soft found'] else 'no'} | "
              f"{b['elsewhere']} / {a['elsewhere']} | {pb['all']} / {pa['all']} | "
              f"{pb['step over ground']} / {pa['step over ground']} | {r['wall_s']} s |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
