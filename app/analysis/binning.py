"""Mergeable per-bin weighted sums along the track (25 cm profile bins).

A run is processed in chunks that may run independently (on different hosts,
possibly twice) and are merged later. Chunk seams are crossfaded: every sample
carries a weight ``w`` and the weights of all chunks covering one sample add up
to 1. Bins are therefore accumulated as plain sums, which add exactly:

* ``weight`` = Σ w, ``count`` = number of contributions with w > 0,
* ``sums[name]`` = Σ w·v, ``sq[name]`` = Σ w·v² (only for names asked for),
* ``vweight[name]`` = Σ w over the samples where v was finite.

Merging two partial results is an element-wise addition on the union of their
bins, so the merged result does not depend on how a run was split.
:meth:`BinSums.finalize` turns the sums into weighted means and RMS values.

Bin index convention: ``bin = floor(track_m / bin_length)`` with ``track_m``
the position along the line km axis in m; the bin centre is
``(bin + 0.5) * bin_length`` m.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from app.analysis._checks import positive_float

__all__ = ["BinSums", "position_to_bin"]

_NAME_RE = re.compile(r"^[A-Za-z0-9_]+$")
_FORMAT_VERSION = 1
_PREFIX_SUM = "sum__"
_PREFIX_SQ = "sq__"
_PREFIX_VW = "vw__"


def position_to_bin(track_m: np.ndarray, bin_length: float = 0.25) -> np.ndarray:
    """Bin index of track positions.

    Parameters
    ----------
    track_m : array_like
        Track positions along the line km axis, m. Must be finite.
    bin_length : float, optional
        Bin length, m (default 0.25). Must be finite and > 0.

    Returns
    -------
    numpy.ndarray
        ``floor(track_m / bin_length)`` as int64, same shape as ``track_m``.

    Raises
    ------
    ValueError
        If ``track_m`` holds NaN/inf or ``bin_length`` is not a positive finite number.
    """
    bin_length = _check_bin_length(bin_length)
    x = np.asarray(track_m, dtype=np.float64)
    if not np.all(np.isfinite(x)):
        raise ValueError("track_m must be finite (found NaN or inf)")
    return np.floor(x / bin_length).astype(np.int64)


def _check_bin_length(bin_length: float) -> float:
    return positive_float(bin_length, "bin_length", positive="a finite number > 0 m")


def _check_name(name: object, what: str) -> str:
    if not isinstance(name, str) or not _NAME_RE.match(name):
        raise ValueError(
            f"{what} names must be non-empty strings of letters, digits and '_', got {name!r}"
        )
    return name


@dataclass(eq=False)
class BinSums:
    """Per-bin weighted sums of one or more sample values.

    Attributes
    ----------
    bins : numpy.ndarray
        (nb,) int64 bin indices, sorted and unique.
    weight : numpy.ndarray
        (nb,) float64, Σ w of the samples in each bin.
    count : numpy.ndarray
        (nb,) int64, number of contributing samples (w > 0). A sample covered by
        two crossfaded chunks counts twice; ``weight`` counts it once.
    sums : dict of str to numpy.ndarray
        (nb,) float64 per value name, Σ w·v over the samples where v is finite.
    sq : dict of str to numpy.ndarray
        (nb,) float64 per value name kept with squares, Σ w·v².
    vweight : dict of str to numpy.ndarray
        (nb,) float64 per value name, Σ w over the samples where v is finite.
    """

    bins: np.ndarray
    weight: np.ndarray
    count: np.ndarray
    sums: dict[str, np.ndarray] = field(default_factory=dict)
    sq: dict[str, np.ndarray] = field(default_factory=dict)
    vweight: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.bins = np.asarray(self.bins)
        if self.bins.ndim != 1 or not (
            np.issubdtype(self.bins.dtype, np.integer) or self.bins.size == 0
        ):
            raise ValueError("bins must be a 1-D integer array")
        self.bins = self.bins.astype(np.int64, copy=False)
        nb = self.bins.size
        if nb > 1 and not np.all(np.diff(self.bins) > 0):
            raise ValueError("bins must be sorted and unique")
        self.weight = _as_column(self.weight, nb, "weight", np.float64)
        self.count = _as_column(self.count, nb, "count", np.int64)
        self.sums = {
            _check_name(k, "sums"): _as_column(v, nb, f"sums[{k!r}]", np.float64)
            for k, v in self.sums.items()
        }
        self.vweight = {
            _check_name(k, "vweight"): _as_column(v, nb, f"vweight[{k!r}]", np.float64)
            for k, v in self.vweight.items()
        }
        self.sq = {
            _check_name(k, "sq"): _as_column(v, nb, f"sq[{k!r}]", np.float64)
            for k, v in self.sq.items()
        }
        if set(self.vweight) != set(self.sums):
            raise ValueError("vweight must have the same names as sums")
        extra = set(self.sq) - set(self.sums)
        if extra:
            raise ValueError(f"sq names {sorted(extra)} are not in sums")

    # ------------------------------------------------------------------ build
    @classmethod
    def from_samples(
        cls,
        bins: np.ndarray,
        weight: np.ndarray,
        values: Mapping[str, np.ndarray],
        squares: Iterable[str] = (),
    ) -> BinSums:
        """Accumulate per-sample values into per-bin sums.

        Parameters
        ----------
        bins : array_like of int
            (n,) bin index of every sample (see :func:`position_to_bin`).
        weight : array_like of float
            (n,) sample weights (crossfade weights, 0..1), finite and >= 0.
            Samples with ``weight == 0`` are dropped.
        values : mapping of str to array_like
            (n,) real sample values per name (e.g. m/s², m/s). A NaN/inf value
            excludes that sample for that value only.
        squares : iterable of str, optional
            Names in ``values`` for which Σ w·v² is kept (for an RMS).

        Returns
        -------
        BinSums

        Raises
        ------
        ValueError
            If an argument has the wrong shape/dtype, ``weight`` is negative or not
            finite, or ``squares`` names a value that is not in ``values``.
        """
        b = np.asarray(bins)
        if b.ndim != 1:
            raise ValueError(f"bins must be 1-D, got shape {b.shape}")
        if b.size and not np.issubdtype(b.dtype, np.integer):
            raise ValueError(f"bins must be integers, got dtype {b.dtype}")
        b = b.astype(np.int64, copy=False)
        n = b.size
        w = np.asarray(weight, dtype=np.float64)
        if w.shape != (n,):
            raise ValueError(f"weight must have shape {(n,)} like bins, got {w.shape}")
        if not np.all(np.isfinite(w)) or np.any(w < 0):
            raise ValueError("weight must be finite and >= 0")
        if not isinstance(values, Mapping):
            raise ValueError("values must be a mapping of name -> array")
        vals: dict[str, np.ndarray] = {}
        for name, v in values.items():
            _check_name(name, "values")
            arr = np.asarray(v)
            if np.iscomplexobj(arr):
                raise ValueError(f"values[{name!r}] must be real, got complex")
            arr = arr.astype(np.float64, copy=False)
            if arr.shape != (n,):
                raise ValueError(
                    f"values[{name!r}] must have shape {(n,)} like bins, got {arr.shape}"
                )
            vals[name] = arr
        squares = list(squares) if not isinstance(squares, str) else [squares]
        missing = [s for s in squares if s not in vals]
        if missing:
            raise ValueError(f"squares names {missing} are not in values")

        keep = w > 0
        if not np.all(keep):
            b, w = b[keep], w[keep]
            vals = {k: v[keep] for k, v in vals.items()}
        ub, inv = np.unique(b, return_inverse=True)
        nb = ub.size
        inv = inv.reshape(-1)

        def bsum(x: np.ndarray) -> np.ndarray:
            return np.bincount(inv, weights=x, minlength=nb).astype(np.float64, copy=False)

        sums: dict[str, np.ndarray] = {}
        sq: dict[str, np.ndarray] = {}
        vweight: dict[str, np.ndarray] = {}
        for name, v in vals.items():
            finite = np.isfinite(v)
            wf = np.where(finite, w, 0.0)
            wv = np.where(finite, w * np.where(finite, v, 0.0), 0.0)
            sums[name] = bsum(wv)
            vweight[name] = bsum(wf)
            if name in squares:
                sq[name] = bsum(wv * np.where(finite, v, 0.0))
        return cls(
            bins=ub.astype(np.int64),
            weight=bsum(w),
            count=np.bincount(inv, minlength=nb).astype(np.int64),
            sums=sums,
            sq=sq,
            vweight=vweight,
        )

    # ------------------------------------------------------------------ merge
    @property
    def names(self) -> list[str]:
        """Value names, in insertion order."""
        return list(self.sums)

    def __len__(self) -> int:
        return int(self.bins.size)

    def merge(self, other: BinSums) -> BinSums:
        """Return the sums of ``self`` and ``other`` on the union of their bins.

        Raises
        ------
        ValueError
            If ``other`` carries different value names or squares.
        """
        return BinSums.merge_all([self, other])

    @staticmethod
    def merge_all(parts: Iterable[BinSums]) -> BinSums:
        """Merge many partial results in one pass (deterministic for a given order).

        Parameters
        ----------
        parts : iterable of BinSums
            Partial results with identical value names and squares.

        Returns
        -------
        BinSums

        Raises
        ------
        ValueError
            If ``parts`` is empty or the parts disagree on names/squares.
        """
        parts = list(parts)
        if not parts:
            raise ValueError("parts must hold at least one BinSums")
        for i, p in enumerate(parts):
            if not isinstance(p, BinSums):
                raise ValueError(f"parts[{i}] is not a BinSums")
        first = parts[0]
        names, sq_names = set(first.sums), set(first.sq)
        for i, p in enumerate(parts[1:], start=1):
            if set(p.sums) != names or set(p.sq) != sq_names:
                raise ValueError(
                    f"parts[{i}] has value names {sorted(p.sums)} / squares {sorted(p.sq)}, "
                    f"expected {sorted(names)} / {sorted(sq_names)}"
                )
        all_bins = np.concatenate([p.bins for p in parts])
        ub, inv = np.unique(all_bins, return_inverse=True)
        inv = inv.reshape(-1)
        nb = ub.size

        def add(get: Callable[[BinSums], np.ndarray]) -> np.ndarray:
            x = np.concatenate([np.asarray(get(p), dtype=np.float64) for p in parts])
            return np.bincount(inv, weights=x, minlength=nb)

        count = np.bincount(
            inv, weights=np.concatenate([p.count for p in parts]).astype(np.float64), minlength=nb
        )
        return BinSums(
            bins=ub.astype(np.int64),
            weight=add(lambda p: p.weight),
            count=np.rint(count).astype(np.int64),
            sums={k: add(lambda p, k=k: p.sums[k]) for k in first.sums},
            sq={k: add(lambda p, k=k: p.sq[k]) for k in first.sq},
            vweight={k: add(lambda p, k=k: p.vweight[k]) for k in first.sums},
        )

    # ------------------------------------------------------------- round trip
    def to_arrays(self) -> dict[str, np.ndarray]:
        """Flat dict of arrays for ``numpy.savez`` (value names encoded in the keys)."""
        out: dict[str, np.ndarray] = {
            "binsums_version": np.array(_FORMAT_VERSION, dtype=np.int64),
            "bins": self.bins,
            "weight": self.weight,
            "count": self.count,
        }
        for k in self.sums:
            out[_PREFIX_SUM + k] = self.sums[k]
            out[_PREFIX_VW + k] = self.vweight[k]
            if k in self.sq:
                out[_PREFIX_SQ + k] = self.sq[k]
        return out

    @classmethod
    def from_arrays(cls, d: Mapping[str, np.ndarray]) -> BinSums:
        """Rebuild from :meth:`to_arrays` output (a dict or an ``NpzFile``).

        Raises
        ------
        ValueError
            If a required key is missing, the format version is unknown or the
            arrays are inconsistent.
        """
        keys = list(d.files) if hasattr(d, "files") else list(d.keys())
        for req in ("binsums_version", "bins", "weight", "count"):
            if req not in keys:
                raise ValueError(f"d is missing the key {req!r}")
        version = int(np.asarray(d["binsums_version"]))
        if version != _FORMAT_VERSION:
            raise ValueError(f"d has binsums_version {version}, expected {_FORMAT_VERSION}")
        sums, sq, vweight = {}, {}, {}
        for k in keys:
            if k.startswith(_PREFIX_SUM):
                sums[k[len(_PREFIX_SUM) :]] = np.asarray(d[k])
            elif k.startswith(_PREFIX_SQ):
                sq[k[len(_PREFIX_SQ) :]] = np.asarray(d[k])
            elif k.startswith(_PREFIX_VW):
                vweight[k[len(_PREFIX_VW) :]] = np.asarray(d[k])
        return cls(
            bins=np.asarray(d["bins"]),
            weight=np.asarray(d["weight"]),
            count=np.asarray(d["count"]),
            sums=sums,
            sq=sq,
            vweight=vweight,
        )

    # --------------------------------------------------------------- finalize
    def finalize(self, bin_length: float) -> pd.DataFrame:
        """Per-bin weighted means (and RMS values) as a DataFrame.

        Parameters
        ----------
        bin_length : float
            Bin length, m (used for the km of the bin centre).

        Returns
        -------
        pandas.DataFrame
            Columns ``bin`` (int64), ``km`` (bin centre, km =
            ``(bin + 0.5) * bin_length / 1000``), ``n_samples`` (int64: effective
            number of samples, ``round(Σ w)``; with crossfade weights summing to 1
            this is the number of distinct samples in the bin), then ``<name>``
            = Σ w·v / Σ w over finite v (NaN where no finite sample) for every
            value, and ``<name>_rms`` = sqrt(Σ w·v² / Σ w) for every name kept
            with squares.
        """
        bin_length = _check_bin_length(bin_length)
        cols: dict[str, np.ndarray] = {
            "bin": self.bins.copy(),
            "km": (self.bins.astype(np.float64) + 0.5) * bin_length / 1000.0,
            "n_samples": np.rint(self.weight).astype(np.int64),
        }
        for k, s in self.sums.items():
            vw = self.vweight[k]
            ok = vw > 0
            cols[k] = np.divide(s, vw, out=np.full_like(s, np.nan), where=ok)
        for k, s2 in self.sq.items():
            vw = self.vweight[k]
            ok = vw > 0
            ms = np.divide(s2, vw, out=np.full_like(s2, np.nan), where=ok)
            cols[f"{k}_rms"] = np.sqrt(np.maximum(ms, 0.0))
        return pd.DataFrame(cols)


def _as_column(x: np.ndarray, nb: int, what: str, dtype: type) -> np.ndarray:
    arr = np.asarray(x)
    if arr.shape != (nb,):
        raise ValueError(f"{what} must have shape {(nb,)} like bins, got {arr.shape}")
    return arr.astype(dtype, copy=False)
