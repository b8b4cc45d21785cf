"""The reference curve of one class: ``A_ref(class, v)`` fitted to block passes.

The 25 cm rows are reduced to block passes (:func:`block_samples`); the curve is the additive
model ``ln A = g_class(ln v) + m(location) + e`` fitted by backfitting with the robust local
regression of :mod:`~app.analysis.stiffness.reference_curve.smoother`, levelled so that the class's
median location has index 0, with a block-bootstrap band (:func:`fit_reference_curve`; the method
is :mod:`app.analysis.stiffness.reference_curve`'s docstring).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from app.analysis._checks import check_positive
from app.analysis.robust import mad_sd
from app.analysis.speed_match import DEFAULT_SPEED_TOLERANCE, log_speed_tolerance
from app.analysis.stiffness.reference_curve.smoother import (
    LocalFit,
    group_median,
    interp_nan,
    local_fit,
)

__all__ = ["BLOCK_M", "GROUP_BLOCKS", "BlockSamples", "ReferenceCurve", "block_samples", "fit_reference_curve"]

#: Block length the rows are reduced to before the fit, m.
BLOCK_M = 10.0
#: Locations per bootstrap group (20 blocks of 10 m = 200 m).
GROUP_BLOCKS = 20
#: Smallest spread of ``ln v`` within locations for the ``"within"`` method.
_MIN_WITHIN_LOG_SPEED_STD = 0.02
#: Fewest locations passed more than once for the ``"within"`` method.
_MIN_MULTI_LOCATIONS = 10
_MAX_BACKFIT = 60
#: Backfitting stops when the curve moves less than this (ln units).
_BACKFIT_TOL = 5e-4
#: Backfitting iterations of a bootstrap replicate (it starts from the fit).
_BOOT_ITER = 8


@dataclass(frozen=True)
class BlockSamples:
    """Block passes: one row per run, wheel and block (arrays of equal length).

    Attributes
    ----------
    log_amp : numpy.ndarray
        Median ``ln(A / 1 m/s²)`` of the block's bins.
    log_speed : numpy.ndarray
        Median ``ln(v / 1 m/s)``.
    location : numpy.ndarray
        Integer id of (rail, block).
    run : numpy.ndarray
        Run id.
    wheel : numpy.ndarray
        Wheel label (object).
    cls : numpy.ndarray
        Class label per block (object).
    block : numpy.ndarray
        Block index ``floor(x / block_m)`` (int64).
    rail : numpy.ndarray
        Rail side label (object).
    """

    log_amp: np.ndarray
    log_speed: np.ndarray
    location: np.ndarray
    run: np.ndarray
    wheel: np.ndarray
    cls: np.ndarray
    block: np.ndarray
    rail: np.ndarray

    def __len__(self) -> int:
        return int(self.log_amp.size)

    def take(self, mask: np.ndarray) -> BlockSamples:
        """The rows where ``mask`` holds."""
        return BlockSamples(**{k: getattr(self, k)[mask] for k in self.__dataclass_fields__})


def block_samples(
    amplitude: np.ndarray,
    speed_mps: np.ndarray,
    position_m: np.ndarray,
    run: np.ndarray,
    wheel: np.ndarray,
    rail: np.ndarray,
    cls: np.ndarray,
    *,
    block_m: float = BLOCK_M,
    bin_length_m: float = 0.25,
    min_fill: float = 0.5,
) -> BlockSamples:
    """Reduce 25 cm profile rows to block passes (median ``ln A`` and speed per run, wheel, block).

    Parameters
    ----------
    amplitude : numpy.ndarray
        Sleeper-passage amplitude per row, m/s² (rows with A <= 0, NaN or a
        speed <= 0 are left out).
    speed_mps : numpy.ndarray
        Speed per row, m/s.
    position_m : numpy.ndarray
        Bin centre on the km axis, m.
    run, wheel, rail : numpy.ndarray
        Run id, wheel and rail side of each row (a location is a block of one rail).
    cls : numpy.ndarray
        Class label per row (the block takes the label of its rows' majority;
        rows labelled None, e.g. near a change of superstructure, are left out).
    block_m : float
        Block length, m (default 10).
    bin_length_m : float
        Row length, m.
    min_fill : float
        Fraction of a block's bins a pass needs (default 0.5).
    """
    a = np.asarray(amplitude, dtype=np.float64)
    v = np.asarray(speed_mps, dtype=np.float64)
    x = np.asarray(position_m, dtype=np.float64)
    arrays = [np.asarray(c) for c in (run, wheel, rail, cls)]
    if not all(arr.shape == a.shape for arr in (v, x, *arrays)) or a.ndim != 1:
        raise ValueError("amplitude, speed_mps, position_m, run, wheel, rail, cls: must be 1-D of equal length")
    check_positive(block_m, "block_m")
    check_positive(bin_length_m, "bin_length_m")
    ok = np.isfinite(a) & (a > 0) & np.isfinite(v) & (v > 0) & np.isfinite(x)
    ok &= np.array([c is not None for c in arrays[3].tolist()], dtype=bool).reshape(a.shape)
    a, v, x = a[ok], v[ok], x[ok]
    run_a, wheel_a, rail_a, cls_a = (arr[ok] for arr in arrays)
    block = np.floor(x / block_m).astype(np.int64)
    run_u, run_i = np.unique(run_a, return_inverse=True)
    wheel_u, wheel_i = np.unique(wheel_a.astype(str), return_inverse=True)
    if block.size == 0:
        empty = np.zeros(0)
        obj = np.zeros(0, dtype=object)
        return BlockSamples(empty, empty, np.zeros(0, np.int64), np.zeros(0, run_u.dtype), obj, obj,
                            np.zeros(0, np.int64), obj)
    # one int64 key per (run, wheel, block): a 1-D unique is much faster than rows of a 2-D one
    b0 = block - block.min()
    nb, nw = int(b0.max()) + 1, wheel_u.size
    flat, inv, counts = np.unique((run_i.ravel() * nw + wheel_i.ravel()) * nb + b0, return_inverse=True,
                                  return_counts=True)
    inv = inv.ravel()
    n = flat.size
    uniq = np.stack([flat // (nw * nb), (flat // nb) % nw, flat % nb + block.min()], axis=1)
    la = group_median(np.log(a), inv, n)
    lv = group_median(np.log(v), inv, n)
    first = np.full(n, -1)
    first[inv[::-1]] = np.arange(inv.size)[::-1]
    cls_u, cls_i = np.unique(cls_a.astype(str), return_inverse=True)
    votes = np.zeros((n, cls_u.size))
    np.add.at(votes, (inv, cls_i.ravel()), 1.0)
    block_cls = cls_u[np.argmax(votes, axis=1)].astype(object)
    keep = counts >= min_fill * block_m / bin_length_m
    rail_b = rail_a[first].astype(str).astype(object)
    _, loc = np.unique(np.unique(rail_b, return_inverse=True)[1].ravel() * nb + (uniq[:, 2] - block.min()),
                       return_inverse=True)
    s = BlockSamples(la, lv, loc.ravel().astype(np.int64), run_u[uniq[:, 0]],
                     wheel_u[uniq[:, 1]].astype(object), block_cls, uniq[:, 2], rail_b)
    return s.take(keep)


@dataclass(frozen=True)
class ReferenceCurve:
    """``A_ref(class, v)``: the expected amplitude of a typical location of a class at speed ``v``.

    Attributes
    ----------
    cls : str
        Class label (superstructure type; ``""`` = the whole line or no section).
    log_speed : numpy.ndarray
        Nodes, ``ln(v / 1 m/s)`` (step ``h / 2``).
    log_amp : numpy.ndarray
        ``ln(A_ref / 1 m/s²)`` at the nodes (NaN without support).
    log_amp_se : numpy.ndarray
        Its standard error (bootstrap), ln units.
    log_amp_low, log_amp_high : numpy.ndarray
        The confidence band (bootstrap percentiles), ln units.
    support : numpy.ndarray
        Block passes within ``±h`` of each node (int).
    support_runs : numpy.ndarray
        Runs among them (int).
    speed_tolerance : float
        ``tol``: the matched-speed window is ``±ln(1 + tol)`` in ``ln v``.
    method : str
        ``"within"`` (locations passed at several speeds inform the shape) or ``"pooled"``.
    n_samples, n_locations, n_runs : int
        Block passes, locations and runs used.
    spread : float
        Robust standard deviation of the class's location effects (ln units):
        how much locations of the class differ from each other.
    repeatability : float
        Standard deviation of one 25 cm bin's ``ln A`` between passes (ln
        units; NaN when unknown): the bin's own uncertainty.
    confidence : float
        Level of the band.
    """

    cls: str
    log_speed: np.ndarray
    log_amp: np.ndarray
    log_amp_se: np.ndarray
    log_amp_low: np.ndarray
    log_amp_high: np.ndarray
    support: np.ndarray
    support_runs: np.ndarray
    speed_tolerance: float
    method: str
    n_samples: int
    n_locations: int
    n_runs: int
    spread: float
    repeatability: float = float("nan")
    confidence: float = 0.9

    @property
    def speed_range_mps(self) -> tuple[float, float]:
        """Lowest and highest speed with a reference, m/s (NaN, NaN if none)."""
        ok = np.isfinite(self.log_amp)
        if not ok.any():
            return (float("nan"), float("nan"))
        return (float(np.exp(self.log_speed[ok].min())), float(np.exp(self.log_speed[ok].max())))

    def evaluate(self, speed_mps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``ln A_ref`` and its standard error at speeds (m/s); NaN outside the supported speeds."""
        v = np.asarray(speed_mps, dtype=np.float64)
        u = np.log(np.where(v > 0, v, np.nan))
        return interp_nan(u, self.log_speed, self.log_amp), interp_nan(u, self.log_speed, self.log_amp_se)

    def with_repeatability(self, value: float) -> ReferenceCurve:
        """A copy with the bin repeatability set."""
        return ReferenceCurve(**{**self.__dict__, "repeatability": float(value)})

    def to_dict(self) -> dict[str, Any]:
        """JSON-able form (NaN → None)."""

        def lst(a: np.ndarray) -> list[float | None]:
            return [float(x) if math.isfinite(x) else None for x in np.asarray(a, dtype=np.float64).tolist()]

        def num(x: float) -> float | None:
            return float(x) if math.isfinite(x) else None

        return {
            "cls": self.cls, "log_speed": lst(self.log_speed), "log_amp": lst(self.log_amp),
            "log_amp_se": lst(self.log_amp_se), "log_amp_low": lst(self.log_amp_low),
            "log_amp_high": lst(self.log_amp_high), "support": [int(s) for s in self.support],
            "support_runs": [int(s) for s in self.support_runs], "speed_tolerance": self.speed_tolerance,
            "method": self.method, "n_samples": self.n_samples, "n_locations": self.n_locations,
            "n_runs": self.n_runs, "spread": num(self.spread), "repeatability": num(self.repeatability),
            "confidence": self.confidence,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> ReferenceCurve:
        """Inverse of :meth:`to_dict`."""

        def arr(k: str) -> np.ndarray:
            return np.array([np.nan if x is None else x for x in d[k]], dtype=np.float64)

        def num(k: str) -> float:
            return float("nan") if d.get(k) is None else float(d[k])

        return cls(
            cls=str(d["cls"]), log_speed=arr("log_speed"), log_amp=arr("log_amp"),
            log_amp_se=arr("log_amp_se"), log_amp_low=arr("log_amp_low"), log_amp_high=arr("log_amp_high"),
            support=np.asarray(d["support"], dtype=np.int64), support_runs=np.asarray(d["support_runs"], dtype=np.int64),
            speed_tolerance=float(d["speed_tolerance"]), method=str(d["method"]), n_samples=int(d["n_samples"]),
            n_locations=int(d["n_locations"]), n_runs=int(d["n_runs"]), spread=num("spread"),
            repeatability=num("repeatability"), confidence=float(d.get("confidence", 0.9)),
        )


@dataclass
class _Backfit:
    g_nodes: np.ndarray
    support: np.ndarray
    m: np.ndarray
    method: str


def _backfit(y: np.ndarray, u: np.ndarray, loc: np.ndarray, n_loc: int, nodes: np.ndarray, h: float,
             min_support: int, method: str, g_start: np.ndarray | None = None,
             max_iter: int = _MAX_BACKFIT) -> _Backfit:
    """``y = g(u) + m(loc)`` by backfitting (``"within"``: g from multi-pass locations only)."""
    counts = np.bincount(loc, minlength=n_loc)
    use = counts[loc] >= 2 if method == "within" else np.ones(y.size, dtype=bool)
    m = np.zeros(n_loc)
    g_nodes = g_start
    if method == "pooled":
        g_nodes, support = local_fit(u, y, nodes, h, min_support)
        g = interp_nan(u, nodes, g_nodes)
        m = group_median(y - g, loc, n_loc)
        return _Backfit(g_nodes, support, m, method)
    if g_nodes is not None:
        m = group_median(y - interp_nan(u, nodes, g_nodes), loc, n_loc)
    support = np.zeros(nodes.size, dtype=np.int64)
    smoother = LocalFit(u[use], nodes, h, min_support)  # the same speeds every iteration
    for _ in range(max_iter):
        r = y - np.nan_to_num(m[loc])
        g_new, support = smoother.fit(r[use])
        g = interp_nan(u, nodes, g_new)
        m_new = group_median(np.where(use, y - g, np.nan), loc, n_loc)
        m_new = np.where(np.isfinite(m_new), m_new, 0.0)
        shift = np.nanmedian(m_new[counts >= 2]) if (counts >= 2).any() else 0.0
        m_new -= shift
        done = g_nodes is not None and np.nanmax(np.abs(g_new - g_nodes), initial=0.0) < _BACKFIT_TOL
        g_nodes, m = g_new, m_new
        if done:
            break
    return _Backfit(g_nodes, support, m, method)


def _components(g: np.ndarray, u: np.ndarray, loc: np.ndarray, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Linked speed ranges of a curve: component id per node (-1 if NaN) and per sample.

    Contiguous runs of finite nodes are joined where a location has passes in both.
    """
    finite = np.isfinite(g)
    run_id = np.cumsum(np.r_[True, finite[1:] != finite[:-1]]) - 1
    node_comp = np.where(finite, run_id, -1)
    j = np.clip(np.searchsorted(nodes, u, side="right") - 1, 0, nodes.size - 1)
    j2 = np.clip(j + 1, 0, nodes.size - 1)
    sample_comp = np.where(node_comp[j] >= 0, node_comp[j], node_comp[j2])
    parent = {int(c): int(c) for c in np.unique(node_comp[node_comp >= 0])}

    def root(c: int) -> int:
        while parent[c] != c:
            parent[c] = parent[parent[c]]
            c = parent[c]
        return c

    ok = sample_comp >= 0
    # the distinct (location, component) pairs in lexicographic order, by one integer key
    n_comp = int(node_comp.max()) + 1 if node_comp.size else 0
    key = np.unique(loc[ok].astype(np.int64) * max(n_comp, 1) + sample_comp[ok])
    pairs = np.stack([key // max(n_comp, 1), key % max(n_comp, 1)], axis=1)
    for k in np.flatnonzero(pairs[1:, 0] == pairs[:-1, 0]):
        a, b = root(int(pairs[k, 1])), root(int(pairs[k + 1, 1]))
        if a != b:
            parent[max(a, b)] = min(a, b)
    # each component's root, looked up per node and sample (-1 stays -1)
    roots = np.full(n_comp + 1, -1, dtype=np.int64)
    for c in parent:
        roots[c] = root(c)
    return roots[node_comp], roots[sample_comp]


def _level(g: np.ndarray, y: np.ndarray, u: np.ndarray, loc: np.ndarray, n_loc: int,
           nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Shift the curve so that the median location of each linked speed range has index 0.

    Passes at several speeds tie the curve's level across speeds; speed ranges
    no location links are levelled separately (there the typical location is
    assumed to be alike, as in the pooled method). Returns the curve and the
    location effects.
    """
    g = g.copy()
    node_comp, sample_comp = _components(g, u, loc, nodes)
    resid = y - interp_nan(u, nodes, g)
    for c in np.unique(node_comp[node_comp >= 0]):
        sel = sample_comp == c
        level = np.nanmedian(group_median(resid[sel], loc[sel], n_loc))
        if np.isfinite(level):
            g[node_comp == c] += level
    m = group_median(y - interp_nan(u, nodes, g), loc, n_loc)
    return g, m


def _choose_method(u: np.ndarray, loc: np.ndarray, n_loc: int) -> str:
    counts = np.bincount(loc, minlength=n_loc)
    multi = counts[loc] >= 2
    if (counts >= 2).sum() < _MIN_MULTI_LOCATIONS:
        return "pooled"
    mean_u = np.bincount(loc, weights=u, minlength=n_loc) / np.maximum(counts, 1)
    dev = (u - mean_u[loc])[multi]
    return "within" if dev.std() >= _MIN_WITHIN_LOG_SPEED_STD else "pooled"


def fit_reference_curve(
    samples: BlockSamples,
    cls: str = "",
    *,
    speed_tolerance: float = DEFAULT_SPEED_TOLERANCE,
    min_support: int = 20,
    confidence: float = 0.9,
    n_boot: int = 40,
    seed: int = 0,
) -> ReferenceCurve:
    """Fit ``A_ref(cls, v)`` to the block passes of one class (module docstring).

    Parameters
    ----------
    samples : BlockSamples
        Block passes of the class (:func:`block_samples`, rows of other classes removed).
    cls : str
        The class label.
    speed_tolerance : float
        ``tol`` > 0: the local window and the matched-speed rule are
        ``±ln(1 + tol)`` in ``ln v`` (default 0.1 = ±10 %).
    min_support : int
        Block passes a node needs within the window (default 20 = 200 m of track).
    confidence : float
        Level of the band (default 0.9).
    n_boot : int
        Bootstrap replicates (default 40; 0 = no band).
    seed : int
        Seed of the bootstrap.
    """
    check_positive(speed_tolerance, "speed_tolerance")
    if not 0 < confidence < 1:
        raise ValueError(f"confidence: must be in (0, 1), got {confidence!r}")
    if int(min_support) != min_support or min_support < 3:
        raise ValueError(f"min_support: must be an integer >= 3, got {min_support!r}")
    y, u = samples.log_amp, samples.log_speed
    h = log_speed_tolerance(speed_tolerance)  # the window: the matched-speed rule
    _, loc = np.unique(samples.location, return_inverse=True)
    loc = loc.ravel()
    n_loc = int(loc.max()) + 1 if loc.size else 0
    nan_curve = np.zeros(0)
    if y.size < min_support:
        return ReferenceCurve(cls, nan_curve, nan_curve, nan_curve, nan_curve, nan_curve,
                              np.zeros(0, np.int64), np.zeros(0, np.int64), speed_tolerance, "none",
                              int(y.size), n_loc, int(np.unique(samples.run).size), float("nan"),
                              confidence=confidence)
    step = h / 2
    nodes = np.arange(math.floor(u.min() / step), math.ceil(u.max() / step) + 1) * step
    method = _choose_method(u, loc, n_loc)
    fit = _backfit(y, u, loc, n_loc, nodes, h, min_support, method)
    g = fit.g_nodes
    g, m = _level(g, y, u, loc, n_loc, nodes)
    spread = mad_sd(m)
    # support: passes and runs within the window of each node
    order = np.argsort(u, kind="stable")
    us, runs_sorted = u[order], samples.run[order]
    lo = np.searchsorted(us, nodes - h, side="left")
    hi = np.searchsorted(us, nodes + h, side="right")
    support = (hi - lo).astype(np.int64)
    run_ids = np.unique(runs_sorted, return_inverse=True)[1].ravel()
    support_runs = np.array([np.count_nonzero(np.bincount(run_ids[a:b])) for a, b in zip(lo, hi, strict=True)],
                            dtype=np.int64)
    se = np.full(nodes.size, np.nan)
    low = np.full(nodes.size, np.nan)
    high = np.full(nodes.size, np.nan)
    if n_boot > 0:
        rng = np.random.default_rng(seed)
        block_of_loc = np.zeros(n_loc, dtype=np.int64)
        block_of_loc[loc] = samples.block // GROUP_BLOCKS
        groups, group_of_loc = np.unique(block_of_loc, return_inverse=True)
        group_of_loc = group_of_loc.ravel()
        members = [np.flatnonzero(group_of_loc[loc] == k) for k in range(groups.size)]
        reps = []
        for _ in range(n_boot):
            pick = rng.integers(0, groups.size, groups.size)
            rows = np.concatenate([members[k] for k in pick]) if groups.size else np.zeros(0, np.int64)
            # resampled groups are new locations: offset their ids by draw number
            draw = np.repeat(np.arange(pick.size), [members[k].size for k in pick])
            bl = loc[rows] + draw * n_loc
            _, bl = np.unique(bl, return_inverse=True)
            bl = bl.ravel()
            nb = int(bl.max()) + 1 if bl.size else 0
            bf = _backfit(y[rows], u[rows], bl, nb, nodes, h, min_support, method, g_start=fit.g_nodes,
                          max_iter=_BOOT_ITER)
            reps.append(_level(bf.g_nodes, y[rows], u[rows], bl, nb, nodes)[0])
        rep = np.array(reps)
        finite = np.isfinite(rep).sum(axis=0) >= max(3, n_boot // 2)
        se = np.full(nodes.size, np.nan)
        se[finite] = np.nanstd(rep[:, finite], axis=0, ddof=1)
        # here: the settings name this module's constants (a light import)
        from scipy.special import ndtri

        with np.errstate(invalid="ignore"):
            alpha = (1 - confidence) / 2
            z = ndtri(1 - alpha)
            low = np.where(finite, g - z * se, np.nan)
            high = np.where(finite, g + z * se, np.nan)
    ok = np.isfinite(g) & (support >= min_support)
    g = np.where(ok, g, np.nan)
    return ReferenceCurve(
        cls=cls, log_speed=nodes, log_amp=g, log_amp_se=np.where(ok, se, np.nan),
        log_amp_low=np.where(ok, low, np.nan), log_amp_high=np.where(ok, high, np.nan),
        support=support, support_runs=support_runs, speed_tolerance=float(speed_tolerance), method=method,
        n_samples=int(y.size), n_locations=n_loc, n_runs=int(np.unique(samples.run).size), spread=spread,
        confidence=confidence,
    )
