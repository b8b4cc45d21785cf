"""Processing pipeline of a run: plan chunks → process each chunk → assemble.

The three steps are plain functions over files so that any queue can run
them (the local SQLite worker, Procrastinate workers on several hosts, the
``process`` command):

* :func:`plan_chunks` cuts the run into chunks of ``settings.chunk_seconds``
  with the overlap the VKF needs (from its impulse response at the slowest
  speed of the chunk) and a raised-cosine crossfade at each seam.
* :func:`process_chunk` runs the VKF for every wheel (Z and, if present, Q
  channel solved together: one factorisation, two right-hand sides) and
  writes **additive** per-bin sums (crossfade-weighted) to one ``.npz`` file,
  atomically. Running it twice writes the same file.
* :func:`assemble` adds the chunk sums and turns them into the 25 cm profile
  rows and the wheel out-of-roundness results. It is deterministic and
  idempotent; it reads no raw signal.

Orders per wheel: index 0 = sleeper passage ``v/d_s``, 1..n = wheel orders
``l·v/(π d_w)`` with that wheel's diameter. Bandwidth = ``bandwidth_orders ×
v/(π d_w)`` (constant in orders), floored at its value at the minimum speed.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from app.analysis.binning import BinSums, position_to_bin
from app.analysis.chunking import Chunk, plan_chunk_layout
from app.analysis.order_residual import railway_residual
from app.analysis.orders import OrderTrack, railway_multipliers
from app.analysis.settings import ProcessingSettings
from app.analysis.vkf import vkf, vkf_overlap
from app.analysis.wheel_oor import (
    apply_diameter_correction,
    radius_phasor,
    refine_diameter,
    summarize_oor,
)
from app.io import WHEELS, open_run

__all__ = [
    "ChunkSpec",
    "RunResults",
    "PipelineCancelled",
    "plan_chunks",
    "process_chunk",
    "assemble",
    "assemble_wheel",
    "results_meta",
    "run_pipeline",
    "ENGINE_VERSION",
]

#: bump when the stored numbers would change for the same input and settings
ENGINE_VERSION = "trackvkf-pipeline/2"
#: neglected impulse-response tail at chunk seams: chunked profiles agree with an
#: unchunked solve to ~1e-5 of the signal level (far below the indicators' noise),
#: with 40 % less overlap than the engine's own 1e-8
CHUNK_JOIN_TOL = 1e-5
#: wheel OOR phasors are averaged over windows of this travelled distance, m
OOR_WINDOW_M = 50.0
#: envelope output spacing for binning, m (several points per 25 cm bin)
_OUTPUT_SPACING_M = 0.05
#: full-rate block length for residuals, samples
_BLOCK = 1 << 16


class PipelineCancelled(RuntimeError):
    """Raised by :func:`process_chunk` when ``should_cancel()`` turned true."""


#: a chunk task of a run: the engine's chunk layout (JSON via to_dict/from_dict)
ChunkSpec = Chunk


@dataclass
class RunResults:
    """Profiles, wheel results and provenance of one processed run."""

    profiles: pd.DataFrame
    wheels: list[dict[str, Any]]
    meta: dict[str, Any] = field(default_factory=dict)


def _wheel_orders(run: Any, wheel: str, settings: ProcessingSettings) -> tuple[np.ndarray, float]:
    d_w = float(run.metadata.wheel_diameters.get(wheel, 0.92))
    mult = railway_multipliers(d_w, float(run.metadata.sleeper_spacing), settings.n_wheel_orders)
    return mult, d_w


def _bandwidth_per_speed(settings: ProcessingSettings, d_w: float) -> tuple[float, float]:
    """(Hz per m/s, floor in Hz) of the order filters."""
    per_speed = settings.bandwidth_orders / (np.pi * d_w)
    return per_speed, per_speed * max(settings.min_speed_kmh / 3.6, 1.0)


def plan_chunks(run_path: Path, settings: ProcessingSettings) -> list[ChunkSpec]:
    """Cut a run into chunks with the overlap the VKF needs.

    Parameters
    ----------
    run_path : Path
        Canonical run file (HDF5).
    settings : ProcessingSettings

    Returns
    -------
    list of ChunkSpec
        Cores tile ``[0, n_samples)``; JSON-serialisable via ``to_dict``.
    """
    with open_run(run_path) as run:
        n, fs = run.n_samples, run.fs
        speed = run.speed()
        d_min = min(float(run.metadata.wheel_diameters.get(w, 0.92)) for w in WHEELS)
        d_max = max(float(run.metadata.wheel_diameters.get(w, 0.92)) for w in WHEELS)
        mult = railway_multipliers(d_min, float(run.metadata.sleeper_spacing), settings.n_wheel_orders)
    core = max(int(round(settings.chunk_seconds * fs)), 1)
    per_speed, floor = _bandwidth_per_speed(settings, d_max)
    fmax_nyq = 0.499 * fs

    def overlap(a: int, b: int) -> int:
        v = np.abs(speed[a:b])
        v_min, v_max = float(v.min()), float(v.max())
        f_max = min(float(mult.max()) * v_max, fmax_nyq)
        bw_min = max(per_speed * v_min, floor)
        bw_max = max(per_speed * v_max, floor)
        return vkf_overlap(fs, 0.0, f_max, bw_min, bw_max, settings.filter_order, tol=CHUNK_JOIN_TOL)

    return plan_chunk_layout(n, core, overlap)


def _atomic_savez(path: Path, arrays: dict[str, np.ndarray]) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, **arrays)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _residual_sums(
    y: np.ndarray,
    env: np.ndarray,
    out_idx: np.ndarray,
    psi: np.ndarray,
    mult: np.ndarray,
    chunk: ChunkSpec,
    lo: int,
    bins_of: Callable[[np.ndarray], np.ndarray],
    keep: Callable[[np.ndarray], np.ndarray],
    should_cancel: Callable[[], bool],
) -> BinSums:
    """Crossfade-weighted Σ residual² per bin at the full rate, block by block.

    Parameters
    ----------
    y : ndarray, shape (N_chunk,)
        Measured acceleration of one wheel over the chunk, m/s².
    env : ndarray, complex, shape (s, m)
        Envelopes (peak phasors) of the orders on the output grid ``out_idx``.
    out_idx : ndarray of int, shape (m,)
        Regular output grid ``out_lo, out_lo + step, …`` (global samples).
    psi : ndarray, shape (N_chunk,)
        Phase per unit multiplier (order phase = ``mult[n] × psi``), rad.

    Notes
    -----
    The waveforms are evaluated by :func:`app.analysis.order_residual.railway_residual`
    (envelopes linear between grid points: spacing ≤ 5 cm, ≥ 100x the filter
    bandwidth), one block of grid intervals at a time.
    """
    step = int(out_idx[1] - out_idx[0]) if out_idx.size > 1 else 1
    base = int(out_idx[0])
    rows_per_block = max(1, _BLOCK // step)
    n_rows = -(-(chunk.out_hi - base) // step)
    parts = []
    for r0 in range(0, n_rows, rows_per_block):
        if should_cancel():
            raise PipelineCancelled(f"cancelled in chunk {chunk.index}")
        r1 = min(r0 + rows_per_block, n_rows)
        a = base + r0 * step
        b = min(base + r1 * step, chunk.out_hi)
        r = railway_residual(y[a - lo : b - lo], psi[a - lo : b - lo], env[:, r0 : r1 + 1], step, mult)
        idx = np.arange(a, b)
        w = chunk.weight(idx) * keep(idx)
        parts.append(BinSums.from_samples(bins_of(idx), w, {"residual": r}, squares=("residual",)))
    return BinSums.merge_all(parts)


def _wheel_groups(run: Any, settings: ProcessingSettings) -> list[tuple[list[str], np.ndarray, float]]:
    """Wheels present in the run, grouped by diameter: (wheels, multipliers, d_w).

    Wheels with equal diameters have the same orders, so their channels share
    one factorisation of the VKF system.
    """
    groups: dict[float, list[str]] = {}
    for wheel in WHEELS:
        if run.has(f"Z{wheel}"):
            d_w = float(run.metadata.wheel_diameters.get(wheel, 0.92))
            groups.setdefault(d_w, []).append(wheel)
    out = []
    for d_w, wheels in groups.items():
        mult, _ = _wheel_orders(run, wheels[0], settings)
        out.append((wheels, mult, d_w))
    return out


def process_chunk(
    run_path: Path,
    settings: ProcessingSettings,
    chunk: ChunkSpec,
    out_path: Path,
    should_cancel: Callable[[], bool] = lambda: False,
) -> None:
    """Process one chunk of a run and write its per-bin sums atomically.

    Parameters
    ----------
    run_path : Path
        Canonical run file.
    settings : ProcessingSettings
    chunk : ChunkSpec
    out_path : Path
        Target ``.npz``; written via a temporary file and ``os.replace``.
    should_cancel : callable
        Polled between wheel groups and residual blocks.

    Raises
    ------
    PipelineCancelled
        If ``should_cancel()`` returned True.

    Notes
    -----
    Wheels of equal diameter share their orders: their Z (and Q) channels are
    solved together, one factorisation for all of them.
    """
    arrays: dict[str, np.ndarray] = {"chunk_index": np.array(chunk.index)}
    with open_run(run_path) as run:
        fs = run.fs
        lo, hi = chunk.lo, chunk.hi
        speed = run.speed(lo, hi)
        v_abs = np.abs(speed)
        min_v = settings.min_speed_kmh / 3.6
        position = run.position(lo, hi)
        v_max = max(float(v_abs.max()), 1.0)
        step = max(1, int(np.floor(fs * _OUTPUT_SPACING_M / v_max)))
        out_idx = np.arange(chunk.out_lo, chunk.out_hi, step)
        w_out = chunk.weight(out_idx)
        moving = v_abs[out_idx - lo] >= min_v
        # wheel angle θ = 2 s / d_w referred to the run start; psi × mult = phase
        psi = 2.0 * np.pi * (float(position[0]) + np.cumsum(v_abs) / fs)
        orders = np.arange(1, settings.n_wheel_orders + 1)
        win = np.floor(position[out_idx - lo] / OOR_WINDOW_M).astype(np.int64)

        def keep(idx: np.ndarray) -> np.ndarray:
            return (v_abs[idx - lo] >= min_v).astype(float)

        for wheels, mult, d_w in _wheel_groups(run, settings):
            if should_cancel():
                raise PipelineCancelled(f"cancelled in chunk {chunk.index}")
            channels: list[str] = []
            rows: dict[str, tuple[int, int | None]] = {}
            for wheel in wheels:
                iz = len(channels)
                channels.append(f"Z{wheel}")
                iq = None
                if run.has(f"Q{wheel}"):
                    iq = len(channels)
                    channels.append(f"Q{wheel}")
                rows[wheel] = (iz, iq)
            y = np.vstack([run.read(c, lo, hi) for c in channels])
            per_speed, floor = _bandwidth_per_speed(settings, d_w)
            freqs = OrderTrack(v_abs, mult)
            bandwidth = OrderTrack(v_abs, np.full(mult.size, per_speed), floor=floor)
            phase0 = 2.0 * np.pi * mult * float(position[0])
            res = vkf(y, fs, freqs, bandwidth, settings.filter_order, chunk_duration=np.inf, phase0=phase0)
            env_all = res.envelope_at(out_idx - lo)  # (channels, s, m)
            del res
            for wheel in wheels:
                iz, iq = rows[wheel]
                env = env_all[iz]
                amp = np.abs(env)
                track_m = run.track_m(lo, hi, axle=wheel[0])

                def bins_of(idx: np.ndarray, track_m: np.ndarray = track_m) -> np.ndarray:
                    return position_to_bin(track_m[idx - lo], settings.bin_length_m)

                values = {"speed": v_abs[out_idx - lo], "sleeper_amp": amp[0]}
                for lvl in orders:
                    values[f"order_amp_{lvl:02d}"] = amp[lvl]
                if iq is not None:
                    values["sleeper_force_amp"] = np.abs(env_all[iq, 0])
                sums = BinSums.from_samples(bins_of(out_idx), w_out * moving, values)
                resid = _residual_sums(y[iz], env, out_idx, psi, mult, chunk, lo, bins_of, keep, should_cancel)
                arrays.update(_pack_group(f"bins_{wheel}__", sums.to_arrays()))
                arrays.update(_pack_group(f"resid_{wheel}__", resid.to_arrays()))

                # wheel OOR: radius phasors of the wheel orders, summed per window
                rho = radius_phasor(env[1:], v_abs[out_idx - lo], d_w, orders)
                ok = moving & np.all(np.isfinite(rho), axis=0)
                oor_vals = {}
                for i, lvl in enumerate(orders):
                    oor_vals[f"re_{lvl:02d}"] = np.where(ok, rho[i].real, np.nan)
                    oor_vals[f"im_{lvl:02d}"] = np.where(ok, rho[i].imag, np.nan)
                    oor_vals[f"acc_{lvl:02d}"] = np.where(ok, amp[i + 1], np.nan)
                oor = BinSums.from_samples(win, w_out * ok, oor_vals)
                arrays.update(_pack_group(f"oor_{wheel}__", oor.to_arrays()))
                arrays[f"diameter_{wheel}"] = np.array(d_w)
    _atomic_savez(out_path, arrays)


def _pack_group(prefix: str, arrays: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """One group of equal-length arrays as four ``.npz`` members.

    ``packed_names`` lists the float names, ``"|"``, the integer names, ``"|"``
    and the scalar names; ``packed_f8`` / ``packed_i8`` hold the float / integer
    arrays as rows, ``packed_scalars`` the integer scalars.

    A chunk file holds ~50 arrays per wheel; as separate members, reading them
    back cost more than merging them (each member is a zip entry with a parsed
    header). Packed, a group is four members whatever its size.
    """
    lengths = {np.asarray(v).shape for v in arrays.values() if np.asarray(v).ndim == 1}
    if len(lengths) > 1:
        raise ValueError(f"{prefix}: arrays of different lengths {sorted(lengths)}")
    floats = [k for k, v in arrays.items() if np.asarray(v).ndim == 1 and np.asarray(v).dtype.kind == "f"]
    ints = [k for k, v in arrays.items() if np.asarray(v).ndim == 1 and np.asarray(v).dtype.kind in "iu"]
    scalars = [k for k in arrays if k not in floats and k not in ints]
    if any(np.asarray(arrays[k]).ndim != 0 or np.asarray(arrays[k]).dtype.kind not in "iu" for k in scalars):
        raise ValueError(f"{prefix}: only 1-D float/int arrays and integer scalars can be packed")
    n = lengths.pop()[0] if lengths else 0
    return {
        f"{prefix}packed_names": np.array(floats + ["|"] + ints + ["|"] + scalars, dtype=np.str_),
        f"{prefix}packed_f8": np.array([arrays[k] for k in floats], dtype=np.float64).reshape(len(floats), n),
        f"{prefix}packed_i8": np.array([arrays[k] for k in ints], dtype=np.int64).reshape(len(ints), n),
        f"{prefix}packed_scalars": np.array([int(arrays[k]) for k in scalars], dtype=np.int64),
    }


def _load_group(npz: Any, prefix: str) -> BinSums | None:
    """A group written by :func:`_pack_group` (or, in older files, one member per array)."""
    if f"{prefix}packed_names" in npz.files:
        names = [str(x) for x in npz[f"{prefix}packed_names"]]
        cut1 = names.index("|")
        cut2 = names.index("|", cut1 + 1)
        floats, ints, scalars = names[:cut1], names[cut1 + 1 : cut2], names[cut2 + 1 :]
        f8, i8 = npz[f"{prefix}packed_f8"], npz[f"{prefix}packed_i8"]
        sc = npz[f"{prefix}packed_scalars"]
        arrays = {k: f8[i] for i, k in enumerate(floats)}
        arrays.update({k: i8[i] for i, k in enumerate(ints)})
        arrays.update({k: sc[i] for i, k in enumerate(scalars)})
        return BinSums.from_arrays(arrays)
    keys = {k[len(prefix) :]: npz[k] for k in npz.files if k.startswith(prefix)}
    return BinSums.from_arrays(keys) if keys else None


def _profile_columns(settings: ProcessingSettings) -> list[str]:
    orders = [f"order_amp_{lvl:02d}" for lvl in range(1, settings.n_wheel_orders + 1)]
    return ["wheel", "bin", "km", "n_samples", "speed_mean", "sleeper_amp", *orders,
            "residual_rms", "sleeper_force_amp"]


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
        Profile rows of the wheel sorted by bin (columns of ``RunResults.profiles``)
        and its entry of ``RunResults.wheels``; None if the chunks hold no data
        of the wheel. Deterministic: the same files give the same result.
    """
    g: dict[str, list[BinSums]] = {}
    d_w = 0.92
    for path in sorted(chunk_paths, key=lambda p: str(p)):
        with np.load(path) as npz:
            for kind in ("bins", "resid", "oor"):
                part = _load_group(npz, f"{kind}_{wheel}__")
                if part is not None:
                    g.setdefault(kind, []).append(part)
            if f"diameter_{wheel}" in npz.files:
                d_w = float(npz[f"diameter_{wheel}"])
    if not g:
        return None
    prof = BinSums.merge_all(g["bins"]).finalize(settings.bin_length_m)
    resid = BinSums.merge_all(g["resid"]).finalize(settings.bin_length_m)
    prof = prof.merge(resid[["bin", "residual_rms"]], on="bin", how="left")
    prof = prof[prof["n_samples"] > 0]
    if "sleeper_force_amp" not in prof:
        prof["sleeper_force_amp"] = np.nan
    prof = prof.rename(columns={"speed": "speed_mean"})
    prof.insert(0, "wheel", wheel)
    prof = prof[_profile_columns(settings)].sort_values("bin").reset_index(drop=True)
    prof["bin"] = prof["bin"].astype(np.int64)
    prof["n_samples"] = prof["n_samples"].astype(np.int64)
    return prof, _wheel_result(wheel, g.get("oor", []), d_w, settings)


def results_meta(settings: ProcessingSettings, n_chunks: int) -> dict[str, Any]:
    """Provenance stored with a job's results (engine version, settings)."""
    return {"engine": ENGINE_VERSION, "settings": settings.to_dict(), "oor_window_m": OOR_WINDOW_M,
            "n_chunks": n_chunks}


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
    frames, wheels = [], []
    for wheel in WHEELS:
        # one wheel at a time: only its partial sums are in memory
        done = assemble_wheel(settings, chunk_paths, wheel)
        if done is not None:
            frames.append(done[0])
            wheels.append(done[1])
    cols = _profile_columns(settings)
    profiles = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=cols)
    return RunResults(profiles=profiles, wheels=wheels, meta=results_meta(settings, len(chunk_paths)))


def _wheel_result(wheel: str, parts: list[BinSums], d_w: float, settings: ProcessingSettings) -> dict[str, Any]:
    orders = np.arange(1, settings.n_wheel_orders + 1)
    windows = BinSums.merge_all(parts).finalize(OOR_WINDOW_M) if parts else None
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


def run_pipeline(
    run_path: Path,
    settings: ProcessingSettings,
    work_dir: Path,
    progress: Callable[[float], None] | None = None,
    should_cancel: Callable[[], bool] | None = None,
) -> RunResults:
    """Plan, process (skipping chunk files that exist) and assemble a run.

    Parameters
    ----------
    run_path : Path
        Canonical run file.
    settings : ProcessingSettings
    work_dir : Path
        Directory for chunk files ``chunk-00000.npz`` …
    progress : callable, optional
        Called with the fraction of chunks done (0–1).
    should_cancel : callable, optional
        Polled between sub-blocks.
    """
    cancel = should_cancel or (lambda: False)
    chunks = plan_chunks(run_path, settings)
    work_dir = Path(work_dir)
    paths = []
    for i, chunk in enumerate(chunks):
        path = work_dir / f"chunk-{chunk.index:05d}.npz"
        if not path.exists():
            process_chunk(run_path, settings, chunk, path, cancel)
        paths.append(path)
        if progress is not None:
            progress((i + 1) / len(chunks))
    return assemble(run_path, settings, paths)
