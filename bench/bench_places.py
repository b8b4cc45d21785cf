"""Which criterion turns the condition store into a work list of places: measured on fleet histories
through the real pipeline.

Two histories of :mod:`app.simulate.history` (12 runs of a 2.4 km line two weeks apart, each a full
4-wheel signal uploaded, processed by the local worker and published into the condition store; speed
ramps 65 → cruise over the first 500 m and cruise → 60 km/h over the last 400 m, cruise speeds spread
over ±10 %, start odometry errors N(0, 5 m)):

* ``uniform``: one superstructure type, nothing planted — every place is a false one;
* ``planted``: three sections, a lasting soft and hard spot, two new changes (−20 %, +25 % over 20 m),
  a developing place and a tamping over it.

For every run (as the publish step would see it: the curves fitted on the runs up to it) the anomaly
criteria below are evaluated per 10 m segment (mean over the wheels), the exceeding segments merged into
places (:func:`app.analysis.condition.places.merge_places`, gap 10 m) and scored against the truth
(:meth:`app.simulate.history.HistorySpec.truth_places`; a place is *real* when it overlaps a planted
feature present that day, ±10 m):

``lnA_z``   the current work list's anomaly: robust z of ``ln A`` against the segments of its class in
            the same run, at whatever speed (threshold 3.5);
``idx_z``   the same robust z of the speed-conditioned stiffness index ``ln(A / A_ref(class, v))``;
``idx_lvl`` the index itself beyond a level (ln units) — a tier limit;
``step``    the stored matched-speed step test (|Σz/√n| ≥ 4.5, the store's flags);
``trend``   the stored trend test of the 100 m holding the segment.

It also prints the distribution of the index of healthy segments per class (for the tier and
section-class defaults).

Usage::

    .venv/bin/python bench/bench_places.py [--workdir /tmp/places-bench] [--seeds 0] [--runs 12]
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from sqlalchemy import select

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app.analysis.condition.change import combine_wheels  # noqa: E402
from app.analysis.condition.extent_level import extent_level  # noqa: E402
from app.analysis.condition.interventions import latest_action_days
from app.analysis.condition.lifecycle import (  # noqa: E402
    Action,
    LifecycleParams,
    PlaceState,
    advance_places,
    severity_trend,
)
from app.analysis.condition.maintenance_effect import action_effect  # noqa: E402
from app.analysis.condition.outlook import time_to_limit  # noqa: E402
from app.analysis.condition.places import merge_places  # noqa: E402
from app.analysis.condition.run_places import (  # noqa: E402
    DEFAULT_CHANGE_LIMITS,
    DEFAULT_LEVEL_LIMITS,
    DEFAULT_PLACE_PARAMS,
    PlaceParams,
    find_places,
    segment_index,
)
from app.analysis.condition.section_class import DEFAULT_SECTION_LIMITS, section_classes  # noqa: E402
from app.analysis.condition.segment_curves import fit_segment_curves  # noqa: E402
from app.analysis.condition.tiers import TierLimits, TierTable, rank_places  # noqa: E402
from app.analysis.robust import robust_spread  # noqa: E402
from app.analysis.stiffness.reference_curve import fit_reference_from_rows  # noqa: E402
from app.analysis.stiffness.superstructure import section_classes as superstructure_classes  # noqa: E402
from app.simulate.history import HistorySpec, TruthPlace, planted_history, uniform_history  # noqa: E402

SEG_M = 10.0


@dataclass
class RunData:
    run_id: int
    day: float
    shift_m: float
    seg: np.ndarray            # (S,)
    wheels: list[str]
    log_amp: np.ndarray        # (W, S)
    speed: np.ndarray          # (W, S) m/s
    change_z: np.ndarray       # (W, S)
    change: np.ndarray         # (W, S)
    trend_z: np.ndarray        # (W, S) of the 100 m parent
    index_sd: np.ndarray | None = None  # (W, S) the stated 1-σ of log_amp (NaN: none)


def build(which: str, seed: int, n_runs: int, workdir: Path) -> tuple[HistorySpec, str]:
    """The history's database (made once per spec; reused)."""
    from tests.condition.history_support import history_service, process_history

    spec = (planted_history if which == "planted" else uniform_history)(seed=seed, n_runs=n_runs)
    root = workdir / f"db-{which}-{seed}-{spec.fingerprint()}"
    url = f"sqlite:///{root / 'db.sqlite'}"
    if (root / "done").is_file():
        return spec, url
    shutil.rmtree(root, ignore_errors=True)
    root.mkdir(parents=True)
    t0 = time.perf_counter()
    with history_service(root) as client:
        process_history(client, spec, workdir / "files")
    (root / "done").write_text(f"{time.perf_counter() - t0:.0f} s\n")
    print(f"  {which} seed {seed}: {n_runs} runs through the pipeline in {time.perf_counter() - t0:.0f} s",
          flush=True)
    return spec, url


def load(url: str, spec: HistorySpec) -> tuple[list[RunData], pd.DataFrame, pd.DataFrame]:
    """Segment rows per run (10 m, all wheels), the 25 cm rows of every run and the sections."""
    from app.analytics.frames import analytics_frame
    from app.db import reference_crud, results_reader
    from app.db.models import ConditionLine, ConditionRun
    from app.db.models import SegmentCondition as SC
    from app.db.session import Database

    db = Database(url)
    try:
        with db.read() as s:
            line = s.scalar(select(ConditionLine).where(ConditionLine.line_id == spec.line_id))
            runs = s.execute(select(ConditionRun.run_id, ConditionRun.run_time, ConditionRun.shift_m)
                             .where(ConditionRun.line_key == line.id).order_by(ConditionRun.run_time)).all()
            out = []
            for run_id, when, shift in runs:
                day = (when.replace(tzinfo=spec.start.tzinfo) - spec.start).total_seconds() / 86400.0
                rows = pd.DataFrame(s.execute(select(SC.seg_m, SC.wheel, SC.seg, SC.condition_index, SC.speed_mean,
                                                     SC.change_z, SC.change, SC.trend_z, SC.condition_index_sd)
                                              .where(SC.run_id == run_id)).all(),
                                    columns=["seg_m", "wheel", "seg", "index", "speed", "change_z", "change",
                                             "trend_z", "index_sd"])
                r10, r100 = rows[rows.seg_m == 10], rows[rows.seg_m == 100]
                seg = np.sort(r10.seg.unique())
                wheels = sorted(r10.wheel.unique())
                mats = {k: np.full((len(wheels), seg.size), np.nan) for k in
                        ("index", "speed", "change_z", "change", "trend_z", "index_sd")}
                for i, w in enumerate(wheels):
                    a = r10[r10.wheel == w]
                    j = np.searchsorted(seg, a.seg.to_numpy())
                    for k in ("index", "speed", "change_z", "change", "index_sd"):
                        mats[k][i, j] = a[k].to_numpy(dtype=float)
                    b = r100[r100.wheel == w].set_index("seg")["trend_z"]
                    mats["trend_z"][i] = b.reindex(seg * 10 // 100).to_numpy(dtype=float)
                out.append(RunData(run_id, day, float(shift), seg, wheels, mats["index"], mats["speed"],
                                   mats["change_z"], mats["change"], mats["trend_z"], mats["index_sd"]))
            jobs = results_reader.result_jobs(s, results_reader.runs_with_results(s, spec.line_id, spec.track))
            bins = analytics_frame(s, jobs, bin_length_m=0.25, min_speed_kmh=25.0, edge_trim_m=50.0,
                                                 columns=("speed_mean", "sleeper_amp"))
            sections = reference_crud.reference_frame(s, "superstructure", line_id=spec.line_id, track=spec.track)
    finally:
        db.dispose()
    return out, bins, sections


def classes_of(sections: pd.DataFrame, pos: np.ndarray, margin_m: float = 50.0) -> np.ndarray:
    return superstructure_classes(pos, sections["km_from"].to_numpy() * 1000.0, sections["km_to"].to_numpy() * 1000.0,
                           sections["type"].to_numpy(dtype=object), boundary_margin_m=margin_m)


def _on(src: RunData, dst: RunData, values: np.ndarray) -> np.ndarray:
    """(W, S) values of run ``src`` on the segments and wheels of ``dst`` (NaN where none)."""
    out = np.full((len(dst.wheels), dst.seg.size), np.nan)
    j = np.minimum(np.searchsorted(src.seg, dst.seg), src.seg.size - 1)
    hit = src.seg[j] == dst.seg
    for i, w in enumerate(dst.wheels):
        if w in src.wheels:
            out[i, hit] = values[src.wheels.index(w), j[hit]]
    return out


def _class_z(values: np.ndarray, classes: np.ndarray) -> np.ndarray:
    """Robust z of each value against the values of its class (the retired hotspot list's anomaly)."""
    z = np.full(values.shape, np.nan)
    for c in np.unique(classes):
        m = classes == c
        med, spread = robust_spread(values[..., m], axis=-1)
        with np.errstate(invalid="ignore", divide="ignore"):
            z[..., m] = np.where(spread[..., None] > 0, (values[..., m] - med[..., None]) / spread[..., None], np.nan)
    return z


def mean_w(a: np.ndarray) -> np.ndarray:
    ok = np.isfinite(a)
    n = ok.sum(axis=0)
    with np.errstate(invalid="ignore"):
        return np.where(n > 0, np.where(ok, a, 0).sum(axis=0) / np.maximum(n, 1), np.nan)


def overlaps(a: float, b: float, t: TruthPlace, tol_m: float = 10.0) -> bool:
    return t.track_from_m < b + tol_m and a - tol_m < t.track_to_m


def variants() -> dict[str, PlaceParams]:
    """The work-list designs compared (level limits per class on |index|, change limits on |change|); a
    name ending in "(store curves)" uses the curves fitted to the store's 10 m rows, the others the curves
    of the 25 cm rows."""
    return {
        "level 0.25 + step": PlaceParams(TierTable(TierLimits(0.25, 0.375, 0.625)), DEFAULT_CHANGE_LIMITS),
        "per class + step": DEFAULT_PLACE_PARAMS,
        "per class + step (store curves)": DEFAULT_PLACE_PARAMS,
        "per class + step (store curves, ≥ 40 locations)": DEFAULT_PLACE_PARAMS,
        CHOSEN: DEFAULT_PLACE_PARAMS,
        STATED: DEFAULT_PLACE_PARAMS,
    }


DEFAULT_LEVELS = DEFAULT_LEVEL_LIMITS
MIN_LOCATIONS = (0, 40, 80)
CHOSEN = "per class + step (store curves, ≥ 80 locations)"
#: the chosen design with the stated 1-σ of the store's rows (issue 26: step denominators, tiers on the lower
#: bound); the chosen design above is the same code without it (NaN sd: as before), so the two compare in one run
STATED = CHOSEN + " + stated 1-σ"


def evaluate(which: str, seed: int, spec: HistorySpec, url: str, results: list[dict], healthy: list[pd.DataFrame],
             centre_err: list[dict]) -> None:
    runs, bins, sections = load(url, spec)
    life: dict[str, tuple[list[PlaceState], int, list[int]]] = {}
    actions = [Action(i + 1, c.track_from_m, c.track_to_m, c.day) for i, c in enumerate(spec.changes)
               if c.kind == "tamping"]
    ramp_lo = spec.km_start * 1000 + spec.ramp_in_m
    ramp_hi = spec.km_start * 1000 + spec.length_km * 1000 - spec.ramp_out_m
    for k, run in enumerate(runs):
        truth = spec.truth_places(run.day)
        centres = (run.seg + 0.5) * SEG_M
        cls = classes_of(sections, centres)
        cls_lbl = np.array(["-" if c is None else c for c in cls.tolist()], dtype=object)
        curves = fit_curves(bins, sections, [r.run_id for r in runs[:k + 1]])
        store_curves = {n: fit_store_curves(runs[:k + 1], sections, n) for n in MIN_LOCATIONS}
        idx = segment_index(run.log_amp, run.speed, cls, curves)
        hist = np.stack([_on(runs[j], run, segment_index(runs[j].log_amp, runs[j].speed,
                                                         classes_of(sections, (runs[j].seg + 0.5) * SEG_M), curves))
                         for j in range(k)], axis=2) if k else np.zeros((*idx.shape, 0))
        idx_s, hist_s = {}, {}
        for n, sc in store_curves.items():
            idx_s[n] = segment_index(run.log_amp, run.speed, cls, sc)
            hist_s[n] = np.stack([_on(runs[j], run, segment_index(runs[j].log_amp, runs[j].speed,
                                                                  classes_of(sections, (runs[j].seg + 0.5) * SEG_M),
                                                                  sc))
                                  for j in range(k)], axis=2) if k else np.zeros((*idx.shape, 0))
        days = np.array([r.day for r in runs[:k]])
        ln_a = mean_w(run.log_amp)
        found_by: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = {}
        found_tiers: dict[str, np.ndarray] = {}
        # ln A against its class (the retired hotspot list's anomaly) and the stored matched-speed step test
        z_a = _class_z(ln_a, cls_lbl)
        p = merge_places(run.seg, z_a, np.abs(z_a) >= 3.5, segment_m=SEG_M, gap_m=10.0)
        found_by["current: lnA z 3.5"] = (p.start_m, p.end_m, p.centre_m, np.argsort(-np.abs(p.peak)))
        cz, _ = combine_wheels(run.change_z, 2.0)
        p = merge_places(run.seg, cz, np.abs(np.nan_to_num(cz)) >= 4.5, segment_m=SEG_M, gap_m=10.0)
        found_by["stored step (lnA, matched speed)"] = (p.start_m, p.end_m, p.centre_m, np.argsort(-np.abs(p.peak)))
        covered = (float(run.seg.min() * SEG_M), float((run.seg.max() + 1) * SEG_M))
        # every design: a segment's history starts anew after the tamping over it, as the service reads it
        support = latest_action_days(run.seg, SEG_M, np.array([a.start_m for a in actions]),
                                     np.array([a.end_m for a in actions]), np.array([a.day for a in actions]), run.day)
        for name, params in variants().items():
            if name == STATED:
                n = MIN_LOCATIONS[-1]
                hist_sd = np.stack([_on(runs[j], run, runs[j].index_sd) for j in range(k)], axis=2) if k \
                    else np.zeros((*idx.shape, 0))
                rp = find_places(run.seg, idx_s[n], hist_s[n], days, run.day, cls, segment_m=SEG_M, params=params,
                                 index_sd=run.index_sd, history_sd=hist_sd, support_days=support)
                tier_log.append({"history": which, "seed": seed, "run": k,
                                 "median index_sd": float(np.nanmedian(run.index_sd)),
                                 "places": len(rp), "tier >= 2": int((rp.tier >= 2).sum()),
                                 "tier >= 2 without sd": int((found_tiers.get(CHOSEN, np.zeros(0)) >= 2).sum()),
                                 "median severity_sd": float(np.nanmedian(rp.severity_sd)) if len(rp) else np.nan})
            elif "store curves" in name:
                n = int(name.split("≥ ")[1].split(" ")[0]) if "≥" in name else 0
                rp = find_places(run.seg, idx_s[n], hist_s[n], days, run.day, cls, segment_m=SEG_M, params=params,
                                 support_days=support)
            else:
                rp = find_places(run.seg, idx, hist, days, run.day, cls, segment_m=SEG_M, params=params,
                                 support_days=support)
            order = rank_places(rp.tier, np.full(len(rp), np.nan), rp.severity)
            found_tiers[name] = rp.tier
            found_by[name] = (rp.places.start_m, rp.places.end_m, rp.places.centre_m, order)
            # the same design with the lifecycle: the work list holds the listed, active places
            known, next_id, n_alerts = life.setdefault(name, ([], 1, {}))
            events, _, next_id = advance_places(known, rp, run_id=run.run_id, day=run.day, covered_m=covered,
                                                params=LIFECYCLE, next_id=next_id, place_params=params,
                                                actions=actions)
            for e in events:
                if e.kind == "repaired" and name == CHOSEN:
                    kp = next(x for x in known if x.id == e.place_id)
                    repaired.append({"history": which, "seed": seed, "run": k, "place km": f"{kp.start_m / 1000:.3f}"
                                     f"–{kp.end_m / 1000:.3f}", "action": e.action_id,
                                     "effect places explained": sum(1 for x in known if x.explained_by == e.action_id)})
            life[name] = (known, next_id, n_alerts)
            for e in events:
                n_alerts[e.kind] = n_alerts.get(e.kind, 0) + 1
                if name == CHOSEN:
                    kp = next(x for x in known if x.id == e.place_id)
                    alert_log.append({"history": which, "seed": seed, "run": k, "kind": e.kind, "place": e.place_id,
                                      "km": f"{kp.start_m / 1000:.3f}–{kp.end_m / 1000:.3f}",
                                      "tier": f"{e.old_tier}→{e.new_tier}",
                                      "real": any(overlaps(kp.start_m, kp.end_m, t) for t in truth)})
            listed = [kp for kp in known if kp.listed and kp.active]
            tiers = np.array([kp.tier for kp in listed], dtype=np.int64)
            sev = np.array([kp.observations[-1].severity for kp in listed])
            days_next = np.array([time_to_limit(severity_trend(kp), float(
                DEFAULT_LEVELS.next_limit(np.array([kp.tier]), np.array([kp.cls], dtype=object))[0])).days
                for kp in listed])
            order = rank_places(tiers, days_next, sev) if listed else np.zeros(0, np.int64)
            found_by[name + " | listed"] = (np.array([kp.start_m for kp in listed]),
                                            np.array([kp.end_m for kp in listed]),
                                            np.array([kp.observations[-1].centre_m for kp in listed]), order)
            alerts_by[(which, seed, name)] = dict(n_alerts)
            tamp = [c.day for c in spec.changes if c.kind == "tamping"]
            if name == CHOSEN and tamp and k + 1 < len(runs) and runs[k + 1].day > tamp[0] > run.day:
                for t in (t for t in truth if t.kind == "developing"):
                    for kp in listed:
                        if overlaps(kp.start_m, kp.end_m, t):
                            tr = severity_trend(kp)
                            nxt = float(DEFAULT_LEVELS.next_limit(np.array([kp.tier]),
                                                                   np.array([kp.cls], dtype=object))[0])
                            trends.append({"history": which, "seed": seed, "run": k, "truth_per_year": 1.2,
                                           "rate": tr.rate_per_year, "low": tr.low_per_year,
                                           "high": tr.high_per_year, "runs": tr.n, "tier": kp.tier,
                                           "days_to_next": time_to_limit(tr, nxt).days})
        for name, (a, b, c, order) in found_by.items():
            real = np.array([any(overlaps(a[i], b[i], t) for t in truth) for i in range(a.size)], dtype=bool)
            ramp = (a < ramp_lo) | (b > ramp_hi)
            top = real[order[:10]]
            row = {"history": which, "seed": seed, "run": k, "day": run.day, "design": name, "places": int(a.size),
                   "false": int((~real).sum()), "false_on_ramps": int((~real & ramp).sum()),
                   "top10_real": float(top.mean()) if top.size else np.nan,
                   "tested_step": float(np.isfinite(cz).mean()) if name.startswith("stored") else np.nan}
            for kind in ("anomaly", "change", "developing"):
                ts = [t for t in truth if t.kind == kind]
                if ts:
                    row[f"found_{kind}"] = float(np.mean([any(overlaps(a[i], b[i], t) for i in range(a.size))
                                                          for t in ts]))
            for t in truth:
                if t.kind == "change":
                    hit = [i for i in range(a.size) if overlaps(a[i], b[i], t)]
                    if hit:
                        centre_err.append({"design": name, "history": which, "seed": seed, "run": k,
                                           "err_m": min(abs(c[i] - t.centre_m) for i in hit), "n_places": len(hit)})
            results.append(row)
        # healthy segments: 30 m away from every planted feature, ever
        far = np.ones(run.seg.size, bool)
        for t in [*spec.truth_places(1e9), *[TruthPlace(c.kind, c.track_from_m, c.track_to_m, 0.0, c.day)
                                            for c in spec.changes]]:
            far &= ~((centres > t.track_from_m - 30) & (centres < t.track_to_m + 30))
        on_ramp = (centres < ramp_lo) | (centres > ramp_hi)
        healthy.append(pd.DataFrame({"history": which, "seed": seed, "run": k, "cls": cls_lbl[far],
                                     "index": mean_w(idx_s[MIN_LOCATIONS[-1]])[far], "ramp": on_ramp[far], "seg": run.seg[far]}))
    # section classes of the newest run: the class of the sections holding a planted feature, and the others
    run = runs[-1]
    sc = section_classes(run.seg, mean_w(idx_s[MIN_LOCATIONS[-1]]), segment_m=SEG_M, limits=DEFAULT_SECTION_LIMITS)
    planted = np.zeros(len(sc), bool)
    for t in spec.truth_places(run.day):
        if t.kind != "tamping":
            planted |= (sc.start_m < t.track_to_m) & (t.track_from_m < sc.end_m)
    sections_out.append({"history": which, "seed": seed,
                         "healthy": " ".join(sorted(c or "-" for c in sc.cls[~planted])),
                         "with a planted place": " ".join(c or "-" for c in sc.cls[planted])})
    for t in (c for c in spec.changes if c.kind == "tamping"):
        effects.append({"history": which, "seed": seed, "truth_pct": 100 * np.expm1(spec.tamping_effect(t)),
                        **tamping_effect(runs, sections, t)})


def tamping_effect(runs: list[RunData], sections: pd.DataFrame, action) -> dict[str, float]:
    """The tamping's effect (% of the amplitude) from ``ln A`` and from the index, each relative to the
    surrounding ±1 km of the same run or absolute; the index with the curves of the store's rows of all runs."""
    curves = fit_store_curves(runs, sections, MIN_LOCATIONS[-1])
    days = np.array([r.day for r in runs])
    out = {}
    for name in ("lnA relative", "index relative", "index absolute"):
        vals = []
        for run in runs:
            if name.startswith("index"):
                centres = (run.seg + 0.5) * SEG_M
                x = mean_w(segment_index(run.log_amp, run.speed, classes_of(sections, centres), curves))
            else:
                x = mean_w(run.log_amp)
            vals.append(extent_level(run.seg, x, action.track_from_m, action.track_to_m, segment_m=SEG_M,
                                     relative=name.endswith("relative")))
        eff = action_effect(days, np.array(vals), action.day)
        out[name] = 100 * np.expm1(eff.recovery) if eff.recovery is not None else np.nan
    return out


effects: list[dict] = []
sections_out: list[dict] = []
repaired: list[dict] = []
trends: list[dict] = []


alerts_by: dict[tuple[str, int, str], dict[str, int]] = {}
alert_log: list[dict] = []
tier_log: list[dict] = []
LIFECYCLE = LifecycleParams()


def fit_store_curves(runs: list[RunData], sections: pd.DataFrame, min_locations: int = 0) -> dict:
    """The reference curves from the store's 10 m rows of ``runs`` (:mod:`app.analysis.condition.segment_curves`)."""
    parts = []
    for r in runs:
        cls = classes_of(sections, (r.seg + 0.5) * SEG_M)
        for i, w in enumerate(r.wheels):
            parts.append((r.seg, r.log_amp[i], r.speed[i], np.full(r.seg.size, r.run_id), np.full(r.seg.size, w), cls))
    cols = [np.concatenate([p[j] for p in parts]) for j in range(6)]
    return fit_segment_curves(*cols, min_locations=min_locations)


def fit_curves(bins: pd.DataFrame, sections: pd.DataFrame, upto: list[int]) -> dict:
    """The reference curves of the runs ``upto`` (what the publish step of the last of them has)."""
    df = bins[bins.run_id.isin(upto)]
    pos = (df["bin"].to_numpy(dtype=float) + 0.5) * 0.25
    wheel = df["wheel"].astype(str).to_numpy(dtype=object)
    ref = fit_reference_from_rows(df["sleeper_amp"].to_numpy(), df["speed_mean"].to_numpy(), pos,
                                  df["run_id"].to_numpy(), wheel, np.array([w[-1:] for w in wheel], dtype=object),
                                  classes_of(sections, pos), bin_length_m=0.25, speed_tolerance=0.1, n_boot=0)
    return dict(ref.curves)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--workdir", type=Path, default=Path("/tmp/places-bench"))
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--runs", type=int, default=12)
    ap.add_argument("--json", type=Path, help="write the per-run results here")
    args = ap.parse_args(argv)
    args.workdir.mkdir(parents=True, exist_ok=True)
    results: list[dict] = []
    healthy: list[pd.DataFrame] = []
    centre_err: list[dict] = []
    for seed in args.seeds:
        for which in ("uniform", "planted"):
            spec, url = build(which, seed, args.runs, args.workdir)
            evaluate(which, seed, spec, url, results, healthy, centre_err)
    df = pd.DataFrame(results)
    pd.set_option("display.width", 250)
    later = df[df.run >= 5]  # from the 6th run on: a history of 5 runs to compare with
    cols = {c: (c, "mean") for c in ("places", "false", "false_on_ramps", "top10_real", "found_anomaly",
                                     "found_change", "found_developing", "tested_step") if c in df.columns}
    print(f"\nPer run from the 6th on (mean over {later.groupby(['history', 'seed', 'run']).ngroups} runs of "
          f"{len(args.seeds)} seed(s)):")
    print(later.groupby(["history", "design"]).agg(**cols).round(2).to_string())
    h = pd.concat(healthy, ignore_index=True)
    h = h[h.cls != "-"]

    def q(s: pd.Series) -> pd.Series:
        a = np.abs(s.dropna().to_numpy())
        return pd.Series(np.r_[np.quantile(a, [0.5, 0.99, 0.999]), a.max()] if a.size else [np.nan] * 4,
                         index=["p50", "p99", "p99.9", "max"])

    print("\nHealthy 10 m segments (30 m from anything planted), |index| per class and ramp/cruise, ln units"
          f" (curves of the store's rows, ≥ {MIN_LOCATIONS[-1]} locations):")
    print(h.groupby(["cls", "ramp"])["index"].apply(q).unstack().round(3).to_string())
    h["sec"] = h["seg"] // 20
    sec = h.groupby(["history", "seed", "run", "sec"]).agg(level=("index", "mean"), spread=("index", "std"),
                                                           n=("index", "count"))
    sec = sec[sec.n >= 10]
    rms = np.sqrt(sec.level**2 + sec.spread**2)
    print("Healthy 200 m sections, rms of the index:",
          {k: round(float(v), 3) for k, v in zip(["p20", "p50", "p80", "p95", "p99", "max"],
                                                 np.r_[np.quantile(rms, [0.2, 0.5, 0.8, 0.95, 0.99]), rms.max()],
                                                 strict=True)})
    if centre_err:
        ce = pd.DataFrame(centre_err)
        print("\nNew 20 m changes after their day: |place centre − change centre|, m; places over one change:")
        print(ce.groupby("design").agg(err_mean=("err_m", "mean"), err_max=("err_m", "max"),
                                       places_max=("n_places", "max"), n=("err_m", "count")).round(2).to_string())
    if tier_log:
        tl = pd.DataFrame(tier_log)
        print(f"\nThe stated 1-σ ({STATED}), per history, runs from the 6th on (sums of places, medians of sd):")
        tl = tl[tl.run >= 5]
        print(tl.groupby(["history", "seed"]).agg(**{
            "median index_sd": ("median index_sd", "median"), "places": ("places", "sum"),
            "tier>=2": ("tier >= 2", "sum"), "tier>=2 without sd": ("tier >= 2 without sd", "sum"),
            "median severity_sd": ("median severity_sd", "median")}).round(3).to_string())
    print("\nAlerts (events of the lifecycle) over the whole history:")
    print(pd.Series({f"{h} seed {sd}: {n}": v or "none" for (h, sd, n), v in alerts_by.items()}).to_string())
    if alert_log:
        print(f"\nEvery alert of the default design ({CHOSEN} | listed), with whether its place is real:")
        print(pd.DataFrame(alert_log).to_string(index=False))
    print("\n200 m section classes of the newest run (A best … E):")
    print(pd.DataFrame(sections_out).to_string(index=False))
    if repaired:
        print("\nPlaces repaired by a maintenance action (the lifecycle's 'repaired' events):")
        print(pd.DataFrame(repaired).to_string(index=False))
    if trends:
        print("\nThe developing place (truth +1.2 ln units / year) on the run before the tamping: its trend:")
        print(pd.DataFrame(trends).round(2).to_string(index=False))
    if effects:
        print("\nTamping effect, % of the amplitude (truth: the action's own factor on the typical track of its extent):")
        print(pd.DataFrame(effects).round(1).to_string(index=False))
    if args.json:
        args.json.write_text(json.dumps({"results": results, "centre_err": centre_err}, indent=1, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
