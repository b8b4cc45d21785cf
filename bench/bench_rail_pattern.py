"""The rails' own pattern in the store's 10 m index on the real line (issue 33): does it repeat from pass to
pass, across the two speed groups and the two vehicles, and how large is a lasting place against it?

On rough rails the sleeper-passage amplitude is ``|S + R|``: the support's response and the rails' at the
sleeper frequency. The rails do not change between runs, so their part of a segment's index is a pattern
along the line, not noise of a pass; a lasting place is read against that pattern. Averaging passes takes it
out only as far as it changes with the speed and the vehicle (the wheel–track receptance at the sleeper
frequency). Per seed, from the histories :mod:`bench_real_line` processed (made first where missing):

* per run and 10 m segment the **contrast**: the store's index (mean over the wheels) less the median of the
  run's segments within ±100 m (what the run shares along the stretch: its speed, the sensors, the class);
* the runs in **groups** by vehicle and speed group (26 / 40 m/s), the contrast averaged within each group;
* over the **clean** segments (the cruise stretch, 20 m and more from every planted place, off the ground
  stretch): the correlation of the group means between groups, the scatter of one group's means along the
  line (the pattern), the scatter of the passes within a group (pass to pass), and the scatter of the mean
  over all groups (what averaging every pass leaves);
* each **lasting** place of the truth (``anomaly``): its segments' group means and their mean over the
  groups, against that scatter.

Usage::

    .venv/bin/python bench/bench_rail_pattern.py [--seeds 0 1 2] [--workdir /tmp/real-line-bench]
"""

from __future__ import annotations

import argparse
import sys
from itertools import combinations
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from app.simulate.history import REAL_LINE_SPEEDS_MPS, HistorySpec, real_line_history  # noqa: E402

#: Half-width of the stretch a segment's contrast is taken against, segments of 10 m.
AROUND_SEGMENTS = 10
#: Segments this close to a planted place (m) are not clean.
PLACE_MARGIN_M = 20.0


def _rows(root: Path) -> tuple[dict[int, str], np.ndarray]:
    """Per run its vehicle, and ``(run_id, seg, index, speed)`` of every 10 m segment (mean over the wheels)."""
    from sqlalchemy import func, select

    from app.db.models import ConditionRun, Run, SegmentCondition
    from app.db.session import Database

    db = Database(f"sqlite:///{root / 'db.sqlite'}")
    try:
        with db.read() as s:
            vehicles = {int(r): str(v) for r, v in s.execute(
                select(ConditionRun.run_id, Run.vehicle_id).join(Run, Run.id == ConditionRun.run_id))}
            sc = SegmentCondition
            rows = np.array(s.execute(
                select(sc.run_id, sc.seg, func.avg(sc.condition_index), func.avg(sc.speed_mean))
                .where(sc.seg_m == 10).group_by(sc.run_id, sc.seg).order_by(sc.run_id, sc.seg)).all(), dtype=float)
    finally:
        db.dispose()
    return vehicles, rows


def pattern(spec: HistorySpec, root: Path) -> dict:
    """The group means of the contrast and their statistics (module docstring)."""
    vehicles, rows = _rows(root)
    segs = np.arange(int(rows[:, 1].min()), int(rows[:, 1].max()) + 1)
    centres = (segs + 0.5) * 10.0
    runs = sorted(vehicles)
    index = np.full((len(runs), segs.size), np.nan)
    speed = np.full_like(index, np.nan)
    for i, r in enumerate(runs):
        mine = rows[rows[:, 0] == r]
        k = (mine[:, 1] - segs[0]).astype(int)
        index[i, k], speed[i, k] = mine[:, 2], mine[:, 3]
    contrast = np.full_like(index, np.nan)
    for j in range(segs.size):
        lo, hi = max(0, j - AROUND_SEGMENTS), j + AROUND_SEGMENTS + 1
        contrast[:, j] = index[:, j] - np.nanmedian(index[:, lo:hi], axis=1)
    cruise = spec.ramps()
    planted = spec.truth_places(spec.runs[-1].day)
    lasting = [p for p in planted if p.kind == "anomaly"]
    clean = (centres > cruise[0]) & (centres < cruise[1])
    for p in planted:
        clean &= (centres < p.track_from_m - PLACE_MARGIN_M) | (centres > p.track_to_m + PLACE_MARGIN_M)
    for g in spec.line.surface.grindings if spec.line.surface is not None else ():
        clean &= (centres < g.track_from_m) | (centres > g.track_to_m)
    groups: dict[tuple[str, float], list[int]] = {}
    for i, r in enumerate(runs):
        v = float(np.nanmedian(speed[i, clean]))
        group = min(REAL_LINE_SPEEDS_MPS, key=lambda c: abs(c - v))
        groups.setdefault((vehicles[r][-2:], group), []).append(i)
    names = sorted(groups)
    means = {g: np.nanmean(contrast[groups[g]], axis=0) for g in names}
    within = {g: float(np.nanmedian(np.nanstd(contrast[groups[g]][:, clean], axis=0, ddof=1)))
              for g in names if len(groups[g]) > 1}
    corr: dict[str, list[float]] = {"other vehicle, same speed": [], "same vehicle, other speed": [],
                                    "other vehicle and speed": []}
    for a, b in combinations(names, 2):
        ok = clean & np.isfinite(means[a]) & np.isfinite(means[b])
        c = float(np.corrcoef(means[a][ok], means[b][ok])[0, 1])
        key = ("other vehicle, same speed" if a[1] == b[1] else
               "same vehicle, other speed" if a[0] == b[0] else "other vehicle and speed")
        corr[key].append(c)
    overall = np.nanmean(np.array([means[g] for g in names]), axis=0)
    places = []
    for p in lasting:
        on = (centres >= p.track_from_m) & (centres < p.track_to_m)
        places.append({"km": (p.track_from_m / 1000.0, p.track_to_m / 1000.0), "truth": p.log_change,
                       "groups": {f"{g[0]} {g[1]:g} m/s": np.round(means[g][on], 2).tolist() for g in names},
                       "all passes": np.round(overall[on], 2).tolist()})
    clean_all = overall[clean & np.isfinite(overall)]
    beyond = {f"{x:g}": int(np.sum(clean_all <= -x)) for x in (0.5, 0.7, 0.9)}
    return {"groups": {f"{g[0]} {g[1]:g} m/s": len(groups[g]) for g in names},
            "clean_below": beyond,
            "clean_segments": int(clean.sum()),
            "corr": {k: (float(np.mean(v)) if v else float("nan")) for k, v in corr.items()},
            "pattern_sd": float(np.mean([np.nanstd(means[g][clean]) for g in names])),
            "pass_sd": float(np.mean(list(within.values()))) if within else float("nan"),
            "all_passes_sd": float(np.nanstd(overall[clean])),
            "lasting": places}


def main(argv: list[str] | None = None) -> int:
    from bench_real_line import build

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--workdir", type=Path, default=Path("/tmp/real-line-bench"))
    args = ap.parse_args(argv)
    args.workdir.mkdir(parents=True, exist_ok=True)
    out = []
    for seed in args.seeds:
        spec = real_line_history(seed=seed)
        out.append((seed, pattern(spec, build(spec, args.workdir))))
    print("| seed | runs per group | clean segments | correlation of the group means: other vehicle, same speed / "
          "same vehicle, other speed / both other | pattern: sd along the line, one group | pass to pass, within "
          "a group | sd of the mean over all passes | clean segments whose mean over all passes reads ≤ −0.5 / −0.7 / "
          "−0.9 |")
    print("|---|---|---|---|---|---|---|---|")
    for seed, r in out:
        c = r["corr"]
        print(f"| {seed} | {', '.join(f'{k}: {v}' for k, v in r['groups'].items())} | {r['clean_segments']} | "
              f"{c['other vehicle, same speed']:+.2f} / {c['same vehicle, other speed']:+.2f} / "
              f"{c['other vehicle and speed']:+.2f} | {r['pattern_sd']:.2f} | {r['pass_sd']:.3f} | "
              f"{r['all_passes_sd']:.2f} | {' / '.join(str(v) for v in r['clean_below'].values())} |")
    print("\n| seed | lasting place (km), truth | its segments per group | mean over all passes | in units of that sd |")
    print("|---|---|---|---|---|")
    for seed, r in out:
        for p in r["lasting"]:
            per = "; ".join(f"{g} {v}" for g, v in p["groups"].items())
            z = np.round(np.array(p["all passes"]) / r["all_passes_sd"], 1).tolist()
            print(f"| {seed} | {p['km'][0]:.3f}–{p['km'][1]:.3f}, {p['truth']:+.2f} | {per} | {p['all passes']} | {z} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
