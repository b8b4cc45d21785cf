"""Argument checks shared by the analysis modules.

The messages keep each module's style: the stiffness analyses say
``"<name>: must be …"``, the profile and wheel modules ``"<name> must be …"``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["paired_1d", "check_positive", "positive_float"]


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


def positive_float(
    value: object, name: str, *, number: str = "a number", positive: str = "a finite number > 0"
) -> float:
    """``float(value)``, which must be finite and > 0.

    Parameters
    ----------
    value : object
        The argument.
    name : str
        Its name for the message.
    number, positive : str, optional
        What the messages say it must be when it is not a number
        (``"<name> must be <number>, got …"``) and when it is not finite and
        > 0 (``"<name> must be <positive>, got …"``); give the unit there.

    Raises
    ------
    ValueError
        With one of the two messages.
    """
    try:
        out = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be {number}, got {value!r}") from None
    if not np.isfinite(out) or out <= 0:
        raise ValueError(f"{name} must be {positive}, got {value!r}")
    return out
