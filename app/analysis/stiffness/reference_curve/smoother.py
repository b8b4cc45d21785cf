"""The robust smoother of the reference curves: a LOWESS in ``ln v`` on the medians of fine bins
(local quadratic, tricube kernel, bisquare robustness weights; a lower degree where a window's
speeds hardly vary), group medians, and an interpolation that never bridges a gap of support."""

from __future__ import annotations

import numpy as np

__all__ = ["group_median", "tricube", "local_fit", "interp_nan"]

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
    """
    fit = np.full(nodes.size, np.nan)
    keep = np.isfinite(u) & np.isfinite(r)
    u, r = u[keep], r[keep]
    if u.size == 0:
        return fit, np.zeros(nodes.size, dtype=np.int64)
    fine = np.floor(u / (h / _FINE_BINS_PER_H)).astype(np.int64)
    fb, fi, fc = np.unique(fine, return_inverse=True, return_counts=True)
    fi = fi.ravel()
    ub = np.bincount(fi, weights=u) / fc  # fine bins in ascending u
    rb = group_median(r, fi, fb.size)
    cum = np.r_[0, np.cumsum(fc)]
    lo = np.searchsorted(ub, nodes - h, side="left")
    mid = np.searchsorted(ub, nodes, side="left")
    hi = np.searchsorted(ub, nodes + h, side="right")
    support = cum[hi] - cum[lo]
    below = np.abs(nodes - ub[np.clip(mid - 1, 0, ub.size - 1)])
    above = np.abs(ub[np.clip(mid, 0, ub.size - 1)] - nodes)
    near = np.minimum(below, above) <= h / 2
    live = np.flatnonzero((support >= min_support) & near)
    if live.size == 0:
        return fit, support
    width = int((hi[live] - lo[live]).max())
    idx = lo[live, None] + np.arange(width)[None, :]
    inside = idx < hi[live, None]
    idx = np.minimum(idx, ub.size - 1)
    du = np.where(inside, (ub[idx] - nodes[live, None]) / h, 0.0)
    yy = np.where(inside, rb[idx], 0.0)
    w0 = np.where(inside, tricube(du) * fc[idx], 0.0)
    # the degree the window's speeds can carry: quadratic, linear, or a weighted mean
    sw0 = np.maximum(w0.sum(axis=1), 1e-300)
    spread = np.sqrt((w0 * (du - ((w0 * du).sum(axis=1) / sw0)[:, None]) ** 2).sum(axis=1) / sw0)
    use_lin = (spread >= _MIN_LINEAR_SPREAD)[:, None]
    use_quad = (spread >= _MIN_QUADRATIC_SPREAD)[:, None]
    basis = np.stack([np.ones_like(du), du * use_lin, du * du * use_quad], axis=-1)  # (nodes, window, 3)
    w = w0
    n_in = (hi - lo)[live]
    rows = np.arange(live.size)
    coef = np.zeros((live.size, 3))
    for it in range(robust_iter + 1):
        xtwx = np.einsum("nwi,nw,nwj->nij", basis, w, basis)
        # a small ridge keeps windows with fewer than three distinct speeds solvable
        xtwx = xtwx + (1e-6 * np.trace(xtwx, axis1=1, axis2=2) + 1e-12)[:, None, None] * np.eye(3)
        xtwy = np.einsum("nwi,nw,nw->ni", basis, w, yy)
        coef = np.linalg.solve(xtwx, xtwy[..., None])[..., 0]
        if it == robust_iter:
            break
        res = yy - np.einsum("nwi,ni->nw", basis, coef)
        srt = np.sort(np.where(inside, np.abs(res), np.inf), axis=1)
        scale = 0.5 * (srt[rows, (n_in - 1) // 2] + srt[rows, n_in // 2])
        scale = np.where(scale > 0, scale, np.inf)
        w = w0 * np.clip(1.0 - (res / (6.0 * scale[:, None])) ** 2, 0.0, None) ** 2
    fit[live] = coef[:, 0]
    return fit, support


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
