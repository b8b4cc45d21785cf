"""Step 2 of the pipeline: solve one chunk of a run and write its per-bin sums.

:func:`process_chunk` runs the VKF of every wheel's order recipe
(:mod:`app.analysis.recipe`; the Z and, if present, Q channels of wheels of
equal diameter solved together: one factorisation, several right-hand sides)
and writes **additive**, crossfade-weighted per-bin sums to one chunk file
(:mod:`app.pipeline.chunkfile`), atomically. Running it twice writes the same
file.

Force channels lose their static load first (a moving mean over
``settings.force_mean_window_m`` of travel, :mod:`app.analysis.static_load`).
What a wheel's results cannot be trusted for is written beside its sums as
plain-language warnings (:func:`chunk_warnings`: colliding orders dropped by
the recipe, a chunk shorter than the filters need, the engine's own
``VKFWarning``), which assembly gathers onto the job.
"""

from __future__ import annotations

import logging
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from app.analysis.binning import BinSums, position_to_bin
from app.analysis.order_residual import railway_residual
from app.analysis.recipe import (
    OrderRecipe,
    harmonic_label,
    order_overlap,
    travel_phase,
    wheel_recipe,
)
from app.analysis.settings import ProcessingSettings
from app.analysis.static_load import remove_static_load
from app.analysis.units import KMH_PER_MPS
from app.analysis.vkf import VKFResult, VKFWarning
from app.analysis.wheel_oor import radius_phasor
from app.io import WHEELS, open_run
from app.pipeline.chunkfile import wheel_members, write_chunk_file
from app.pipeline.impacts import chunk_dip_member, wheel_orders_at
from app.pipeline.plan import ChunkSpec
from app.pipeline.roughness_sums import SleeperTrack, recipe_floor_gain, rough_groups

__all__ = ["OOR_WINDOW_M", "SHORT_RECORD_TOL", "PipelineCancelled", "chunk_warnings", "process_chunk",
           "sleeper_rms", "solve_logged", "wheel_groups"]

log = logging.getLogger(__name__)

#: wheel OOR phasors are averaged over windows of this travelled distance, m
OOR_WINDOW_M = 50.0
#: envelope output spacing for binning, m (several points per 25 cm bin)
_OUTPUT_SPACING_M = 0.05
#: full-rate block length for residuals, samples
_BLOCK = 1 << 16
#: a solved stretch is "too short" when it is shorter than the impulse response of
#: its narrowest order filter down to this fraction (see chunk_warnings)
SHORT_RECORD_TOL = 0.1


class PipelineCancelled(RuntimeError):
    """Raised by :func:`process_chunk` when ``should_cancel()`` turned true."""


def _residual_sums(
    y: np.ndarray,
    env: np.ndarray,
    out_idx: np.ndarray,
    psi: np.ndarray,
    recipe: OrderRecipe,
    chunk: ChunkSpec,
    lo: int,
    bins_of: Callable[[np.ndarray], np.ndarray],
    keep: Callable[[np.ndarray], np.ndarray],
    should_cancel: Callable[[], bool],
) -> tuple[BinSums, np.ndarray]:
    """Crossfade-weighted Σ residual² per bin at the full rate, block by block.

    Also returns the residual mixed down by the sleeper phase and averaged over
    every interval of the output grid (complex, one value per ``out_idx``), for
    the floor beside the sleeper order (:mod:`app.pipeline.roughness_sums`).

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
    mult, powers, n_track = recipe.multipliers, recipe.powers, len(recipe.track_rows)
    rows_per_block = max(1, _BLOCK // step)
    n_rows = -(-(chunk.out_hi - base) // step)
    parts, demod = [], []
    for r0 in range(0, n_rows, rows_per_block):
        if should_cancel():
            raise PipelineCancelled(f"cancelled in chunk {chunk.index}")
        r1 = min(r0 + rows_per_block, n_rows)
        a = base + r0 * step
        b = min(base + r1 * step, chunk.out_hi)
        r, z = railway_residual(y[a - lo : b - lo], psi[a - lo : b - lo], env[:, r0 : r1 + 1], step, mult,
                                powers, n_track, demodulate=True)
        demod.append(z)
        idx = np.arange(a, b)
        w = chunk.weight(idx) * keep(idx)
        parts.append(BinSums.from_samples(bins_of(idx), w, {"residual": r}, squares=("residual",)))
    return BinSums.merge_all(parts), np.concatenate(demod)[: out_idx.size]


def sleeper_rms(amplitudes: np.ndarray) -> np.ndarray:
    """Sleeper-passage RMS (the energy indicator) from the peak amplitudes of its harmonics.

    Parameters
    ----------
    amplitudes : ndarray, shape (h, ...)
        Peak amplitudes of the fundamental and the extracted harmonics, m/s².

    Returns
    -------
    ndarray, shape (...)
        ``sqrt(Σ_h A_h² / 2)``: the RMS of the periodic signal they make up, m/s².
    """
    a = np.asarray(amplitudes, dtype=np.float64)
    return np.sqrt(0.5 * np.sum(a * a, axis=0))


def solve_logged(recipe: OrderRecipe, y: np.ndarray, fs: float, speed: np.ndarray, start_m: float,
                 notes: list[str]) -> VKFResult:
    """:meth:`OrderRecipe.solve` with the engine's warnings sent to the log and to ``notes``.

    Orders closer than their bandwidth are the recipe's design (wide track
    orders beside narrow wheel orders, :func:`app.analysis.recipe.order_collisions`
    drops those that really collide; :meth:`OrderRecipe.solve` does not warn of
    them): those pairs go to the debug log only. Every ``VKFWarning`` (an
    ill-conditioned solve) is logged and appended to ``notes``; nothing is printed raw.
    """
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", VKFWarning)
        res = recipe.solve(y, fs, speed, start_m)
    if res.close_orders:
        log.debug("VKF: orders %s come closer than their bandwidth (the recipe's design)", sorted(res.close_orders))
    for w in caught:
        text = str(w.message)
        if not issubclass(w.category, VKFWarning):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        else:
            log.warning("VKF: %s", text)
            notes.append(f"VKF: {text}")
    return res


def chunk_warnings(recipe: OrderRecipe, fs: float, speed: np.ndarray, n_samples: int,
                   where: str) -> list[str]:
    """Plain-language warnings of one wheel's solve over a stretch of a run.

    * every collision the recipe resolved by dropping an order (:attr:`OrderRecipe.notes`);
    * a stretch too short for the orders asked: shorter than the impulse
      response of the narrowest order filter down to :data:`SHORT_RECORD_TOL`
      (:func:`app.analysis.recipe.order_overlap` at the stretch's speeds).
      Below that, the filter cannot settle anywhere in the stretch and the
      coupled solve leans on its structural equation alone (its envelopes
      become near-linear in time): measured on 12 orders at 0.1 wheel
      orders, amplitudes off by -44 % … x700 under ~1 s.

    Parameters
    ----------
    recipe : OrderRecipe
    fs : float
        Sample rate, Hz.
    speed : ndarray
        Absolute speed over the stretch, m/s.
    n_samples : int
        Samples solved.
    where : str
        Names the stretch in the message (``"chunk 3"``, ``"the run"``).
    """
    out = list(recipe.notes)
    moving = np.abs(np.asarray(speed, dtype=np.float64))
    moving = moving[moving >= recipe.min_speed]
    if moving.size:
        need = order_overlap(fs, moving, [recipe], tol=SHORT_RECORD_TOL)
        if n_samples < need:
            out.append(
                f"{where} is {n_samples / fs:.2f} s long, shorter than the {need / fs:.2f} s the narrowest "
                f"order filter needs to settle (its impulse response to {SHORT_RECORD_TOL:.0%}): "
                "its amplitudes are unreliable; process a longer record or widen bandwidth_orders"
            )
    return out


def wheel_groups(run: Any, settings: ProcessingSettings) -> list[tuple[list[str], OrderRecipe]]:
    """Wheels present in the run, grouped by diameter, with their order recipe.

    Wheels with equal diameters have the same orders, so their channels share
    one factorisation of the VKF system.

    Parameters
    ----------
    run : RunFile
        An open canonical run file.
    settings : ProcessingSettings
    """
    groups: dict[float, list[str]] = {}
    for wheel in WHEELS:
        if run.has(f"Z{wheel}"):
            groups.setdefault(float(run.metadata.wheel_diameters[wheel]), []).append(wheel)
    return [(wheels, wheel_recipe(run.metadata, wheels[0], settings)) for wheels in groups.values()]


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
        Target chunk file (``.npz``, :mod:`app.pipeline.chunkfile`); written
        via a temporary file and ``os.replace``.
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
    members: dict[str, np.ndarray] = {}
    with open_run(run_path) as run:
        fs = run.fs
        lo, hi = chunk.lo, chunk.hi
        speed = run.speed(lo, hi)
        v_abs = np.abs(speed)
        min_v = settings.min_speed_kmh / KMH_PER_MPS
        position = run.position(lo, hi)
        v_max = max(float(v_abs.max()), 1.0)
        step = max(1, int(np.floor(fs * _OUTPUT_SPACING_M / v_max)))
        out_idx = np.arange(chunk.out_lo, chunk.out_hi, step)
        w_out = chunk.weight(out_idx)
        moving = v_abs[out_idx - lo] >= min_v
        # phases referred to the run start (the chunk's first sample is at position[0])
        start_m = float(position[0])
        psi = travel_phase(v_abs, fs, start_m)
        travelled = psi / (2.0 * np.pi)
        win = np.floor(position[out_idx - lo] / OOR_WINDOW_M).astype(np.int64)
        where = "the run" if (lo, hi) == (0, run.n_samples) else f"chunk {chunk.index}"

        def keep(idx: np.ndarray) -> np.ndarray:
            return (v_abs[idx - lo] >= min_v).astype(float)

        solved: dict[str, tuple[dict[str, BinSums], float, list[str]]] = {}
        tracks: dict[str, SleeperTrack] = {}

        for wheels, recipe in wheel_groups(run, settings):
            if should_cancel():
                raise PipelineCancelled(f"cancelled in chunk {chunk.index}")
            orders, order_rows, sleeper = recipe.wheel_orders, recipe.wheel_rows, recipe.sleeper_row
            harmonics = recipe.harmonics
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
            forces = [i for i, c in enumerate(channels) if c.startswith("Q")]
            if forces and settings.force_mean_window_m > 0:
                y[forces] = remove_static_load(y[forces], travelled, settings.force_mean_window_m,
                                               recipe.sleeper_spacing)
            notes = chunk_warnings(recipe, fs, v_abs, hi - lo, where)
            res = solve_logged(recipe, y, fs, v_abs, start_m, notes)
            env_all = res.envelope_at(out_idx - lo)  # (channels, s, m)
            del res
            for wheel in wheels:
                iz, iq = rows[wheel]
                env = env_all[iz]
                amp = np.abs(env)
                track_m = run.track_m(lo, hi, axle=wheel[0])

                def bins_of(idx: np.ndarray, track_m: np.ndarray = track_m) -> np.ndarray:
                    return position_to_bin(track_m[idx - lo], settings.bin_length_m)

                values = {"speed": v_abs[out_idx - lo], "sleeper_amp": amp[sleeper]}
                for h, row in harmonics.items():
                    if h > 1:
                        values[f"{harmonic_label(h)}_amp"] = amp[row]
                values["sleeper_rms"] = sleeper_rms(amp[list(harmonics.values())])
                for lvl, row in zip(orders, order_rows, strict=True):
                    values[f"order_amp_{lvl:02d}"] = amp[row]
                if iq is not None:
                    values["sleeper_force_amp"] = np.abs(env_all[iq, sleeper])
                sums = BinSums.from_samples(bins_of(out_idx), w_out * moving, values)
                resid, demod = _residual_sums(
                    y[iz], env, out_idx, psi, recipe, chunk, lo, bins_of, keep, should_cancel
                )
                tracks[wheel] = SleeperTrack(env[sleeper], demod, bins_of(out_idx), w_out * moving,
                                             float(recipe.bandwidth_per_speed[sleeper]),
                                             float(recipe.multipliers[sleeper]), recipe.filter_order,
                                             recipe_floor_gain(recipe))
                # isolated impacts: dips of the surface under the wheel (app.pipeline.impacts)
                members.update(chunk_dip_member(wheel, y[iz], travelled, v_abs, track_m, recipe,
                                                wheel_orders_at(env, out_idx, travelled, recipe, lo), chunk, lo,
                                                fs=fs))

                # wheel OOR: radius phasors of the wheel orders, summed per window
                rho = radius_phasor(env[order_rows], v_abs[out_idx - lo], recipe.wheel_diameter, orders)
                ok = moving & np.all(np.isfinite(rho), axis=0)
                oor_vals = {}
                for i, lvl in enumerate(orders):
                    oor_vals[f"re_{lvl:02d}"] = np.where(ok, rho[i].real, np.nan)
                    oor_vals[f"im_{lvl:02d}"] = np.where(ok, rho[i].imag, np.nan)
                    oor_vals[f"acc_{lvl:02d}"] = np.where(ok, amp[order_rows[i]], np.nan)
                oor = BinSums.from_samples(win, w_out * ok, oor_vals)
                solved[wheel] = ({"bins": sums, "resid": resid, "oor": oor}, recipe.wheel_diameter, notes)
        rough = rough_groups(tracks, v_abs[out_idx - lo], fs / step) if tracks else {}
        for wheel, (groups, diameter, notes) in solved.items():
            members.update(wheel_members(wheel, {**groups, "rough": rough[wheel]}, diameter, warnings=notes))
    write_chunk_file(out_path, chunk.index, members)
