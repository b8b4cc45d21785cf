"""Map matching: points in a local metric plane onto a polyline with km stations.

A railway line (one track) is a polyline of vertices ``(x, y)`` (m, in a local
metric projection) with the line chainage ``c`` (m, line km × 1000) at every
vertex, strictly increasing or strictly decreasing along the polyline; between
two vertices the chainage is linear in the distance along the segment (so km
jumps and shortened kilometres live in the stations, not the geometry). A
point is matched to the nearest point of the polyline (exactly: candidate
segments are found with a k-d tree over points spaced at most
``sample_step_m`` along the polyline) and gets that point's chainage and its
signed distance from the line (positive to the left of the km direction).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # scipy.spatial loads with the first polyline, not with every API process
    from scipy.spatial import cKDTree

__all__ = ["Polyline", "MatchResult", "match_points"]


@dataclass(frozen=True)
class Polyline:
    """A line geometry with chainage stations.

    Parameters
    ----------
    x, y : numpy.ndarray
        Vertex coordinates, m (local metric projection), at least two vertices,
        no two consecutive vertices equal.
    chainage_m : numpy.ndarray
        Line km × 1000 at every vertex, m; strictly monotonic.
    sample_step_m : float
        Spacing of the k-d tree points along the polyline, m (default 10).
    """

    x: np.ndarray
    y: np.ndarray
    chainage_m: np.ndarray
    sample_step_m: float = 10.0
    _tree: cKDTree = field(init=False, repr=False, compare=False)
    _owner: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        x = np.asarray(self.x, dtype=np.float64)
        y = np.asarray(self.y, dtype=np.float64)
        c = np.asarray(self.chainage_m, dtype=np.float64)
        if x.ndim != 1 or x.shape != y.shape or x.shape != c.shape:
            raise ValueError("x, y and chainage_m must be 1-D arrays of equal length")
        if x.size < 2:
            raise ValueError("a polyline needs at least two vertices")
        if not (np.isfinite(x).all() and np.isfinite(y).all() and np.isfinite(c).all()):
            raise ValueError("x, y and chainage_m must be finite")
        dc = np.diff(c)
        if not ((dc > 0).all() or (dc < 0).all()):
            raise ValueError("chainage_m must be strictly increasing or strictly decreasing")
        seg = np.hypot(np.diff(x), np.diff(y))
        if (seg <= 0).any():
            raise ValueError(f"vertices {int(np.flatnonzero(seg <= 0)[0])} and the next are equal")
        if not (np.isfinite(self.sample_step_m) and self.sample_step_m > 0):
            raise ValueError(f"sample_step_m must be > 0 m, got {self.sample_step_m!r}")
        per_seg = np.maximum(np.ceil(seg / self.sample_step_m).astype(np.int64), 1)
        owner = np.repeat(np.arange(seg.size), per_seg)
        start = np.concatenate(([0], np.cumsum(per_seg)[:-1]))
        frac = (np.arange(owner.size) - start[owner]) / per_seg[owner]
        px = x[owner] + frac * (x[owner + 1] - x[owner])
        py = y[owner] + frac * (y[owner + 1] - y[owner])
        px = np.append(px, x[-1])
        py = np.append(py, y[-1])
        owner = np.append(owner, seg.size - 1)
        for name, value in (("x", x), ("y", y), ("chainage_m", c)):
            object.__setattr__(self, name, value)
        from scipy.spatial import cKDTree

        object.__setattr__(self, "_tree", cKDTree(np.column_stack((px, py))))
        object.__setattr__(self, "_owner", owner)

    @property
    def n_segments(self) -> int:
        """Number of segments."""
        return int(self.x.size - 1)

    @property
    def increasing(self) -> bool:
        """Whether the chainage increases along the vertices."""
        return bool(self.chainage_m[-1] > self.chainage_m[0])

    def point_at(self, chainage_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Coordinates (m) of the points of the polyline at the given chainages (m)."""
        c = np.asarray(chainage_m, dtype=np.float64)
        order = slice(None) if self.increasing else slice(None, None, -1)
        cs = self.chainage_m[order]
        return np.interp(c, cs, self.x[order]), np.interp(c, cs, self.y[order])


@dataclass(frozen=True)
class MatchResult:
    """Points matched onto a polyline.

    Attributes
    ----------
    chainage_m : numpy.ndarray
        Chainage of the nearest polyline point, m (line km × 1000).
    offset_m : numpy.ndarray
        Signed distance from the polyline, m (positive: left of the km direction).
    segment : numpy.ndarray
        Index of the segment holding the nearest point (int64).
    """

    chainage_m: np.ndarray
    offset_m: np.ndarray
    segment: np.ndarray


def match_points(line: Polyline, x: np.ndarray, y: np.ndarray, *, chunk: int = 8192) -> MatchResult:
    """Match points onto the nearest point of a polyline.

    Parameters
    ----------
    line : Polyline
        The geometry.
    x, y : array_like
        Point coordinates, m, in the polyline's plane; finite, equal shapes (1-D).
    chunk : int
        Points matched per batch (memory bound).

    Returns
    -------
    MatchResult
    """
    px = np.asarray(x, dtype=np.float64)
    py = np.asarray(y, dtype=np.float64)
    if px.ndim != 1 or px.shape != py.shape:
        raise ValueError("x and y must be 1-D arrays of equal length")
    if not (np.isfinite(px).all() and np.isfinite(py).all()):
        raise ValueError("x and y must be finite")
    if int(chunk) < 1:
        raise ValueError(f"chunk must be >= 1, got {chunk!r}")
    n = px.size
    chain = np.empty(n)
    offset = np.empty(n)
    segment = np.empty(n, dtype=np.int64)
    x0, y0 = line.x[:-1], line.y[:-1]
    dx, dy = np.diff(line.x), np.diff(line.y)
    len2 = dx * dx + dy * dy
    sign = 1.0 if line.increasing else -1.0
    for a in range(0, n, int(chunk)):
        b = min(a + int(chunk), n)
        pts = np.column_stack((px[a:b], py[a:b]))
        d0, _ = line._tree.query(pts)
        radius = d0 + line.sample_step_m
        hits = line._tree.query_ball_point(pts, radius, return_sorted=False)
        counts = np.fromiter((len(h) for h in hits), dtype=np.int64, count=b - a)
        rows = np.repeat(np.arange(b - a), counts)
        segs = line._owner[np.concatenate([np.asarray(h, dtype=np.int64) for h in hits])]
        key = np.unique(rows * (line.n_segments + 1) + segs)
        rows, segs = key // (line.n_segments + 1), key % (line.n_segments + 1)
        qx, qy = pts[rows, 0], pts[rows, 1]
        t = np.clip(((qx - x0[segs]) * dx[segs] + (qy - y0[segs]) * dy[segs]) / len2[segs], 0.0, 1.0)
        cx = x0[segs] + t * dx[segs]
        cy = y0[segs] + t * dy[segs]
        dist2 = (qx - cx) ** 2 + (qy - cy) ** 2
        order = np.lexsort((dist2, rows))
        first = np.ones(order.size, dtype=bool)
        first[1:] = rows[order][1:] != rows[order][:-1]
        best = order[first]
        r, s, tb = rows[best], segs[best], t[best]
        chain[a + r] = line.chainage_m[s] + tb * (line.chainage_m[s + 1] - line.chainage_m[s])
        cross = dx[s] * (pts[r, 1] - y0[s]) - dy[s] * (pts[r, 0] - x0[s])
        offset[a + r] = sign * np.sign(cross) * np.sqrt(dist2[best])
        segment[a + r] = s
    return MatchResult(chainage_m=chain, offset_m=offset, segment=segment)
