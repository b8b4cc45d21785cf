"""Argument checks shared by the stiffness analyses (messages ``"<name>: must be …"``)."""

from __future__ import annotations

import numpy as np

__all__ = ["paired_1d", "check_positive"]


def paired_1d(a: object, b: object, names: str) -> tuple[np.ndarray, np.ndarray]:
    """``a`` and ``b`` as float64 arrays, which must be 1-D of equal length.

    Parameters
    ----------
    a, b : array_like
        The two arrays.
    names : str
        Their names for the message, e.g. ``"start_m, end_m"``.

    Raises
    ------
    ValueError
        ``"<names>: must be 1-D of equal length"``.
    """
    x = np.asarray(a, dtype=np.float64)
    y = np.asarray(b, dtype=np.float64)
    if x.shape != y.shape or x.ndim != 1:
        raise ValueError(f"{names}: must be 1-D of equal length")
    return x, y


def check_positive(value: float, name: str) -> None:
    """Raise ``ValueError("<name>: must be > 0, got …")`` unless ``value > 0`` (NaN fails)."""
    if not value > 0:
        raise ValueError(f"{name}: must be > 0, got {value!r}")
