"""Odometry fused with map-matched GNSS: the line chainage of every odometry value.

Odometry ``s`` (m travelled, smooth, exact over short distances but drifting:
wheel diameter error, slip) and GNSS fixes matched onto the line geometry
(chainage ``c_i`` at odometry ``s_i``; metres of noise, occasional multipath
outliers, outages in cuttings and tunnels) are combined into one monotonic map
``c(s)``::

    c(s) = a + b s + d(s)

* ``a + b s`` — the line through the fixes (robust: Tukey-weighted least
  squares); ``sign(b)`` is the km direction, ``|b|`` the odometry scale
  (checked against ``max_scale_error``).
* ``d(s)`` — a piecewise-linear correction on knots every ``knot_spacing_m``
  of odometry, fitted as a P-spline (penalised second differences) with the
  same robust weights, iterated (IRLS) so that outliers get weight 0. The
  penalty is set from ``smoothing_m``: drifts with wavelengths much longer
  than it are followed, GNSS noise at shorter wavelengths is averaged away
  (half-power wavelength ``smoothing_m``). Where no fix exists (an outage)
  the penalty makes ``d`` a straight line between the fixes on either side:
  the outage is bridged by the odometry with the scale estimated around it.

Pure numpy/scipy: no geometry library, no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import solveh_banded

from app.analysis.robust import mad_sd

__all__ = ["FusionSettings", "OdometryFusion", "fuse_odometry_gnss"]

_TUKEY_C = 4.685


@dataclass(frozen=True)
class FusionSettings:
    """Parameters of :func:`fuse_odometry_gnss`.

    Attributes
    ----------
    knot_spacing_m : float
        Odometry distance between the knots of the correction, m (default 25).
    smoothing_m : float
        Half-power wavelength of the correction, m (default 2000): shorter
        GNSS errors are averaged away, longer odometry drifts followed.
    min_fixes : int
        Fewest usable fixes (default 20).
    max_scale_error : float
        Largest accepted ``| |b| - 1 |`` of the odometry scale (default 0.05).
    noise_floor_m : float
        Smallest robust scale of the residuals used for the weights, m
        (default 0.5: keeps perfect data from rejecting everything).
    outage_s : float
        A gap between fixes longer than this is reported as an outage, s (default 5).
    iterations : int
        Robust reweighting passes (default 8).
    """

    knot_spacing_m: float = 25.0
    smoothing_m: float = 2000.0
    min_fixes: int = 20
    max_scale_error: float = 0.05
    noise_floor_m: float = 0.5
    outage_s: float = 5.0
    iterations: int = 8

    def __post_init__(self) -> None:
        for name in ("knot_spacing_m", "smoothing_m", "noise_floor_m", "outage_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
        if not 0 < self.max_scale_error < 1:
            raise ValueError(f"max_scale_error must be in (0, 1), got {self.max_scale_error!r}")
        if int(self.min_fixes) != self.min_fixes or self.min_fixes < 3:
            raise ValueError(f"min_fixes must be an integer >= 3, got {self.min_fixes!r}")
        if int(self.iterations) != self.iterations or self.iterations < 1:
            raise ValueError(f"iterations must be an integer >= 1, got {self.iterations!r}")


@dataclass(frozen=True)
class OdometryFusion:
    """The fused map odometry → chainage.

    Attributes
    ----------
    knots_odo_m : numpy.ndarray
        Odometry of the knots, m (increasing).
    knots_chainage_m : numpy.ndarray
        Chainage (line km × 1000) at the knots, m; monotonic in the km direction.
    direction : int
        +1 if the chainage increases with the odometry, else -1.
    scale : float
        ``|b|``: line metres per odometry metre of the straight fit.
    n_fixes, n_used : int
        Fixes given; fixes with non-zero final weight.
    residual_rms_m : float
        RMS of the used fixes about ``c(s)``, m.
    outages : list of tuple
        ``(t_from, t_to)`` (s) of the gaps between fixes longer than
        ``outage_s`` (when times are given).
    """

    knots_odo_m: np.ndarray
    knots_chainage_m: np.ndarray
    direction: int
    scale: float
    n_fixes: int
    n_used: int
    residual_rms_m: float
    outages: list[tuple[float, float]] = field(default_factory=list)

    def chainage(self, odo_m: np.ndarray) -> np.ndarray:
        """Chainage (m) at odometry values (m); linear beyond the knots."""
        s = np.asarray(odo_m, dtype=np.float64)
        k, c = self.knots_odo_m, self.knots_chainage_m
        out = np.interp(s, k, c)
        slope = self.direction * self.scale
        lo, hi = s < k[0], s > k[-1]
        out[lo] = c[0] + slope * (s[lo] - k[0])
        out[hi] = c[-1] + slope * (s[hi] - k[-1])
        return out

    def summary(self) -> dict[str, object]:
        """JSON form kept with the run."""
        return {
            "direction": self.direction,
            "scale": self.scale,
            "n_fixes": self.n_fixes,
            "n_used": self.n_used,
            "residual_rms_m": self.residual_rms_m,
            "outages_s": [[round(a, 3), round(b, 3)] for a, b in self.outages],
        }


def _tukey(u: np.ndarray) -> np.ndarray:
    w = np.zeros_like(u)
    inside = np.abs(u) < 1.0
    w[inside] = (1.0 - u[inside] ** 2) ** 2
    return w


def _robust_scale(e: np.ndarray, w: np.ndarray, floor: float) -> float:
    used = e[w > 0]
    if used.size == 0:
        return floor
    return max(mad_sd(used), floor)


def _line_fit(s: np.ndarray, c: np.ndarray, settings: FusionSettings) -> tuple[float, float, np.ndarray]:
    w = np.ones_like(s)
    a = b = 0.0
    for _ in range(settings.iterations):
        sw = w.sum()
        sm = (w * s).sum() / sw
        cm = (w * c).sum() / sw
        var = (w * (s - sm) ** 2).sum()
        if var <= 0:
            raise ValueError("the fixes span no odometry distance (the vehicle did not move)")
        b = float((w * (s - sm) * (c - cm)).sum() / var)
        a = float(cm - b * sm)
        e = c - (a + b * s)
        w = _tukey(e / (_TUKEY_C * _robust_scale(e, w, settings.noise_floor_m)))
        if w.sum() < settings.min_fixes:
            raise ValueError("too few fixes agree with each other")
    return a, b, w


def _hat_basis(s: np.ndarray, knots: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Knot index ``j`` and weight ``1 - f`` of knot ``j`` (``f`` of knot ``j + 1``)."""
    u = (s - knots[0]) / spacing
    j = np.clip(np.floor(u).astype(np.int64), 0, knots.size - 2)
    f = u - j
    return j, f


def _pspline(
    j: np.ndarray, f: np.ndarray, r: np.ndarray, w: np.ndarray, n_knots: int, lam: float
) -> np.ndarray:
    """Solve ``(Bᵀ W B + λ Dᵀ D) α = Bᵀ W r`` (upper banded form, two super-diagonals)."""
    ab = np.zeros((3, n_knots))
    rhs = np.zeros(n_knots)
    g0, g1 = 1.0 - f, f
    np.add.at(ab[2], j, w * g0 * g0)
    np.add.at(ab[2], j + 1, w * g1 * g1)
    np.add.at(ab[1], j + 1, w * g0 * g1)
    np.add.at(rhs, j, w * g0 * r)
    np.add.at(rhs, j + 1, w * g1 * r)
    if n_knots >= 3:  # λ Dᵀ D, D the second differences: rows (1, -2, 1)
        rows = np.arange(n_knots - 2)
        np.add.at(ab[2], rows, lam)
        np.add.at(ab[2], rows + 1, 4.0 * lam)
        np.add.at(ab[2], rows + 2, lam)
        np.add.at(ab[1], rows + 1, -2.0 * lam)
        np.add.at(ab[1], rows + 2, -2.0 * lam)
        np.add.at(ab[0], rows + 2, lam)
    ab[2] += 1e-9 * max(float(ab[2].max()), 1.0)  # no data and no penalty: keep it solvable
    return solveh_banded(ab, rhs)


def fuse_odometry_gnss(
    odo_m: np.ndarray,
    chainage_m: np.ndarray,
    *,
    t_s: np.ndarray | None = None,
    odo_range_m: tuple[float, float] | None = None,
    settings: FusionSettings | None = None,
) -> OdometryFusion:
    """Fuse odometry with map-matched GNSS fixes.

    Parameters
    ----------
    odo_m : array_like
        Odometry at the fixes, m (non-decreasing along the run).
    chainage_m : array_like
        Matched chainage of the fixes, m (line km × 1000).
    t_s : array_like, optional
        Times of the fixes, s (for the outage report).
    odo_range_m : (float, float), optional
        Odometry range the result must cover (default: that of the fixes).
    settings : FusionSettings, optional
        Parameters.

    Returns
    -------
    OdometryFusion

    Raises
    ------
    ValueError
        Fewer than ``min_fixes`` usable fixes, no odometry distance, or an
        odometry scale off by more than ``max_scale_error``.
    """
    cfg = settings or FusionSettings()
    s = np.asarray(odo_m, dtype=np.float64)
    c = np.asarray(chainage_m, dtype=np.float64)
    if s.ndim != 1 or s.shape != c.shape:
        raise ValueError("odo_m and chainage_m must be 1-D arrays of equal length")
    ok = np.isfinite(s) & np.isfinite(c)
    s, c = s[ok], c[ok]
    times = None if t_s is None else np.asarray(t_s, dtype=np.float64)[ok]
    if s.size < cfg.min_fixes:
        raise ValueError(f"{s.size} usable GNSS fixes; at least {cfg.min_fixes} are needed")
    a, b, w = _line_fit(s, c, cfg)
    if abs(abs(b) - 1.0) > cfg.max_scale_error:
        raise ValueError(
            f"odometry and GNSS disagree: {abs(b):.4f} line metres per odometry metre "
            f"(accepted 1 ± {cfg.max_scale_error:g}); check the odometry unit and the line geometry"
        )
    lo = float(s.min()) if odo_range_m is None else min(float(odo_range_m[0]), float(s.min()))
    hi = float(s.max()) if odo_range_m is None else max(float(odo_range_m[1]), float(s.max()))
    step = cfg.knot_spacing_m
    n_knots = max(int(math.ceil((hi - lo) / step)) + 1, 2)
    knots = lo + step * np.arange(n_knots)
    j, f = _hat_basis(s, knots, step)
    r = c - (a + b * s)
    per_knot = np.bincount(j, minlength=n_knots - 1)
    density = float(np.median(per_knot[per_knot > 0]))
    lam = density * (cfg.smoothing_m / (2.0 * math.pi * step)) ** 4
    alpha = np.zeros(n_knots)
    for _ in range(cfg.iterations):
        alpha = _pspline(j, f, r, w, n_knots, lam)
        e = r - (alpha[j] * (1.0 - f) + alpha[j + 1] * f)
        w = _tukey(e / (_TUKEY_C * _robust_scale(e, w, cfg.noise_floor_m)))
        if w.sum() < cfg.min_fixes:
            raise ValueError("too few GNSS fixes agree with the odometry")
    direction = 1 if b > 0 else -1
    chain = a + b * knots + alpha
    chain = direction * np.maximum.accumulate(direction * chain)
    e = r - (alpha[j] * (1.0 - f) + alpha[j + 1] * f)
    used = w > 0
    outages: list[tuple[float, float]] = []
    if times is not None and times.size > 1:
        gaps = np.flatnonzero(np.diff(times) > cfg.outage_s)
        outages = [(float(times[g]), float(times[g + 1])) for g in gaps]
    return OdometryFusion(
        knots_odo_m=knots,
        knots_chainage_m=chain,
        direction=direction,
        scale=abs(b),
        n_fixes=int(ok.sum()),
        n_used=int(used.sum()),
        residual_rms_m=float(np.sqrt(np.mean(e[used] ** 2))) if used.any() else float("nan"),
        outages=outages,
    )
