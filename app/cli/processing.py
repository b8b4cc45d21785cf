"""Commands without a server: ``simulate`` (synthetic runs) and ``process`` (a run file → profiles)."""

from __future__ import annotations

import dataclasses
import hashlib
import inspect
import json
import sys
import time
import typing
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any

import typer

from app.cli._common import echo
from app.cli._warnings import engine_warnings

__all__ = ["simulate", "process", "with_settings_options"]


def simulate(
    out: Annotated[Path, typer.Argument(help="Output run file (.h5); truth is written beside it")],
    length_km: Annotated[float, typer.Option(help="Length of the simulated line, km")] = 5.0,
    fs: Annotated[float, typer.Option(help="Sample rate, Hz")] = 10_000.0,
    seed: Annotated[int, typer.Option(help="Random seed")] = 0,
    forces: Annotated[bool, typer.Option(help="Also simulate Q (force) channels")] = True,
    reference: Annotated[bool, typer.Option(
        help="Also write matching subsidence, maintenance and superstructure CSV files "
        "(OUT stem + '-reference/')")] = False,
    amplitude_model: Annotated[str, typer.Option(
        help="Speed response of the sleeper-passage amplitude: 'resonance' (a wheel on a discretely "
        "supported rail) or 'power_law' ((v / 100 km/h) ** 1.5)")] = "resonance",
    recorder: Annotated[str | None, typer.Option(
        help="Write OUT as a recorder file (mdf4 or tdms) with drifting odometry, plus its channel "
        "map and metadata JSON beside it")] = None,
    gnss: Annotated[bool, typer.Option(
        help="With --recorder: a GNSS group (3 m noise, 30 s outages) and the line geometry "
        "(OUT stem + '.line.geojson')")] = False,
    confounders: Annotated[bool, typer.Option(
        help="Rough rails (Sato, good rail) with a dipped weld every 100–200 m, and a 40 mm wheel flat "
        "on wheel 11 (docs/run-format.md)")] = False,
    line_id: Annotated[str, typer.Option(help="Line id of the run (and of the --reference files)")] = "SIM",
    track: Annotated[str, typer.Option(help="Track of the run (and of the --reference files)")] = "1",
    vehicle_id: Annotated[str, typer.Option(help="Vehicle id of the run")] = "SIM-1",
    start_time: Annotated[str, typer.Option(
        help="Start of the run: ISO date and time with its UTC offset, or an ISO date (08:00 UTC)")]
        = "2024-05-01T08:00:00+02:00",
) -> None:
    """Write a synthetic run in the canonical format with its ground truth beside it."""
    from app.simulate.run import simulate_run

    if amplitude_model not in ("resonance", "power_law"):
        typer.echo(f"error: --amplitude-model must be resonance or power_law, got {amplitude_model!r}", err=True)
        raise typer.Exit(2)
    meta = _run_metadata(line_id=line_id, track=track, vehicle_id=vehicle_id, start_time=start_time)
    out.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    options: dict[str, Any] = dict(meta)  # the run's metadata and its surfaces
    if confounders:
        from app.simulate.wheels import WheelFlat

        options.update(rail_surface=True, wheel_flats={"11": WheelFlat()})
    if recorder is not None:
        from app.simulate.recorder import GnssSimulation, simulate_recorder_run

        if recorder not in ("mdf4", "tdms"):
            raise typer.BadParameter("mdf4 or tdms", param_hint="--recorder")
        rec = simulate_recorder_run(out, recorder, gnss=GnssSimulation() if gnss else None, seed=seed,
                                    length_km=length_km, fs=fs, with_forces=forces,
                                    amplitude_model=amplitude_model, **options)
        echo(f"wrote {out} in {time.perf_counter() - t0:.1f} s; channel map {rec.channel_map_path}, "
             f"metadata {rec.metadata_path}" + (f", geometry {rec.geometry_path}" if gnss else ""))
        return
    truth = simulate_run(out, length_km=length_km, fs=fs, seed=seed, with_forces=forces,
                         amplitude_model=amplitude_model, **options)
    echo(f"wrote {out} ({out.stat().st_size / 1e6:.1f} MB) in {time.perf_counter() - t0:.1f} s")
    truth_path = getattr(truth, "path", None)
    if truth_path:
        echo(f"ground truth: {truth_path}")
    if reference:
        from app.simulate.reference import simulate_reference

        ref = simulate_reference(truth.line, out.with_name(f"{out.stem}-reference"), line_id=meta["line_id"],
                                 track=meta["track"], seed=seed)
        echo("reference data: " + ", ".join(ref.files[k] for k in ("subsidence", "maintenance", "superstructure")))


def _run_metadata(**given: str) -> dict[str, Any]:
    """The metadata options of ``simulate`` checked as an upload's metadata are (the ingest's rules:
    non-empty ids within their lengths, an aware start time in the accepted range); a bad one
    exits naming its option. ``start_time`` may be a date: 08:00 UTC that day."""
    import datetime as dt

    from pydantic import ValidationError

    from app.io.metadata import RunMetadata

    value: Any = given["start_time"]
    try:
        value = (dt.datetime.combine(dt.date.fromisoformat(value), dt.time(8, 0), tzinfo=dt.UTC)
                 if len(value.strip()) == 10 else dt.datetime.fromisoformat(value.strip()))
    except ValueError:
        raise typer.BadParameter(f"not an ISO date or date and time: {value!r}", param_hint="--start-time") from None
    if value.tzinfo is None:
        raise typer.BadParameter(f"needs its UTC offset (e.g. {value.isoformat()}+01:00)", param_hint="--start-time")
    try:
        checked = RunMetadata(**{**given, "start_time": value}, direction="up")
    except ValidationError as exc:
        err = exc.errors()[0]
        raise typer.BadParameter(str(err["msg"]), param_hint="--" + str(err["loc"][0]).replace("_", "-")) from None
    return {k: getattr(checked, k) for k in given}


def _file_sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(1 << 20):
            digest.update(block)
    return digest.hexdigest()


def _wheel_tables(wheels: list[dict[str, Any]]):
    import pandas as pd

    order_rows, profile_rows = [], []
    for w in wheels:
        for o in w.get("orders", []):
            order_rows.append(
                {"wheel": str(w["wheel"]), "wheel_diameter_m": w.get("wheel_diameter_m"), **o}
            )
        angles = w.get("angles_deg") or []
        for i, angle in enumerate(angles):
            profile_rows.append(
                {
                    "wheel": str(w["wheel"]),
                    "angle_deg": angle,
                    "profile_um": (w.get("profile_um") or [None] * len(angles))[i],
                    "profile_p05_um": (w.get("profile_p05_um") or [None] * len(angles))[i],
                    "profile_p95_um": (w.get("profile_p95_um") or [None] * len(angles))[i],
                }
            )
    return pd.DataFrame(order_rows), pd.DataFrame(profile_rows)


def _jsonable(value: Any) -> Any:
    from app.core.jsonable import jsonable

    return jsonable(value)


def with_settings_options(command: Callable[..., None]) -> Callable[..., None]:
    """``command`` with one option per processing setting (``--n-wheel-orders`` …), derived from
    :class:`~app.analysis.settings.ProcessingSettings` (its help, valid values and default); the
    options given reach ``command`` as keyword arguments (None: not given)."""
    from app.analysis.settings import ProcessingSettings, setting_help

    hints = typing.get_type_hints(ProcessingSettings)
    signature = inspect.signature(command, eval_str=True)
    params = [p for p in signature.parameters.values() if p.kind is not inspect.Parameter.VAR_KEYWORD]
    annotations = {p.name: p.annotation for p in params}
    for f in dataclasses.fields(ProcessingSettings):
        kind = Annotated[hints[f.name] | None, typer.Option(help=setting_help(f.name))]
        params.append(inspect.Parameter(f.name, inspect.Parameter.KEYWORD_ONLY, default=None, annotation=kind))
        annotations[f.name] = kind

    command.__signature__ = signature.replace(parameters=params)  # type: ignore[attr-defined]
    command.__annotations__ = {**annotations, "return": None}
    return command


def _settings(options: dict[str, Any]):
    """The processing settings of the options given (the defaults for the others)."""
    from app.analysis.settings import ProcessingSettings

    try:
        return ProcessingSettings.from_dict({k: v for k, v in options.items() if v is not None})
    except ValueError as exc:
        raise typer.BadParameter(str(exc)) from None


def _read_json(path: Path, option: str) -> Any:
    """The JSON document of a file option; BadParameter naming the option when unreadable."""
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise typer.BadParameter(f"cannot read {path}: {exc}", param_hint=option) from None


def _canonical_file(run_file: Path, format: str | None, md: Any, extras: dict[str, Any], path: Path) -> None:  # noqa: A002
    """Validate the run file and write it as the canonical HDF5 file ``path`` (exit 2 on a bad file)."""
    from app.io import RunFileError, ingest
    from app.io.geometry import parse_geojson

    echo(f"validating {run_file} ...")
    try:
        lines = parse_geojson(extras["geometry"]) if "geometry" in extras else []
        summary = ingest(run_file, format, md, path, channel_map=extras.get("channel_map"),
                         geometry=lambda line, track: next(
                             (g for g in lines if (g.line_id, g.track) == (line, track)), None))
    except RunFileError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None
    for warning in summary.warnings:
        typer.echo(f"warning: {warning}", err=True)
    echo(
        f"{summary.duration_s:.1f} s at {summary.fs:g} Hz, {summary.distance_m / 1000:.2f} km, "
        f"channels {', '.join(summary.channels)}"
    )


def _run_with_progress(canonical: Path, settings, chunks_dir: Path):
    """The pipeline over ``chunks_dir`` with a progress bar; the results and the engine's warnings."""
    from tqdm import tqdm

    from app.pipeline import run_pipeline

    with tqdm(total=100, unit="%", desc="processing", bar_format="{l_bar}{bar}| {elapsed}") as bar, \
            engine_warnings(lambda line: tqdm.write(line, file=sys.stderr)) as seen:

        def progress(fraction: float) -> None:
            bar.update(max(0.0, 100 * fraction - bar.n))

        results = run_pipeline(canonical, settings, chunks_dir, progress=progress)
        progress(1.0)
    return results, seen.as_list()


def _write_outputs(out: Path, results, meta: dict[str, Any]) -> None:
    """profiles, wheel orders and wheel profiles as CSV and Parquet, wheels.json and meta.json."""
    out.mkdir(parents=True, exist_ok=True)
    results.profiles.to_csv(out / "profiles.csv", index=False)
    results.profiles.to_parquet(out / "profiles.parquet", index=False)
    orders, wheel_profiles = _wheel_tables(results.wheels)
    orders.to_csv(out / "wheel_orders.csv", index=False)
    orders.to_parquet(out / "wheel_orders.parquet", index=False)
    wheel_profiles.to_csv(out / "wheel_profiles.csv", index=False)
    wheel_profiles.to_parquet(out / "wheel_profiles.parquet", index=False)
    (out / "wheels.json").write_text(json.dumps(_jsonable(results.wheels), indent=1))
    (out / "meta.json").write_text(json.dumps(_jsonable(meta), indent=1))


@with_settings_options
def process(
    run_file: Annotated[Path, typer.Argument(help="Run file: HDF5, CSV, Parquet, MDF4 or TDMS")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Output directory")] = Path("trackvkf-out"),
    format: Annotated[
        str | None, typer.Option("--format", help="hdf5, csv, parquet, mdf4 or tdms (default: detect)")
    ] = None,
    metadata: Annotated[
        Path | None, typer.Option(help="Metadata JSON file (required for CSV/Parquet)")
    ] = None,
    channel_map: Annotated[
        Path | None, typer.Option(help="Channel map JSON file (MDF4/TDMS recorder files)")
    ] = None,
    geometry: Annotated[
        Path | None, typer.Option(help="Line geometry GeoJSON (runs placed by GNSS)")
    ] = None,
    **settings_options: Any,
) -> None:
    """Process a run file locally (no server): profiles and wheel OOR to CSV and Parquet.

    ``profiles.csv``/``.parquet`` hold per 25 cm bin and wheel the sleeper-passage fundamental
    (``sleeper_amp``: rail roughness out; ``sleeper_amp_raw`` the wheel's own, ``sleeper_amp_sd`` the
    1-σ of ``sleeper_amp``, ``sleeper_amp_sd_shared`` the part of it shared along ≈ 20 m), its
    harmonics (``sleeper_2_amp``, ``sleeper_3_amp``) and energy indicator
    (``sleeper_rms``), the wheel orders, the force amplitude and the depth of a track impact
    (``track_impact_mm``: a dipped weld or joint, bridged out of the sleeper columns) and the step
    estimate of ``sleeper_amp`` (``sleeper_step``: its levels between change points);
    ``wheels.json`` the wheel OOR and any wheel flat (``flat``); ``meta.json`` the settings and
    the warnings (docs/indicator.md). The processing settings are options (``--n-wheel-orders``
    …, each with its valid values and default).

    Intermediate chunk results are kept in ``OUT/.work`` so an interrupted run
    resumes where it stopped.
    """
    if not run_file.is_file():
        raise typer.BadParameter(f"{run_file} is not a file", param_hint="RUN_FILE")
    settings = _settings(settings_options)
    md = _read_json(metadata, "--metadata") if metadata is not None else None
    extras = {name: _read_json(path, f"--{name.replace('_', '-')}")
              for name, path in (("channel_map", channel_map), ("geometry", geometry)) if path is not None}
    source_sha = _file_sha256(run_file)
    key = hashlib.sha256(
        json.dumps({"sha": source_sha, "md": md, "settings": settings.to_dict(), **extras},
                   sort_keys=True).encode()
    ).hexdigest()[:16]
    work = out / ".work" / key
    work.mkdir(parents=True, exist_ok=True)
    canonical = work / "run.h5"
    if not canonical.is_file():
        _canonical_file(run_file, format, md, extras, canonical)
    results, warnings = _run_with_progress(canonical, settings, work / "chunks")
    meta = {
        **dict(results.meta or {}),
        "source_file": str(run_file),
        "source_sha256": source_sha,
        "settings": settings.to_dict(),
        "warnings": warnings,
    }
    _write_outputs(out, results, meta)
    for text in meta.get("warnings") or ():
        typer.echo(f"warning: {text}", err=True)
    echo(
        f"{len(results.profiles)} profile rows, {len(results.wheels)} wheels -> {out}/ "
        "(profiles.csv/.parquet, wheel_orders.csv/.parquet, wheel_profiles.csv/.parquet, "
        "wheels.json, meta.json)"
    )
