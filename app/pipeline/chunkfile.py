"""The chunk-file format: one ``.npz`` file of additive per-bin sums per chunk of a job.

A chunk file is written once, atomically (:func:`write_chunk_file`:
temporary file, fsync, ``os.replace``), so it either exists whole or not at
all: its presence is the proof that the chunk is done. Members:

``chunk_index``
    The chunk's index (integer scalar).
``<kind>_<wheel>__packed_names`` / ``_packed_f8`` / ``_packed_i8`` / ``_packed_scalars``
    One group of :class:`~app.analysis.binning.BinSums` per kind and wheel
    (:func:`pack_group`): ``bins`` (the 25 cm profile sums), ``resid``
    (residual sums per bin), ``oor`` (wheel out-of-roundness phasor sums per
    window of :data:`app.pipeline.chunk.OOR_WINDOW_M`).
``diameter_<wheel>``
    The wheel diameter the chunk was solved with, m.
``warnings_<wheel>``
    Plain-language warnings of the wheel's solve in this chunk (strings;
    absent in files written before issue 15: none).
``dips_<wheel>``
    The wheel's dip candidates in the chunk's output range
    (:mod:`app.pipeline.impacts`, rows :data:`app.pipeline.impacts.DIP_FIELDS`;
    absent in files written before issue 26: none).

Files of the earlier layout (one member per array, ``<kind>_<wheel>__<name>``)
still read (:func:`load_group`).
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from app.analysis.binning import BinSums

__all__ = [
    "GROUP_KINDS",
    "WheelParts",
    "group_prefix",
    "pack_group",
    "load_group",
    "wheel_members",
    "read_wheel",
    "write_chunk_file",
]

#: groups of sums a chunk file holds per wheel
GROUP_KINDS = ("bins", "resid", "oor")


def group_prefix(kind: str, wheel: str) -> str:
    """Member-name prefix of the group ``kind`` of ``wheel`` (``"bins_11__"``)."""
    if kind not in GROUP_KINDS:
        raise ValueError(f"kind must be one of {', '.join(GROUP_KINDS)}, got {kind!r}")
    return f"{kind}_{wheel}__"


def _diameter_member(wheel: str) -> str:
    return f"diameter_{wheel}"


def _warnings_member(wheel: str) -> str:
    return f"warnings_{wheel}"


def pack_group(prefix: str, arrays: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """One group of equal-length arrays as four ``.npz`` members.

    ``packed_names`` lists the float names, ``"|"``, the integer names, ``"|"``
    and the scalar names; ``packed_f8`` / ``packed_i8`` hold the float / integer
    arrays as rows, ``packed_scalars`` the integer scalars.

    A chunk file holds ~50 arrays per wheel; as separate members, reading them
    back cost more than merging them (each member is a zip entry with a parsed
    header). Packed, a group is four members whatever its size.

    Parameters
    ----------
    prefix : str
        Prefix of the member names (:func:`group_prefix`).
    arrays : mapping of str to ndarray
        1-D float or integer arrays of one length, and integer scalars
        (:meth:`BinSums.to_arrays`).

    Raises
    ------
    ValueError
        If the arrays differ in length or are neither 1-D float/int arrays nor
        integer scalars.
    """
    lengths = {np.asarray(v).shape for v in arrays.values() if np.asarray(v).ndim == 1}
    if len(lengths) > 1:
        raise ValueError(f"{prefix}: arrays of different lengths {sorted(lengths)}")
    floats = [k for k, v in arrays.items() if np.asarray(v).ndim == 1 and np.asarray(v).dtype.kind == "f"]
    ints = [k for k, v in arrays.items() if np.asarray(v).ndim == 1 and np.asarray(v).dtype.kind in "iu"]
    scalars = [k for k in arrays if k not in floats and k not in ints]
    if any(np.asarray(arrays[k]).ndim != 0 or np.asarray(arrays[k]).dtype.kind not in "iu" for k in scalars):
        raise ValueError(f"{prefix}: only 1-D float/int arrays and integer scalars can be packed")
    n = lengths.pop()[0] if lengths else 0
    return {
        f"{prefix}packed_names": np.array(floats + ["|"] + ints + ["|"] + scalars, dtype=np.str_),
        f"{prefix}packed_f8": np.array([arrays[k] for k in floats], dtype=np.float64).reshape(len(floats), n),
        f"{prefix}packed_i8": np.array([arrays[k] for k in ints], dtype=np.int64).reshape(len(ints), n),
        f"{prefix}packed_scalars": np.array([int(arrays[k]) for k in scalars], dtype=np.int64),
    }


def load_group(npz: Any, prefix: str) -> BinSums | None:
    """A group written by :func:`pack_group` (or, in older files, one member per array).

    Parameters
    ----------
    npz : numpy.lib.npyio.NpzFile
        An open chunk file (anything with ``files`` and item access).
    prefix : str
        The group's prefix (:func:`group_prefix`).

    Returns
    -------
    BinSums or None
        None if the file holds no such group.
    """
    if f"{prefix}packed_names" in npz.files:
        names = [str(x) for x in npz[f"{prefix}packed_names"]]
        cut1 = names.index("|")
        cut2 = names.index("|", cut1 + 1)
        floats, ints, scalars = names[:cut1], names[cut1 + 1 : cut2], names[cut2 + 1 :]
        f8, i8 = npz[f"{prefix}packed_f8"], npz[f"{prefix}packed_i8"]
        sc = npz[f"{prefix}packed_scalars"]
        arrays = {k: f8[i] for i, k in enumerate(floats)}
        arrays.update({k: i8[i] for i, k in enumerate(ints)})
        arrays.update({k: sc[i] for i, k in enumerate(scalars)})
        return BinSums.from_arrays(arrays)
    keys = {k[len(prefix) :]: npz[k] for k in npz.files if k.startswith(prefix)}
    return BinSums.from_arrays(keys) if keys else None


def wheel_members(
    wheel: str, groups: Mapping[str, BinSums], diameter_m: float, warnings: Sequence[str] = ()
) -> dict[str, np.ndarray]:
    """The members of one wheel in a chunk file: its groups of sums and its diameter.

    Parameters
    ----------
    wheel : str
        ``"11"``, ``"12"``, ``"41"`` or ``"42"``.
    groups : mapping of kind to BinSums
        One entry per kind of :data:`GROUP_KINDS`.
    diameter_m : float
        Wheel diameter the chunk was solved with, m.
    warnings : sequence of str
        Warnings of the wheel's solve in this chunk.
    """
    if set(groups) != set(GROUP_KINDS):
        raise ValueError(f"groups must hold {', '.join(GROUP_KINDS)}, got {', '.join(sorted(groups))}")
    members: dict[str, np.ndarray] = {}
    for kind in GROUP_KINDS:
        members.update(pack_group(group_prefix(kind, wheel), groups[kind].to_arrays()))
    members[_diameter_member(wheel)] = np.array(diameter_m)
    members[_warnings_member(wheel)] = np.array(list(warnings), dtype=np.str_).reshape(-1)
    return members


@dataclass(frozen=True)
class WheelParts:
    """One wheel's content of one chunk file.

    Attributes
    ----------
    groups : dict of kind to BinSums
        The groups found (kinds of :data:`GROUP_KINDS`).
    diameter_m : float or None
        Wheel diameter, m (None if the file does not hold it).
    warnings : tuple of str
        Warnings of the wheel's solve in the chunk.
    """

    groups: dict[str, BinSums]
    diameter_m: float | None
    warnings: tuple[str, ...] = ()


def read_wheel(path: Path, wheel: str) -> WheelParts:
    """Read one wheel's groups and diameter from a chunk file."""
    with np.load(path) as npz:
        groups = {}
        for kind in GROUP_KINDS:
            part = load_group(npz, group_prefix(kind, wheel))
            if part is not None:
                groups[kind] = part
        member = _diameter_member(wheel)
        diameter = float(npz[member]) if member in npz.files else None
        notes = _warnings_member(wheel)
        found = tuple(str(x) for x in npz[notes]) if notes in npz.files else ()
    return WheelParts(groups=groups, diameter_m=diameter, warnings=found)


def write_chunk_file(path: Path, chunk_index: int, members: Mapping[str, np.ndarray]) -> None:
    """Write a chunk file atomically (temporary file, fsync, ``os.replace``).

    Parameters
    ----------
    path : Path
        Target ``.npz``; its directory is created if missing.
    chunk_index : int
        Index of the chunk.
    members : mapping of str to ndarray
        The wheels' members (:func:`wheel_members`).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays = {"chunk_index": np.array(chunk_index), **members}
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, **arrays)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
