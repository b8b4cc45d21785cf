"""What every input reader provides."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from app.core.i18n import _
from app.io._closing import Closing
from app.io.channels import INPUT_CHANNELS, TIME_COLUMN, canonical_name
from app.io.errors import RunFileError

__all__ = ["SourceInfo", "Source", "map_channel_names"]


@dataclass
class SourceInfo:
    """What a reader learns from an input file before reading data.

    Attributes
    ----------
    channels : list of str
        Canonical names of the channels present (without ``time``).
    has_time : bool
        Whether a ``time`` column/dataset is present (s).
    n_samples : int or None
        Samples per channel if known before reading (HDF5, Parquet).
    file_metadata : dict
        Metadata stored in the file itself (HDF5 ``metadata`` attribute).
    fs_hint : float or None
        Sample rate stored in the file (HDF5 ``sample_rate_hz`` attribute), Hz.
    calibration : dict
        Channel → ``{"gain", "offset"}`` found in the file (HDF5 dataset attributes).
    """

    channels: list[str]
    has_time: bool = False
    n_samples: int | None = None
    file_metadata: dict[str, Any] = field(default_factory=dict)
    fs_hint: float | None = None
    calibration: dict[str, dict[str, float]] = field(default_factory=dict)


class Source(Closing):
    """Base class of the block readers; a context manager (``close`` releases the file)."""

    info: SourceInfo

    def blocks(self, size: int) -> Iterator[dict[str, np.ndarray]]:
        """Yield dicts canonical name → float64 array, all of equal length (≤ ``size``)."""
        raise NotImplementedError


def map_channel_names(names: Iterable[str]) -> dict[str, str]:
    """Map input names to canonical channel names (case-insensitive).

    Parameters
    ----------
    names : iterable of str
        Column or dataset names from the file.

    Returns
    -------
    dict
        Input name → canonical name (``"Z11"``, ``"speed"``, ``"time"`` …).

    Raises
    ------
    RunFileError
        ``field`` is the input name, for an unknown name or a duplicate.
    """
    out: dict[str, str] = {}
    seen: dict[str, str] = {}
    for name in names:
        canon = canonical_name(name)
        if canon is None:
            raise RunFileError(
                str(name),
                _("unknown channel; accepted are {items} and {time}", items=', '.join(INPUT_CHANNELS), time=TIME_COLUMN),
            )
        if canon in seen:
            raise RunFileError(str(name), _("duplicate channel (also given as {seen!r})", seen=seen[canon]))
        seen[canon] = str(name)
        out[str(name)] = canon
    return out
