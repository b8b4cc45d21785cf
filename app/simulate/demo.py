"""The demo's data set: several runs of two lines at different dates plus reference data.

``trackvkf demo`` uploads it so that every dashboard page has content out of the box: three
runs of line ``SIM`` track 1 by vehicle ``SIM-1`` half a year apart (the same line model and
the same wheels, so the line view, the run alignment and the wheel trend compare like with
like; the later runs carry a few metres of odometry error), one run of line ``SIM-B`` track 2
by vehicle ``SIM-2``, subsidence, maintenance and superstructure records of line ``SIM``
track 1 (CSV, as an asset manager would export them) and the geometry of both lines (GeoJSON
with km stations, for the map).

The runs carry the confounders of real data (``confounders=True``, the default): the rails of each
line have their random roughness (Sato, good rail) and a dipped weld every 100–200 m, the grinding
actions of the maintenance records apply to line SIM's rails from their dates on, and wheel 41 of
SIM-1 has a 40 mm wheel flat from the second run on.

With ``history=True`` (what ``trackvkf demo`` uses) the three runs of line ``SIM`` are replaced by
a short **history** of the same line (:func:`app.simulate.history.demo_history`: 10 runs two weeks
apart with speed ramps and cruise speeds ±10 %, a place developing softer, one developing harder
that a tamping repairs two thirds through — its maintenance record lies inside the runs' span —
and a new −20 % change half way), so the Condition page's places, trends, status workflow and
before/after view have content; the line's **assets** (switches, a bridge, a level crossing, joints,
a weld at the new change: :func:`demo_assets`) are written too.

Files are written once into a directory and reused (same bytes, same sha256: the demo's second
start uploads nothing new).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

from app.simulate.geometry import synthetic_line, write_geometry
from app.simulate.history import HistorySpec, demo_history, write_history
from app.simulate.reference import simulate_reference
from app.simulate.run import DEFAULT_TRUE_DIAMETERS_M, Confounders, simulate_run
from app.simulate.surface import RailGrinding
from app.simulate.track import LineModel, generate_line
from app.simulate.wheels import WheelFlat, random_wheel_oor

__all__ = ["DemoRun", "DemoDataset", "DEMO_RUNS", "DEMO_KM_START", "DEMO_HISTORY_RUNS", "REFERENCE_KINDS",
           "demo_assets", "write_demo_dataset"]

#: km of the position reference at the start of every demo run
DEMO_KM_START = 12.0
#: runs of the demo's history of line SIM (two weeks apart)
DEMO_HISTORY_RUNS = 10
#: reference data kinds, in the order they are imported
REFERENCE_KINDS = ("superstructure", "maintenance", "subsidence")


@dataclass(frozen=True)
class DemoRun:
    """One simulated run of the demo (metadata and seeds)."""

    line_id: str
    track: str
    vehicle_id: str
    start_time: str
    seed: int
    line_seed: int
    vehicle_seed: int
    km_error_m: float = 0.0
    wheel_flats: tuple[str, ...] = ()

    def file_name(self, length_km: float, fs: float, amplitude_model: str = "resonance",
                  confounders: bool = False) -> str:
        """Name of the run file (changes with the demo options)."""
        day = self.start_time[:10]
        rough = "-rough" if confounders else ""
        return f"{self.line_id}-{self.track}-{day}-{length_km:g}km-{fs:g}Hz-{amplitude_model}{rough}.h5"


#: the demo's runs: line SIM track 1 three times (the reference data's line), SIM-B once
DEMO_RUNS: tuple[DemoRun, ...] = (
    DemoRun("SIM", "1", "SIM-1", "2024-05-01T08:00:00+02:00", seed=7, line_seed=7, vehicle_seed=1),
    DemoRun("SIM", "1", "SIM-1", "2024-11-05T09:30:00+01:00", seed=8, line_seed=7, vehicle_seed=1,
            km_error_m=4.0, wheel_flats=("41",)),
    DemoRun("SIM", "1", "SIM-1", "2025-05-06T08:15:00+02:00", seed=9, line_seed=7, vehicle_seed=1,
            km_error_m=-3.0, wheel_flats=("41",)),
    DemoRun("SIM-B", "2", "SIM-2", "2025-02-03T14:00:00+01:00", seed=21, line_seed=21, vehicle_seed=2),
)


@dataclass
class DemoDataset:
    """Paths of the demo's files: ``runs`` in the order of :data:`DEMO_RUNS`, ``reference``
    by kind (:data:`REFERENCE_KINDS`), ``geometry`` one GeoJSON per line and track, all under
    ``directory``."""

    directory: Path
    runs: list[Path] = field(default_factory=list)
    reference: dict[str, Path] = field(default_factory=dict)
    geometry: list[Path] = field(default_factory=list)
    reference_line: tuple[str, str] = ("SIM", "1")
    written: list[Path] = field(default_factory=list)
    history: HistorySpec | None = None
    assets: Path | None = None


def _line(line_seed: int, length_km: float, rough: bool = False) -> LineModel:
    """The line model of ``line_seed`` covering every demo run of ``length_km`` (with margins
    for the trailing axle and the odometry errors); ``rough``: with its rail surface."""
    start = 1000.0 * DEMO_KM_START
    end = start + 1000.0 * length_km
    return generate_line(start - 100.0, end + 100.0, np.random.default_rng([line_seed, 7]),
                         anomaly_range_m=(start + 20.0, end - 40.0), surface=rough)


def _ground(line: LineModel, maintenance_csv: Path) -> LineModel:
    """The line with the grinding actions of its maintenance records applied to its rail surface."""
    if line.surface is None:
        return line
    rows = pd.read_csv(maintenance_csv)
    rows = rows[rows["type"] == "grinding"]
    grindings = [RailGrinding(1000.0 * float(r.km_from), 1000.0 * float(r.km_to), str(r.date))
                 for r in rows.itertuples()]
    return replace(line, surface=line.surface.with_grindings(grindings))


def demo_assets(spec: HistorySpec) -> pd.DataFrame:
    """Known discontinuities of the history's line (the asset import's columns), at fixed fractions of
    the run so any demo length works: switches near both ends, a bridge, a level crossing, an
    insulated joint, and a weld at the new change (a place labelled with its asset)."""
    x0, L = spec.km_start, spec.length_km
    change = next((c for c in spec.changes if c.kind == "change"), None)
    rows = [
        ("switch", x0 + 0.03 * L, None, "W 1"),
        ("insulated_joint", x0 + 0.031 * L + 0.03, None, "IJ 1"),
        ("level_crossing", x0 + 0.22 * L, None, "LC Feldweg"),
        ("bridge", x0 + 0.47 * L, x0 + 0.47 * L + 0.045, "Mühlbach bridge"),
        ("switch", x0 + 0.97 * L, None, "W 2"),
    ]
    if change is not None:
        rows.append(("weld", round(0.5 * (change.track_from_m + change.track_to_m)) / 1000.0, None, "thermite weld"))
    return pd.DataFrame([{"line_id": spec.line_id, "track": spec.track, "type": t, "km": round(k, 4),
                          "km_to": None if k2 is None else round(k2, 4), "name": n} for t, k, k2, n in rows],
                        columns=["line_id", "track", "type", "km", "km_to", "name"])


def write_demo_dataset(directory: Path | str, *, length_km: float = 3.0, fs: float = 10_000.0,
                       runs: tuple[DemoRun, ...] = DEMO_RUNS, amplitude_model: str = "resonance",
                       confounders: bool = True, history: bool = False) -> DemoDataset:
    """Write the demo's run files and reference files into ``directory`` (missing ones only).

    Parameters
    ----------
    directory : Path or str
        Where the files go (created).
    length_km : float
        Length of every run, km (> 0).
    fs : float
        Sample rate of the runs, Hz.
    runs : tuple of DemoRun
        The runs (default :data:`DEMO_RUNS`); the reference data belong to the first run's
        line and track.
    amplitude_model : {"resonance", "power_law"}
        Speed response of the sleeper-passage amplitude (:func:`app.simulate.run.simulate_run`;
        default the resonance model: not a power law in speed).
    confounders : bool
        Rail roughness, welds, grinding and the wheel flat of the module docstring (default);
        False: smooth rails and round wheels.
    history : bool
        Replace the runs of the first run's line by its history (:data:`DEMO_HISTORY_RUNS` runs,
        :func:`app.simulate.history.demo_history`; ``length_km`` ≥ 2) whose maintenance record
        replaces the reference data's, and write the line's assets (:func:`demo_assets`). The
        history's runs come first in ``runs``, in date order (the order they must be processed in).

    Returns
    -------
    DemoDataset
        The paths; ``written`` lists the files made by this call.
    """
    if not length_km > 0:
        raise ValueError(f"length_km: must be > 0, got {length_km!r}")
    if not runs:
        raise ValueError("runs: at least one run is needed")
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    first, all_runs = runs[0], runs
    data = DemoDataset(directory=out, reference_line=(first.line_id, first.track))
    lines: dict[int, LineModel] = {}
    # the reference data first: the maintenance records' grinding actions shape line SIM's rails
    ref_dir = out / f"reference-{first.line_id}-{first.track}-{length_km:g}km"
    files = {kind: ref_dir / f"{kind}.csv" for kind in REFERENCE_KINDS}
    if not all(p.is_file() for p in files.values()):
        line = lines.setdefault(first.line_seed, _line(first.line_seed, length_km, confounders))
        ref = simulate_reference(line, ref_dir, line_id=first.line_id, track=first.track,
                                 seed=first.seed)
        files = {kind: Path(ref.files[kind]) for kind in REFERENCE_KINDS}
        data.written.extend(files.values())
    data.reference = files
    spec, hfiles = None, None
    if history:
        if amplitude_model != "resonance":
            raise ValueError("amplitude_model: the demo history is simulated with the resonance model")
        # the history's own line model (smooth rails: the places' numerics are measured on it)
        spec = demo_history(_line(first.line_seed, length_km), km_start=DEMO_KM_START, length_km=length_km,
                            n_runs=DEMO_HISTORY_RUNS, line_id=first.line_id, track=first.track,
                            vehicle_id=first.vehicle_id, fs=fs, seed=first.seed)
        hfiles = write_history(spec, out / "history")
        data.history = spec
        data.runs.extend(hfiles.runs)
        data.written.extend(hfiles.written)
        runs = tuple(r for r in runs if (r.line_id, r.track) != (first.line_id, first.track))
        # the history's tamping (inside the runs' span) is the line's maintenance record, its sections the line's
        data.reference = {**files, "maintenance": hfiles.maintenance, "superstructure": hfiles.superstructure}
        data.assets = out / f"assets-{spec.line_id}-{spec.track}-{spec.fingerprint()}.csv"
        if not data.assets.is_file():
            demo_assets(spec).to_csv(data.assets, index=False)
            data.written.append(data.assets)
    for run in runs:
        path = out / run.file_name(length_km, fs, amplitude_model, confounders)
        data.runs.append(path)
        if path.is_file():
            continue
        if run.line_seed not in lines:
            lines[run.line_seed] = _line(run.line_seed, length_km, confounders)
        line = lines[run.line_seed]
        if run.line_seed == first.line_seed:
            line = _ground(line, files["maintenance"])
        rng = np.random.default_rng([run.vehicle_seed, 3])
        wheels = {w: random_wheel_oor(rng, w, d) for w, d in DEFAULT_TRUE_DIAMETERS_M.items()}
        flats = {w: WheelFlat(0.04, 0.2e-3, angle_rad=1.0) for w in run.wheel_flats} if confounders else None
        simulate_run(path, length_km=length_km, fs=fs, seed=run.seed, line=line, wheels=wheels,
                     start_time=run.start_time, vehicle_id=run.vehicle_id, line_id=run.line_id,
                     track=run.track, km_start=DEMO_KM_START, km_error_m=run.km_error_m,
                     with_forces=True, amplitude_model=amplitude_model, wheel_flats=flats,
                     confounders=Confounders() if confounders else Confounders(False, False, False))
        data.written.append(path)
    for line_id, track, seed in dict.fromkeys((r.line_id, r.track, r.line_seed) for r in all_runs):
        path = out / f"geometry-{line_id}-{track}-{length_km:g}km.geojson"
        data.geometry.append(path)
        if not path.is_file():
            # a margin for the odometry errors and the trailing axle
            _, doc = synthetic_line(DEMO_KM_START - 0.1, DEMO_KM_START + length_km + 0.1, seed=seed,
                                    line_id=line_id, track=track)
            write_geometry(path, doc)
            data.written.append(path)
    return data
