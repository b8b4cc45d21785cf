"""The robust smoother of the reference curves: a LOWESS in ``ln v`` on the medians of fine bins
(local quadratic, tricube kernel, bisquare robustness weights; a lower degree where a window's
speeds hardly vary), group medians, and an interpolation that never bridges a gap of support."""

from __future__ import annotations

import numpy as np

__all__ = ["group_median", "tricube", "local_fit", "LocalFit", "interp_nan"]

#: Weighted standard deviation of ``ln v`` in a window (units of ``h``) for a local
#: linear and for a local quadratic term (fewer distinct speeds: a lower degree).
_MIN_LINEAR_SPREAD = 0.05
_MIN_QUADRATIC_SPREAD = 0.25
#: Fine bins of ln v per window half-width h (the local fit works on their medians).
_FINE_BINS_PER_H = 10


def group_median(values: np.ndarray, groups: np.ndarray, n_groups: int) -> np.ndarray:
    """Median of the finite ``values`` per integer group id (NaN for groups without any)."""
    out = np.full(n_groups, np.nan)
    finite = np.isfinite(values)
    values, groups = values[finite], groups[finite]
    if values.size == 0:
        return out
    # sort by (group, value) with one integer key: group · n + rank of the value (the ranks are
    # distinct, so the order is the lexicographic one; ~3x faster than a two-key lexsort)
    by_value = np.argsort(values)
    rank = np.empty(by_value.size, dtype=np.int64)
    rank[by_value] = np.arange(by_value.size)
    order = np.argsort(groups.astype(np.int64, copy=False) * by_value.size + rank)
    g, v = groups[order], values[order]
    starts = np.flatnonzero(np.r_[True, g[1:] != g[:-1]])
    counts = np.diff(np.r_[starts, g.size])
    lo = starts + (counts - 1) // 2
    hi = starts + counts // 2
    out[g[starts]] = 0.5 * (v[lo] + v[hi])
    return out


def tricube(d: np.ndarray) -> np.ndarray:
    """The tricube kernel ``(1 − |d|³)³`` (0 beyond ``|d| = 1``)."""
    return np.clip(1.0 - np.abs(d) ** 3, 0.0, None) ** 3


def local_fit(u: np.ndarray, r: np.ndarray, nodes: np.ndarray, h: float, min_support: int,
              robust_iter: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Robust local-quadratic fit (LOWESS) of ``r`` on ``u`` at ``nodes``; NaN where support is short.

    The samples are first reduced to the medians of fine bins of ``u``
    (``h / 10`` wide) weighted by their counts, so the cost hardly grows with
    the number of samples; windows whose speeds hardly vary (a plateau) get a
    local-linear or constant fit. A node needs ``min_support`` samples within
    ``±h`` and one within ``±h/2`` (the fit never reaches further than ``h/2``
    beyond the data, e.g. above the highest speed of a class). Returns the fit
    and the support (samples within ``±h``) per node.

    :class:`LocalFit` is the same fit with the windows of ``u`` prepared once, for several ``r``
    on the same speeds (the backfitting's iterations).
    """
    keep = np.isfinite(u) & np.isfinite(r)
    return LocalFit(u[keep], nodes, h, min_support).fit(r[keep], robust_iter)


class LocalFit:
    """:func:`local_fit` at ``nodes`` on the speeds ``u``, whatever is fitted on them.

    Everything that depends only on ``u`` (the fine bins, each node's window, support, kernel
    weights and degree, and the first normal equations) is computed here once; :meth:`fit` adds
    the values. ``fit(r)`` equals ``local_fit(u, r, nodes, h, min_support)``, bit for bit.

    Parameters
    ----------
    u : numpy.ndarray
        ``ln v`` of the samples (non-finite ones are left out).
    nodes : numpy.ndarray
        Where the curve is fitted (ascending).
    h : float
        Window half-width (ln units).
    min_support : int
        Samples a node needs within ``±h``.
    """

    def __init__(self, u: np.ndarray, nodes: np.ndarray, h: float, min_support: int) -> None:
        self.u_all = np.asarray(u, dtype=np.float64)
        self.keep = np.isfinite(self.u_all)
        self.nodes, self.h, self.min_support = nodes, h, min_support
        u = self.u_all[self.keep]
        self.n = u.size
        self.support = np.zeros(nodes.size, dtype=np.int64)
        self.live = np.zeros(0, dtype=np.int64)
        if u.size == 0:
            return
        fine = np.floor(u / (h / _FINE_BINS_PER_H)).astype(np.int64)
        fb, fi, fc = np.unique(fine, return_inverse=True, return_counts=True)
        self.fi, self.n_fine = fi.ravel(), fb.size
        ub = np.bincount(self.fi, weights=u) / fc  # fine bins in ascending u
        cum = np.r_[0, np.cumsum(fc)]
        lo = np.searchsorted(ub, nodes - h, side="left")
        mid = np.searchsorted(ub, nodes, side="left")
        hi = np.searchsorted(ub, nodes + h, side="right")
        self.support = cum[hi] - cum[lo]
        below = np.abs(nodes - ub[np.clip(mid - 1, 0, ub.size - 1)])
        above = np.abs(ub[np.clip(mid, 0, ub.size - 1)] - nodes)
        near = np.minimum(below, above) <= h / 2
        live = np.flatnonzero((self.support >= min_support) & near)
        self.live = live
        if live.size == 0:
            return
        width = int((hi[live] - lo[live]).max())
        idx = lo[live, None] + np.arange(width)[None, :]
        self.inside = idx < hi[live, None]
        self.idx = np.minimum(idx, ub.size - 1)
        du = np.where(self.inside, (ub[self.idx] - nodes[live, None]) / h, 0.0)
        self.w0 = np.where(self.inside, tricube(du) * fc[self.idx], 0.0)
        # the degree the window's speeds can carry: quadratic, linear, or a weighted mean
        sw0 = np.maximum(self.w0.sum(axis=1), 1e-300)
        spread = np.sqrt((self.w0 * (du - ((self.w0 * du).sum(axis=1) / sw0)[:, None]) ** 2).sum(axis=1) / sw0)
        use_lin = (spread >= _MIN_LINEAR_SPREAD)[:, None]
        use_quad = (spread >= _MIN_QUADRATIC_SPREAD)[:, None]
        self.basis = np.stack([np.ones_like(du), du * use_lin, du * du * use_quad], axis=-1)  # (nodes, window, 3)
        self.n_in = (hi - lo)[live]
        self.xtwx0 = self._normal(self.w0)

    def _normal(self, w: np.ndarray) -> np.ndarray:
        xtwx = np.einsum("nwi,nw,nwj->nij", self.basis, w, self.basis)
        # a small ridge keeps windows with fewer than three distinct speeds solvable
        return xtwx + (1e-6 * np.trace(xtwx, axis1=1, axis2=2) + 1e-12)[:, None, None] * np.eye(3)

    def fit(self, r: np.ndarray, robust_iter: int = 2) -> tuple[np.ndarray, np.ndarray]:
        """The fit of ``r`` (one value per sample of ``u``) at the nodes and the support per node.

        Samples whose ``r`` is not finite are left out (the windows are then prepared anew).
        """
        r = np.asarray(r, dtype=np.float64)[self.keep]
        if not np.isfinite(r).all():
            ok = np.isfinite(r)
            return LocalFit(self.u_all[self.keep][ok], self.nodes, self.h, self.min_support).fit(r[ok], robust_iter)
        fit = np.full(self.nodes.size, np.nan)
        if self.n == 0:
            return fit, np.zeros(self.nodes.size, dtype=np.int64)
        if self.live.size == 0:
            return fit, self.support.copy()
        rb = group_median(r, self.fi, self.n_fine)
        inside, basis, w0, n_in = self.inside, self.basis, self.w0, self.n_in
        yy = np.where(inside, rb[self.idx], 0.0)
        w = w0
        rows = np.arange(self.live.size)
        coef = np.zeros((self.live.size, 3))
        for it in range(robust_iter + 1):
            xtwx = self.xtwx0 if it == 0 else self._normal(w)
            xtwy = np.einsum("nwi,nw,nw->ni", basis, w, yy)
            coef = np.linalg.solve(xtwx, xtwy[..., None])[..., 0]
            if it == robust_iter:
                break
            res = yy - np.einsum("nwi,ni->nw", basis, coef)
            srt = np.sort(np.where(inside, np.abs(res), np.inf), axis=1)
            scale = 0.5 * (srt[rows, (n_in - 1) // 2] + srt[rows, n_in // 2])
            scale = np.where(scale > 0, scale, np.inf)
            w = w0 * np.clip(1.0 - (res / (6.0 * scale[:, None])) ** 2, 0.0, None) ** 2
        fit[self.live] = coef[:, 0]
        return fit, self.support.copy()


def interp_nan(x: np.ndarray, xp: np.ndarray, fp: np.ndarray) -> np.ndarray:
    """Linear interpolation of ``fp`` at ``x`` (``xp`` ascending); NaN outside ``xp`` and wherever
    a bracketing node is NaN (a gap of support is never bridged)."""
    x = np.asarray(x, dtype=np.float64)
    out = np.full(x.shape, np.nan)
    if xp.size == 0:
        return out
    j = np.clip(np.searchsorted(xp, x, side="right") - 1, 0, max(xp.size - 2, 0))
    inside = (x >= xp[0]) & (x <= xp[-1])
    if xp.size == 1:
        out[inside] = fp[0]
        return out
    x0, x1 = xp[j], xp[j + 1]
    t = np.clip((x - x0) / (x1 - x0), 0.0, 1.0)
    f0, f1 = fp[j], fp[j + 1]
    val = np.where(t == 0.0, f0, np.where(t == 1.0, f1, f0 + t * (f1 - f0)))
    out[inside] = val[inside]
    return out
