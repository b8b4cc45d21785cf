"""Per-bin sums of a chunk for the roughness-corrected sleeper amplitude (issue 26).

:func:`process_chunk` hands every wheel's sleeper-order envelope and its
demodulated residual (:class:`SleeperTrack`) to :func:`rough_groups`, which
writes one more group of additive per-bin sums per wheel, ``rough``:

* ``pow``: ``|E|²`` of the sleeper order, (m/s²)²;
* ``re``, ``im``: the envelope ``E`` itself, m/s²;
* ``floor_lo``, ``floor_hi``: the floor from the side band below and above the order
  (:func:`app.analysis.roughness.sideband_floor`), (m/s²)²;
* ``res_m``: the sleeper order's spatial resolution (10–90 % step width) the recipe solved it with, m
  (constant: assembly reads the along-track correlation from the recipe that made the sums);
* for the wheels of an axle whose both wheels are measured (:data:`AXLE_PAIRS`):
  ``cross_re``, ``cross_im`` = ``E · conj(E_other)`` and ``pow_other`` = ``|E_other|²``.

Assembly (:func:`app.pipeline.assemble.assemble_wheel`) turns them into
``sleeper_amp`` and ``sleeper_amp_sd`` (:mod:`app.analysis.roughness`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from app.analysis.binning import BinSums
from app.analysis.recipe import OrderRecipe
from app.analysis.roughness import floor_gain, sideband_floor
from app.analysis.uncertainty import STEP_WIDTH_FACTORS

__all__ = ["AXLE_PAIRS", "SleeperTrack", "recipe_floor_gain", "rough_groups"]

#: the two wheels of an axle (right, left): same sleepers, different rails
AXLE_PAIRS: tuple[tuple[str, str], ...] = (("11", "12"), ("41", "42"))


@dataclass(frozen=True)
class SleeperTrack:
    """One wheel's sleeper order over a chunk's output grid.

    Attributes
    ----------
    envelope : ndarray, complex, shape (m,)
        Sleeper-order envelope (peak phasor, phase referred to the run start), m/s².
    demod : ndarray, complex, shape (m,)
        Residual mixed down by the sleeper phase, averaged per grid interval, m/s².
    bins : ndarray of int, shape (m,)
        Profile bin of every grid point (the wheel's axle's track position).
    weight : ndarray, shape (m,)
        Crossfade weight × "moving" of every grid point.
    bandwidth_per_speed : float
        The sleeper order's bandwidth per unit speed, Hz per m/s.
    multiplier : float
        The sleeper order's frequency per unit speed (1/d_s), Hz per m/s.
    gain : float
        :func:`app.analysis.roughness.floor_gain` of the wheel's recipe.
    filter_order : int
        q of the VKF.
    """

    envelope: np.ndarray
    demod: np.ndarray
    bins: np.ndarray
    weight: np.ndarray
    bandwidth_per_speed: float
    multiplier: float
    filter_order: int
    gain: float


def recipe_floor_gain(recipe: OrderRecipe) -> float:
    """:func:`app.analysis.roughness.floor_gain` of a wheel's recipe: every tracked order notches the
    residual, except the stationary ones (:attr:`OrderRecipe.stationary`: fitted as functions of
    frequency over the stretch, they take no broadband content)."""
    keep = ~np.asarray(recipe.stationary, dtype=bool)
    rows = np.flatnonzero(keep)
    return floor_gain(recipe.filter_order, multipliers=recipe.multipliers[keep],
                      bandwidths=recipe.bandwidth_per_speed[keep],
                      sleeper_row=int(np.flatnonzero(rows == recipe.sleeper_row)[0]))


def rough_groups(tracks: Mapping[str, SleeperTrack], speed: np.ndarray, grid_rate: float) -> dict[str, BinSums]:
    """The ``rough`` group of every wheel of a chunk.

    Parameters
    ----------
    tracks : mapping of wheel to SleeperTrack
        Every wheel solved in the chunk, on one output grid.
    speed : ndarray, shape (m,)
        Absolute speed at the grid points, m/s.
    grid_rate : float
        Rate of the output grid, Hz.

    Returns
    -------
    dict of wheel to BinSums
    """
    values: dict[str, dict[str, np.ndarray]] = {}
    for wheel, tr in tracks.items():
        e = tr.envelope
        lo, hi = sideband_floor(tr.demod, grid_rate, speed, tr.bandwidth_per_speed, tr.multiplier,
                                tr.filter_order, gain=tr.gain)
        res_m = STEP_WIDTH_FACTORS[int(tr.filter_order)] / float(tr.bandwidth_per_speed)
        values[wheel] = {"pow": np.abs(e) ** 2, "re": e.real, "im": e.imag, "floor_lo": lo, "floor_hi": hi,
                         "res_m": np.full(e.size, res_m)}
    for a, b in AXLE_PAIRS:
        if a in tracks and b in tracks:
            for me, other in ((a, b), (b, a)):
                prod = tracks[me].envelope * np.conj(tracks[other].envelope)
                values[me].update({"cross_re": prod.real, "cross_im": prod.imag,
                                   "pow_other": np.abs(tracks[other].envelope) ** 2})
    return {wheel: BinSums.from_samples(tracks[wheel].bins, tracks[wheel].weight, vals)
            for wheel, vals in values.items()}
