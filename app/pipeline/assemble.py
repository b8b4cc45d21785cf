"""Step 3 of the pipeline: merge the chunk files into profile rows and wheel results.

Assembly adds the chunk sums and turns them into the 25 cm profile rows and
the wheel out-of-roundness results. It is deterministic and idempotent; it
reads no raw signal, only chunk files (:mod:`app.pipeline.chunkfile`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from app.analysis.binning import BinSums
from app.analysis.denoise import edge_preserving
from app.analysis.roughness import single_wheel_estimate, two_rail_estimate
from app.analysis.settings import ProcessingSettings
from app.analysis.steps import DEFAULT_STEP_PENALTY, step_levels
from app.analysis.uncertainty import STEP_WIDTH_FACTORS
from app.analysis.wheel_oor import apply_diameter_correction, refine_diameter, summarize_oor
from app.core.profile_schema import ENGINE_VERSION, ROUGHNESS_COLUMNS, STEP_COLUMN, TRACK_COLUMNS
from app.io import WHEELS
from app.io.metadata import DEFAULT_WHEEL_DIAMETER_M
from app.pipeline.chunk import OOR_WINDOW_M
from app.pipeline.chunkfile import read_wheel
from app.pipeline.impacts import (
    IMPACT_COLUMN,
    flat_result,
    impact_extents,
    impacts_meta,
    mask_track_impacts,
    run_impacts,
)

__all__ = ["ENGINE_VERSION", "ROUGHNESS_COLUMNS", "STEP_COLUMN", "TRACK_COLUMNS", "RunResults", "WheelAssembly",
           "assemble", "assemble_wheel", "finish_assembly", "results_meta", "run_warnings", "sleeper_estimate",
           "sleeper_step", "wheel_assembly"]



@dataclass
class RunResults:
    """Profiles, wheel results and provenance of one processed run."""

    profiles: pd.DataFrame
    wheels: list[dict[str, Any]]
    meta: dict[str, Any] = field(default_factory=dict)


@dataclass
class WheelAssembly:
    """One wheel assembled alone (:func:`wheel_assembly`), before the run's track impacts are bridged."""

    #: its profile rows in bin order (``sleeper_step`` the step estimate of its own ``sleeper_amp``)
    profiles: pd.DataFrame
    #: its entry of ``RunResults.wheels`` (no ``flat`` yet)
    result: dict[str, Any]
    #: the track orders' resolution it was solved with, m (what its step estimate takes)
    resolution_m: float


def _wheel_order_numbers(settings: ProcessingSettings) -> np.ndarray:
    return np.arange(1, settings.n_wheel_orders + 1)


def _profile_columns(settings: ProcessingSettings) -> list[str]:
    orders = [f"order_amp_{lvl:02d}" for lvl in _wheel_order_numbers(settings)]
    return ["wheel", "bin", "km", "n_samples", "speed_mean", *TRACK_COLUMNS, *orders,
            "residual_rms", "sleeper_force_amp", *ROUGHNESS_COLUMNS, IMPACT_COLUMN, STEP_COLUMN]


def _track_resolution(settings: ProcessingSettings, wheel_diameter: float) -> float:
    """The track orders' 10–90 % step width, m (``track_resolution_m``, or that of the wheel orders' band)."""
    if settings.track_resolution_m is not None:
        return float(settings.track_resolution_m)
    per_speed = float(settings.bandwidth_orders) / (np.pi * float(wheel_diameter))
    return STEP_WIDTH_FACTORS[int(settings.filter_order)] / per_speed


def _wheel_resolution(rough: pd.DataFrame | None, settings: ProcessingSettings, wheel_diameter: float) -> float:
    """The track orders' resolution a wheel was solved with, m: the recipe's (``res_m`` of its ``rough``
    sums), else the settings' (:func:`_track_resolution`)."""
    if rough is not None and "res_m" in rough and rough["res_m"].notna().any():
        return float(np.nanmedian(rough["res_m"]))
    return _track_resolution(settings, wheel_diameter)


def sleeper_step(profile: pd.DataFrame, resolution_m: float, bin_length_m: float,
                 penalty: float = DEFAULT_STEP_PENALTY) -> np.ndarray:
    """``sleeper_step`` of one wheel: the step estimate of its stored ``sleeper_amp``.

    Parameters
    ----------
    profile : pandas.DataFrame
        The wheel's profile rows in bin order: ``bin``, ``sleeper_amp`` and ``sleeper_amp_sd`` (m/s²).
    resolution_m : float
        The track orders' resolution the wheel was solved with, m (10–90 % step width; 3 m by default).
    bin_length_m : float
        m.
    penalty : float
        Cost of one change point (:data:`app.analysis.steps.DEFAULT_STEP_PENALTY`).

    Returns
    -------
    numpy.ndarray
        One value per row, m/s²: the levels between change points of ``sleeper_amp``
        (:func:`app.analysis.steps.step_levels` with ``resolution_m / bin_length_m`` bins, at least 1);
        NaN where ``sleeper_amp`` or its 1-σ is NaN. Bins missing from the rows (no samples) break the
        profile into stretches segmented apart, as a NaN does.
    """
    bins = profile["bin"].to_numpy(dtype=np.int64)
    amp = profile["sleeper_amp"].to_numpy(dtype=np.float64, na_value=np.nan)
    sd = profile["sleeper_amp_sd"].to_numpy(dtype=np.float64, na_value=np.nan)
    if bins.size == 0:
        return np.zeros(0)
    if np.any(np.diff(bins) <= 0):
        raise ValueError("profile: bins must be increasing")
    gaps = np.flatnonzero(np.diff(bins) > 1) + 1  # a NaN between stretches that do not touch
    res_bins = max(1.0, float(resolution_m) / float(bin_length_m))
    out = step_levels(np.insert(amp, gaps, np.nan), np.insert(sd, gaps, np.nan), res_bins, penalty)
    return np.delete(out, gaps + np.arange(gaps.size))


def _with_steps(profiles: pd.DataFrame, resolutions: dict[str, float], bin_length_m: float) -> pd.DataFrame:
    """``profiles`` with :data:`STEP_COLUMN` written for every wheel in ``resolutions`` (each in bin order)."""
    out = profiles.copy()
    out[STEP_COLUMN] = np.nan
    col = out.columns.get_loc(STEP_COLUMN)
    bins = out["bin"].to_numpy(dtype=np.int64)
    for wheel, rows in out.groupby(out["wheel"].astype(str), sort=False).indices.items():
        if wheel in resolutions:
            rows = rows[np.argsort(bins[rows], kind="stable")]
            out.iloc[rows, col] = sleeper_step(out.iloc[rows], resolutions[wheel], bin_length_m)
    return out


def sleeper_estimate(rough: pd.DataFrame, settings: ProcessingSettings, wheel_diameter: float) -> pd.DataFrame:
    """``sleeper_amp`` (the best estimate) and ``sleeper_amp_sd`` of one wheel from its ``rough`` sums.

    Parameters
    ----------
    rough : pandas.DataFrame
        The finalised ``rough`` group (:mod:`app.pipeline.roughness_sums`): ``bin``,
        ``pow``, ``re``, ``im``, ``floor_lo``, ``floor_hi``, ``res_m`` (the recipe's resolution) and,
        for an axle with both wheels measured, ``cross_re`` and ``pow_other``.
    settings : ProcessingSettings
    wheel_diameter : float
        m (the track orders' resolution from the settings, for sums without ``res_m``).

    Returns
    -------
    pandas.DataFrame
        ``bin``, ``sleeper_amp``, ``sleeper_amp_sd``, ``sleeper_amp_sd_shared``: the two-rail estimate where
        the axle's other wheel was measured
        (:func:`app.analysis.roughness.two_rail_estimate`), else the single wheel's
        floor-corrected one (:func:`app.analysis.roughness.single_wheel_estimate`); then, with
        ``settings.edge_preserving_sd``, smoothed by its stated 1-σ with its steps kept
        (:func:`app.analysis.denoise.edge_preserving`).
    """
    bins = rough["bin"].to_numpy(dtype=np.int64)
    res_m = _wheel_resolution(rough, settings, wheel_diameter)
    kw = {"bin_length": settings.bin_length_m, "resolution_m": res_m, "filter_order": int(settings.filter_order)}
    if "cross_re" in rough:
        amp, sd, shared = two_rail_estimate(bins, rough["cross_re"].to_numpy(), rough["pow"].to_numpy(),
                                    rough["pow_other"].to_numpy(), **kw)
    else:
        env = rough["re"].to_numpy() + 1j * rough["im"].to_numpy()
        floor = rough[["floor_lo", "floor_hi"]].to_numpy().T
        amp, sd, shared = single_wheel_estimate(bins, rough["pow"].to_numpy(), floor, env, **kw)
    if settings.edge_preserving_sd > 0:  # steps kept, the fluctuation of the stated 1-σ between them flattened
        amp = edge_preserving(bins, amp, sd, float(settings.edge_preserving_sd))
    return pd.DataFrame({"bin": bins, "sleeper_amp": amp, "sleeper_amp_sd": sd, "sleeper_amp_sd_shared": shared})


def assemble_wheel(
    settings: ProcessingSettings, chunk_paths: Sequence[Path], wheel: str
) -> tuple[pd.DataFrame, dict[str, Any]] | None:
    """Merge one wheel's sums from the chunk files into its profile rows and OOR result.

    Parameters
    ----------
    settings : ProcessingSettings
    chunk_paths : sequence of Path
        One file per chunk (any order).
    wheel : str
        ``"11"``, ``"12"``, ``"41"`` or ``"42"``.

    Returns
    -------
    (pandas.DataFrame, dict) or None
        Profile rows of the wheel sorted by bin (columns of ``RunResults.profiles``, ``sleeper_step`` the
        step estimate of its ``sleeper_amp``: :func:`sleeper_step`) and its entry of
        ``RunResults.wheels``; None if the chunks hold no data of the wheel. Deterministic: the same
        files give the same result. The run's track impacts are not bridged (:func:`finish_assembly`).
    """
    done = wheel_assembly(settings, chunk_paths, wheel)
    return None if done is None else (done.profiles, done.result)


def wheel_assembly(settings: ProcessingSettings, chunk_paths: Sequence[Path], wheel: str) -> WheelAssembly | None:
    """:func:`assemble_wheel` with the wheel's track resolution, m (what :func:`finish_assembly` takes).

    Returns
    -------
    WheelAssembly or None
        None if the chunks hold no data of the wheel.
    """
    done = _assemble_wheel(settings, chunk_paths, wheel)
    if done is None:
        return None
    prof, result, res_m = done
    return WheelAssembly(_with_steps(prof, {wheel: res_m}, settings.bin_length_m), result, res_m)


def _assemble_wheel(
    settings: ProcessingSettings, chunk_paths: Sequence[Path], wheel: str
) -> tuple[pd.DataFrame, dict[str, Any], float] | None:
    """:func:`assemble_wheel` without the step estimate (``sleeper_step`` NaN), and the wheel's track
    resolution, m (:func:`_wheel_resolution`)."""
    g: dict[str, list[BinSums]] = {}
    d_w = DEFAULT_WHEEL_DIAMETER_M
    notes: dict[str, None] = {}
    for path in sorted(chunk_paths, key=lambda p: str(p)):
        parts = read_wheel(path, wheel)
        for kind, part in parts.groups.items():
            g.setdefault(kind, []).append(part)
        if parts.diameter_m is not None:
            d_w = parts.diameter_m
        notes.update(dict.fromkeys(parts.warnings))
    if not g:
        return None
    prof = BinSums.merge_all(g["bins"]).finalize(settings.bin_length_m)
    resid = BinSums.merge_all(g["resid"]).finalize(settings.bin_length_m)
    prof = prof.merge(resid[["bin", "residual_rms"]], on="bin", how="left")
    prof = prof[prof["n_samples"] > 0]
    prof = prof.rename(columns={"sleeper_amp": "sleeper_amp_raw"})
    rough = BinSums.merge_all(g["rough"]).finalize(settings.bin_length_m) if g.get("rough") else None
    if rough is not None:
        prof = prof.merge(sleeper_estimate(rough, settings, d_w), on="bin", how="left")
    elif "sleeper_amp_raw" in prof:  # chunk files before issue 26: the single-wheel amplitude, no 1-σ
        prof["sleeper_amp"] = prof["sleeper_amp_raw"]
    for col in (*TRACK_COLUMNS, *ROUGHNESS_COLUMNS, *[f"order_amp_{lvl:02d}" for lvl in _wheel_order_numbers(settings)],
                "sleeper_force_amp"):
        if col not in prof:  # not extracted (collision, no force channel, older chunk files)
            prof[col] = np.nan
    prof = prof.rename(columns={"speed": "speed_mean"})
    prof[IMPACT_COLUMN] = np.nan  # written across the wheels by assemble (track impacts)
    prof[STEP_COLUMN] = np.nan  # from the stored sleeper_amp: after the track impacts are bridged
    prof.insert(0, "wheel", wheel)
    prof = prof[_profile_columns(settings)].sort_values("bin").reset_index(drop=True)
    prof["bin"] = prof["bin"].astype(np.int64)
    prof["n_samples"] = prof["n_samples"].astype(np.int64)
    result = _wheel_result(wheel, g.get("oor", []), d_w, settings)
    result["warnings"] = list(notes)
    return prof, result, _wheel_resolution(rough, settings, d_w)


def run_warnings(wheels: Sequence[dict[str, Any]]) -> list[str]:
    """The job's warnings from its wheel results: each text once, naming the wheels it concerns.

    Parameters
    ----------
    wheels : sequence of dict
        ``RunResults.wheels`` (entries with ``wheel`` and ``warnings``).

    Returns
    -------
    list of str
        ``"wheels 11, 12: <text>"``, in the order first met.
    """
    seen: dict[str, list[str]] = {}
    for w in wheels:
        for text in w.get("warnings") or ():
            seen.setdefault(str(text), []).append(str(w.get("wheel")))
    return [f"wheel{'s' if len(ws) > 1 else ''} {', '.join(ws)}: {text}" for text, ws in seen.items()]


def results_meta(settings: ProcessingSettings, n_chunks: int, warnings: Sequence[str] = ()) -> dict[str, Any]:
    """Provenance stored with a job's results (engine version, settings) and its warnings.

    ``warnings`` (:func:`run_warnings`) are what the results cannot be trusted
    for; the API shows them with the job. ``step_estimate``: the profile rows hold ``sleeper_step``
    (:func:`sleeper_step`) with this change-point penalty (jobs without it stored none).
    """
    return {"engine": ENGINE_VERSION, "settings": settings.to_dict(), "oor_window_m": OOR_WINDOW_M,
            "n_chunks": n_chunks, "warnings": list(warnings), "step_estimate": {"penalty": DEFAULT_STEP_PENALTY}}


def assemble(run_path: Path, settings: ProcessingSettings, chunk_paths: Sequence[Path]) -> RunResults:
    """Merge chunk files into profile rows and wheel results (:func:`assemble_wheel` per wheel).

    Parameters
    ----------
    run_path : Path
        Canonical run file (unused: the chunk files hold everything; kept so
        that every pipeline step takes the run).
    settings : ProcessingSettings
    chunk_paths : sequence of Path
        One file per chunk (any order).

    Returns
    -------
    RunResults
    """
    frames, wheels, resolutions = [], [], {}
    for wheel in WHEELS:
        # one wheel at a time: only its partial sums are in memory
        done = _assemble_wheel(settings, chunk_paths, wheel)
        if done is not None:
            frames.append(done[0])
            wheels.append(done[1])
            resolutions[wheel] = done[2]
    cols = _profile_columns(settings)
    profiles = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=cols)
    return finish_assembly(settings, chunk_paths, profiles, wheels, resolutions)


def finish_assembly(settings: ProcessingSettings, chunk_paths: Sequence[Path], profiles: pd.DataFrame,
                    wheels: Sequence[dict[str, Any]], resolutions: dict[str, float]) -> RunResults:
    """The run's results once every wheel is assembled: track impacts bridged, steps, flats, provenance.

    Both worker modes end the assembly here: the local one with the wheels it assembled in turn
    (:func:`assemble`), the fan-out one with the rows its wheels stored (``worker.tasks.publish_job``).
    The isolated impacts are found in the chunk files (:func:`app.pipeline.impacts.run_impacts`), the
    profile's track columns bridged around the track impacts
    (:func:`app.pipeline.impacts.mask_track_impacts`, ``track_impact_mm`` written), the step estimate
    taken of ``sleeper_amp`` as bridged (:func:`sleeper_step`) and the wheel flats put on their wheels.

    Parameters
    ----------
    settings : ProcessingSettings
    chunk_paths : sequence of Path
        The run's chunk files (any order).
    profiles : pandas.DataFrame
        Every wheel's profile rows as assembled alone (columns of ``RunResults.profiles``; ``sleeper_step``
        and ``track_impact_mm`` are written anew).
    wheels : sequence of dict
        The wheels' results (``RunResults.wheels``) in the order of :data:`app.io.WHEELS`; not changed.
    resolutions : dict
        Per wheel, the track orders' resolution it was solved with, m (:attr:`WheelAssembly.resolution_m`).

    Returns
    -------
    RunResults
        The profiles, the wheel results each with its ``flat`` (:func:`app.pipeline.impacts.flat_result`)
        and :func:`results_meta` with ``track_impacts`` (:func:`app.pipeline.impacts.impacts_meta`).
    """
    # isolated impacts: track impacts bridged out of the sleeper indicator, wheel flats onto the wheels
    impacts, flats = run_impacts(chunk_paths, wheels)
    # the widest of the wheels' track resolutions (with track_resolution_m None it follows the wheel's diameter)
    extents = impact_extents(profiles, impacts, settings, max(resolutions.values(), default=None))
    profiles = mask_track_impacts(profiles, impacts, settings, extents)
    # the step estimate of sleeper_amp as stored (bridged around the track impacts)
    profiles = _with_steps(profiles, resolutions, settings.bin_length_m)
    results = [{**w, "flat": flat_result(flats.get(str(w["wheel"])))} for w in wheels]
    meta = results_meta(settings, len(chunk_paths), run_warnings(results))
    meta["track_impacts"] = impacts_meta(impacts, extents)
    return RunResults(profiles=profiles, wheels=results, meta=meta)


def _wheel_result(wheel: str, parts: list[BinSums], d_w: float, settings: ProcessingSettings) -> dict[str, Any]:
    windows = BinSums.merge_all(parts).finalize(OOR_WINDOW_M) if parts else None
    orders = _wheel_order_numbers(settings)
    if windows is not None:  # the orders extracted (a wheel order colliding with the sleeper order is not)
        orders = np.array([lvl for lvl in orders if f"re_{lvl:02d}" in windows.columns], dtype=np.int64)
    if windows is None or windows.empty:
        phasors = np.full((orders.size, 0), np.nan + 0j)
        centres = np.zeros(0)
        acc = np.full(orders.size, np.nan)
    else:
        windows = windows.dropna(subset=[f"re_{lvl:02d}" for lvl in orders])
        phasors = np.vstack([windows[f"re_{lvl:02d}"].to_numpy() + 1j * windows[f"im_{lvl:02d}"].to_numpy()
                             for lvl in orders])
        centres = (windows["bin"].to_numpy() + 0.5) * OOR_WINDOW_M
        acc = np.array([float(np.nanmean(windows[f"acc_{lvl:02d}"])) if len(windows) else np.nan for lvl in orders])
    diameter = d_w
    if phasors.shape[1] >= 5:
        diameter = refine_diameter(phasors, centres, d_w, orders)
        if diameter != d_w:
            phasors = apply_diameter_correction(phasors, centres, orders, d_w, diameter)
    summary = summarize_oor(phasors, orders)
    for entry, a in zip(summary["orders"], acc, strict=True):
        entry["accel_amp"] = float(a)
    summary.update({"wheel": wheel, "wheel_diameter_m": float(d_w), "refined_diameter_m": float(diameter)})
    return summary
