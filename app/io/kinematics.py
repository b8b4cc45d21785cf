"""Speed from position and position from speed, computed block-wise, and stored for a run that
lacks one of them (:func:`derive_kinematics`).

Both derivations are defined so that any slice gives exactly the values of a
single pass over the whole run:

* speed from position: centred difference over ``±h`` samples,
  ``v[k] = (p[min(k+h, n-1)] - p[max(k-h, 0)]) / ((min(k+h, n-1) - max(k-h, 0)) / fs)``
  with ``h = round(SPEED_WINDOW_S * fs / 2)`` (at least 1) — the gradient of
  the position smoothed by a boxcar of ``SPEED_WINDOW_S``; one-sided at the ends.
* position from speed: cumulative trapezoid of ``max(v, 0)`` starting at 0 m.
  The run is split into blocks of :data:`POSITION_BLOCK` samples; the position at
  each block start is tabulated once and the samples of a block are integrated
  from there, so every slice reproduces the same numbers.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from app.core.i18n import _
from app.io.canonical import CanonicalWriter
from app.io.errors import RunFileError
from app.io.limits import IngestLimits

__all__ = [
    "SPEED_WINDOW_S",
    "POSITION_BLOCK",
    "speed_half_window",
    "speed_from_position",
    "integrate_block",
    "position_table",
    "position_from_speed",
    "derive_kinematics",
]

#: Length of the smoothing window for speed derived from position, s.
SPEED_WINDOW_S = 0.2
#: Block length (samples) of the position-from-speed integration.
POSITION_BLOCK = 65_536

Reader = Callable[[int, int], np.ndarray]


def speed_half_window(fs: float) -> int:
    """Half window ``h`` (samples) of the speed-from-position difference at ``fs`` Hz."""
    return max(1, round(SPEED_WINDOW_S * float(fs) / 2.0))


def speed_from_position(
    read_position: Reader, n: int, fs: float, start: int, stop: int
) -> np.ndarray:
    """Smoothed speed (m/s) of samples ``start:stop`` from a position channel (m).

    Parameters
    ----------
    read_position : callable
        ``read_position(a, b)`` returns positions (m) of samples ``a:b``.
    n : int
        Number of samples of the run.
    fs : float
        Sample rate, Hz.
    start, stop : int
        Sample range, ``0 <= start <= stop <= n``.

    Returns
    -------
    numpy.ndarray
        Speed, m/s, float64, length ``stop - start``.
    """
    if stop <= start:
        return np.zeros(0)
    if n < 2:
        return np.zeros(stop - start)
    h = speed_half_window(fs)
    a = max(start - h, 0)
    b = min(stop + h, n)
    p = np.asarray(read_position(a, b), dtype=np.float64)
    k = np.arange(start, stop)
    lo = np.maximum(k - h, 0)
    hi = np.minimum(k + h, n - 1)
    return (p[hi - a] - p[lo - a]) * (float(fs) / (hi - lo))


def integrate_block(
    v_ext: np.ndarray, fs: float, p0: float, length: int
) -> tuple[np.ndarray, float]:
    """Integrate one block of speeds into positions.

    Parameters
    ----------
    v_ext : numpy.ndarray
        Speeds (m/s) of the block's ``length`` samples plus, unless the block is
        the last one, the first sample of the next block.
    fs : float
        Sample rate, Hz.
    p0 : float
        Position at the first sample of the block, m.
    length : int
        Number of samples in the block.

    Returns
    -------
    positions : numpy.ndarray
        Positions of the block's samples, m.
    p_next : float
        Position at the first sample of the next block, m (equal to the last
        position when there is no next sample).
    """
    v = np.maximum(np.asarray(v_ext, dtype=np.float64), 0.0)
    inc = (v[:-1] + v[1:]) * (0.5 / float(fs))
    cum = np.cumsum(inc)
    out = np.empty(length)
    out[0] = p0
    out[1:] = p0 + cum[: length - 1]
    p_next = float(p0 + cum[length - 1]) if cum.size >= length else float(out[-1])
    return out, p_next


def position_table(read_speed: Reader, n: int, fs: float) -> np.ndarray:
    """Positions (m) at the start of every :data:`POSITION_BLOCK` block.

    Parameters
    ----------
    read_speed : callable
        ``read_speed(a, b)`` returns speeds (m/s) of samples ``a:b``.
    n : int
        Number of samples.
    fs : float
        Sample rate, Hz.

    Returns
    -------
    numpy.ndarray
        ``table[b]`` is the position of sample ``b * POSITION_BLOCK``, m.
    """
    nb = max(1, -(-n // POSITION_BLOCK))
    table = np.zeros(nb)
    p = 0.0
    for b in range(nb - 1):
        a = b * POSITION_BLOCK
        _v, p = integrate_block(read_speed(a, a + POSITION_BLOCK + 1), fs, p, POSITION_BLOCK)
        table[b + 1] = p
    return table


def position_from_speed(
    read_speed: Reader, table: np.ndarray, n: int, fs: float, start: int, stop: int
) -> np.ndarray:
    """Positions (m) of samples ``start:stop`` integrated from speed.

    Parameters
    ----------
    read_speed : callable
        ``read_speed(a, b)`` returns speeds (m/s) of samples ``a:b``.
    table : numpy.ndarray
        Output of :func:`position_table` for the same run.
    n : int
        Number of samples.
    fs : float
        Sample rate, Hz.
    start, stop : int
        Sample range.

    Returns
    -------
    numpy.ndarray
        Positions, m, float64.
    """
    out = np.empty(max(stop - start, 0))
    if stop <= start:
        return out
    b = start // POSITION_BLOCK
    while b * POSITION_BLOCK < stop:
        a = b * POSITION_BLOCK
        length = min(POSITION_BLOCK, n - a)
        pos, _v = integrate_block(read_speed(a, min(a + length + 1, n)), fs, float(table[b]), length)
        lo, hi = max(start, a), min(stop, a + length)
        out[lo - start : hi - start] = pos[lo - a : hi - a]
        b += 1
    return out


def derive_kinematics(
    writer: CanonicalWriter, stored: list[str], n: int, fs: float, limits: IngestLimits
) -> dict[str, float]:
    """Store the missing one of speed and position of a written run, and check that the two agree.

    Speed from position: :func:`speed_from_position`; position from speed: the block-wise
    cumulative trapezoid (:func:`integrate_block`). Where both are given, the integrated speed
    and the position's distance agree within ``limits.speed_position_tolerance`` (a
    :class:`~app.io.errors.RunFileError` naming ``speed`` otherwise).

    Returns
    -------
    dict
        ``distance`` (m) and ``vmin``, ``vmax`` (m/s).
    """
    h5 = writer.h5
    meta = writer.metadata

    def read(name: str, a: int, b: int) -> np.ndarray:
        gain, offset = (1.0, 0.0) if h5[name].attrs["derived"] else meta.gain_offset(name)
        return h5[name][a:b].astype(np.float64) * gain + offset

    vmin, vmax = math.inf, -math.inf
    if "speed" not in stored:
        writer.add_channel(
            "speed", derived=f"smoothed gradient of position, window {SPEED_WINDOW_S:g} s"
        )
        for a in range(0, n, limits.block_samples):
            b = min(a + limits.block_samples, n)
            v = speed_from_position(lambda i, j: read("position", i, j), n, fs, a, b)
            writer.write("speed", a, v)
            vmin, vmax = min(vmin, float(v.min())), max(vmax, float(v.max()))
    # integrate speed block-wise (POSITION_BLOCK grid) for the stored position or the check
    derive_pos = "position" not in stored
    if derive_pos:
        writer.add_channel("position", derived="cumulative trapezoid of max(speed, 0)")
    p = 0.0
    for a in range(0, n, POSITION_BLOCK):
        length = min(POSITION_BLOCK, n - a)
        v_ext = read("speed", a, min(a + length + 1, n))
        if "speed" in stored:
            vmin, vmax = min(vmin, float(v_ext.min())), max(vmax, float(v_ext.max()))
        pos, p_next = integrate_block(v_ext, fs, p, length)
        if derive_pos:
            writer.write("position", a, pos)
        p = p_next
    integrated = p
    if derive_pos:
        distance = integrated
    else:
        first = float(read("position", 0, 1)[0])
        last = float(read("position", n - 1, n)[0])
        distance = last - first
        if "speed" in stored and max(distance, integrated) > 20.0:
            rel = abs(integrated - distance) / max(distance, integrated)
            if rel > limits.speed_position_tolerance:
                raise RunFileError(
                    "speed",
                    _("integrated speed gives {integrated:.1f} m but position covers {distance:.1f} m ({percent:.0f} % apart); check the units (m/s, m) and calibration", integrated=integrated, distance=distance, percent=100 * rel),
                )
    return {"distance": float(distance), "vmin": vmin, "vmax": vmax}
