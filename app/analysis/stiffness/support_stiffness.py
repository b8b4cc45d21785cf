"""Support stiffness (MN/m per rail seat) of a segment from its passes at several speeds.

The sleeper-passage amplitude is a wheel–track resonance swept by
``f_s = v / d_s`` (:mod:`app.analysis.stiffness.track_dynamics`); the
resonance moves up with the support stiffness ``k``. Given a segment's
amplitudes at several speeds, :func:`estimate_support_stiffness` finds the
``k`` whose model curve ``A(k, v)`` fits them best in ``ln A``:

* ``scale="free"`` (default): a free factor on the model (unknown wheel load,
  unsprung mass, sensor gain): only the *shape* against speed — where the
  resonance lies — tells ``k``;
* ``scale="absolute"``: the model's own amplitude (all other parameters known).

The interval is the set of grid stiffnesses whose residual sum of squares
stays within the profile-likelihood bound ``n ln(RSS / RSS_min) <= chi2_1(level)``.
Everything but ``k`` (rail, pads, sleeper, damping, wheel) is taken from
``params``: a wrong pad stiffness or damping biases the estimate (measured in
``docs/speed-conditioning.md``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.special import gammaincinv  # scipy.stats' chi2 without its import (≈ 1 s per process)

from app.analysis._checks import paired_1d
from app.analysis.stiffness.track_dynamics import TrackParameters, sleeper_passage_amplitude

__all__ = ["StiffnessEstimate", "model_log_amplitudes", "estimate_support_stiffness"]

#: Default grid of support stiffnesses, MN/m.
DEFAULT_K_GRID_MNM = np.geomspace(10.0, 1000.0, 161)


@dataclass(frozen=True)
class StiffnessEstimate:
    """The support stiffness that best explains a segment's amplitudes against speed.

    Attributes
    ----------
    k_mnm : float
        Best grid stiffness, MN/m.
    k_interval_mnm : tuple of float
        Lowest and highest grid stiffness within the likelihood bound, MN/m.
    log_scale : float
        Fitted ``ln`` of the factor on the model (0 with ``scale="absolute"``).
    rms_log_residual : float
        RMS of ``ln A - ln A_model`` at the best ``k``.
    n_speeds : int
        Passes used.
    at_grid_edge : bool
        The best ``k`` is the first or last of the grid (the data do not bound it).
    """

    k_mnm: float
    k_interval_mnm: tuple[float, float]
    log_scale: float
    rms_log_residual: float
    n_speeds: int
    at_grid_edge: bool


def model_log_amplitudes(params: TrackParameters, speed_mps: np.ndarray,
                         k_grid_mnm: np.ndarray = DEFAULT_K_GRID_MNM) -> np.ndarray:
    """``ln A(k, v)`` (m/s²) for every grid stiffness (rows) and speed (columns)."""
    v = np.asarray(speed_mps, dtype=np.float64)
    return np.array([np.log(sleeper_passage_amplitude(params.replace(ballast_stiffness=k * 1e6), v))
                     for k in np.asarray(k_grid_mnm, dtype=np.float64)])


def estimate_support_stiffness(
    speed_mps: np.ndarray,
    amplitude: np.ndarray,
    *,
    params: TrackParameters | None = None,
    scale: Literal["free", "absolute"] = "free",
    k_grid_mnm: np.ndarray = DEFAULT_K_GRID_MNM,
    level: float = 0.9,
    model: np.ndarray | None = None,
) -> StiffnessEstimate:
    """Fit ``k`` to a segment's sleeper-passage amplitudes (m/s²) at several speeds (m/s).

    Parameters
    ----------
    speed_mps, amplitude : numpy.ndarray
        One value per pass (> 0); at least 2 passes (3 with ``scale="free"``).
    params : TrackParameters, optional
        Everything but the support stiffness (default: the physics reference runs' track).
    scale : {"free", "absolute"}
        Fit a factor on the model or not (module docstring).
    k_grid_mnm : numpy.ndarray
        Candidate stiffnesses, MN/m, ascending.
    level : float
        Level of the interval.
    model : numpy.ndarray, optional
        :func:`model_log_amplitudes` of these speeds and grid, when already computed.
    """
    v, a = paired_1d(speed_mps, amplitude, "speed_mps, amplitude")
    if np.any(~(v > 0)) or np.any(~(a > 0)):
        raise ValueError("speed_mps, amplitude: must be > 0")
    if scale not in ("free", "absolute"):
        raise ValueError(f"scale: must be 'free' or 'absolute', got {scale!r}")
    need = 3 if scale == "free" else 2
    if v.size < need:
        raise ValueError(f"speed_mps: need at least {need} passes, got {v.size}")
    grid = np.asarray(k_grid_mnm, dtype=np.float64)
    if grid.ndim != 1 or grid.size < 3 or np.any(np.diff(grid) <= 0):
        raise ValueError("k_grid_mnm: must be 1-D, ascending, with at least 3 values")
    if not 0 < level < 1:
        raise ValueError(f"level: must be in (0, 1), got {level!r}")
    params = TrackParameters() if params is None else params
    m = model_log_amplitudes(params, v, grid) if model is None else np.asarray(model, dtype=np.float64)
    if m.shape != (grid.size, v.size):
        raise ValueError("model: must have the shape (len(k_grid_mnm), len(speed_mps))")
    r = np.log(a)[None, :] - m
    c = r.mean(axis=1) if scale == "free" else np.zeros(grid.size)
    rss = ((r - c[:, None]) ** 2).sum(axis=1)
    best = int(np.argmin(rss))
    bound = 2 * gammaincinv(0.5, level)  # the χ² (1 degree of freedom) quantile at level
    ok = v.size * np.log(np.maximum(rss, 1e-300) / max(rss[best], 1e-300)) <= bound
    inside = np.flatnonzero(ok)
    return StiffnessEstimate(
        k_mnm=float(grid[best]), k_interval_mnm=(float(grid[inside.min()]), float(grid[inside.max()])),
        log_scale=float(c[best]), rms_log_residual=float(np.sqrt(rss[best] / v.size)), n_speeds=int(v.size),
        at_grid_edge=best in (0, grid.size - 1),
    )
