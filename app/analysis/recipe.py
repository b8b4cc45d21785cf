"""The railway order recipe: which orders the VKF tracks on a wheel, how wide, with what phase.

Every consumer of the orders reads them from here, so that a change of the
recipe changes the stored profiles, the chunk plan and the spectrogram's
extracted components alike:

* the processing pipeline (:mod:`app.pipeline`: chunk plan, chunk solve,
  residual, wheel out-of-roundness),
* the spectrogram of a km window (:mod:`app.analysis.spectrogram`, served by
  ``GET /runs/{id}/spectrogram``),
* the ``process`` command (through the pipeline).

The recipe of one wheel (:class:`OrderRecipe`, built by :func:`order_recipe`
from the wheel diameter d_w, the sleeper spacing d_s and the job's
:class:`~app.analysis.settings.ProcessingSettings`) holds, per tracked order
(row ``n`` of the VKF's order stack), as arrays:

* ``labels[n]``: ``"sleeper"`` (row 0, the sleeper passage ``f_s = v/d_s``),
  ``"sleeper_2"``, ``"sleeper_3"`` (its harmonics ``2 f_s``, ``3 f_s``, up to
  ``settings.sleeper_harmonics``), then ``"1"`` … ``"n"`` (wheel
  out-of-roundness orders ``f_l = l·v/(π d_w)``); the sleeper order and its
  harmonics are the *track orders*;
* ``multipliers[n]``: frequency per unit speed, Hz per m/s;
* ``bandwidth_per_speed[n]``: full -3 dB bandwidth per unit speed, Hz per
  m/s (:func:`order_bandwidths`): the wheel orders ``bandwidth_orders / (π d_w)``
  (narrow: out-of-roundness is stationary over a run), the track orders
  ``c_q / track_resolution_m`` (wide: a set spatial resolution, see
  :func:`track_bandwidth_per_speed`), all solved in one coupled VKF;
* below :attr:`OrderRecipe.floor_speed` the bandwidths keep their value at
  that speed (a slow or standing train still gives a finite filter), so the
  bandwidth floor of row ``n`` is ``bandwidth_per_speed[n] × floor_speed``.

Phase convention (the VKF's own, referred to a start position ``s0``): at
sample ``k`` order ``n`` has the phase ``multipliers[n] × psi[k]`` with
``psi = 2π (s0 + Σ_{l≤k} |v_l| / fs)`` (:func:`travel_phase`), i.e. the VKF is
started with ``phase0 = 2π multipliers s0`` (:meth:`OrderRecipe.phase0`). The
pipeline refers phases to the run start (``s0`` = position of the chunk's
first sample), the spectrogram to the window's first sample (``s0 = 0``).

Collisions: an order closer to another than the narrower one's bandwidth
cannot be told apart from it by the coupled solve. At d_w = 0.86 m the sleeper
order sits at 4.50 wheel orders and ``2 f_s`` at wheel order 9.01. A colliding
harmonic is dropped for that wheel; where the fundamental collides, the wheel
order is dropped instead (:func:`order_collisions`). The recipe keeps what it
dropped and why (:attr:`OrderRecipe.notes`), for the job's warnings.

Stationary wheel orders (issue 26): the wheel orders inside a track order's
band (:func:`in_band_wheel_orders`: 5, 9 and 10 by default) are solved as
stationary orders of the engine (:attr:`OrderRecipe.stationary`): a wheel's
out-of-roundness responds to the speed, not to the place, so their envelopes
are fitted as functions of frequency over the stretch solved and the track
orders are solved on what is left; otherwise a stiffness change would lose
its share at their lines (a 15.8 m ripple, docs/indicator.md).

Overlap: a stretch solved on its own agrees with a longer solve inside it
when it is padded by the impulse-response length of its narrowest filter
(:func:`order_overlap`); chunk seams use :data:`CHUNK_JOIN_TOL`. The
stationary wheel orders are fitted per stretch, so there the agreement is
that of the two fits (a steady wheel: the same phasor).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from app.analysis.orders import OrderTrack, railway_multipliers
from app.analysis.settings import MAX_SLEEPER_HARMONIC, ProcessingSettings
from app.analysis.units import KMH_PER_MPS
from app.analysis.vkf import CLOSE_ORDERS_MESSAGE, VKFWarning, vkf, vkf_overlap

if TYPE_CHECKING:
    from app.analysis.vkf import VKFResult

__all__ = [
    "SLEEPER",
    "STEP_WIDTH_FACTOR",
    "harmonic_label",
    "track_bandwidth_per_speed",
    "order_collisions",
    "in_band_wheel_orders",
    "CHUNK_JOIN_TOL",
    "OrderRecipe",
    "WheelGeometry",
    "order_bandwidths",
    "order_recipe",
    "wheel_recipe",
    "travel_phase",
    "order_overlap",
]

#: label of the sleeper-passage order (row 0 of the order stack)
SLEEPER = "sleeper"
#: 10–90 % width of the VKF's amplitude step response × its -3 dB bandwidth, per
#: filter order q: the continuous zero-phase low-pass H = 1/(1 + (√2−1)(2Δf/B)^(2q))
#: (-3 dB, |H| = 1/√2, at Δf = ±B/2); q = 1 in closed form 2 ln 5 / π · (√2−1)^(1/2),
#: q = 2 and 3 by integration; measured through the VKF in tests/pipeline/test_recipe.py
STEP_WIDTH_FACTOR: dict[int, float] = {1: 2.0 * math.log(5.0) / math.pi * math.sqrt(math.sqrt(2.0) - 1.0),
                                       2: 0.7205, 3: 0.7672}
#: neglected impulse-response tail at chunk seams: chunked profiles agree with an
#: unchunked solve to ~1e-5 of the signal level (far below the indicators' noise),
#: with 40 % less overlap than the engine's own 1e-8
CHUNK_JOIN_TOL = 1e-5
#: highest order frequency the overlap plans for, fraction of fs
_F_MAX_OF_FS = 0.499


class WheelGeometry(Protocol):
    """What the recipe reads of a run's metadata (:class:`app.io.RunMetadata`).

    ``wheel_diameters`` holds every wheel: the metadata's validation fills the
    nominal diameter (``app.io.metadata.DEFAULT_WHEEL_DIAMETER_M``) for wheels
    it was not given.
    """

    wheel_diameters: Mapping[str, float]
    sleeper_spacing: float


@dataclass(frozen=True, eq=False)
class OrderRecipe:
    """The orders the VKF tracks on one wheel, their bandwidths and phases.

    Build it with :func:`order_recipe` or :func:`wheel_recipe`. Arrays have
    one entry per tracked order (the rows of the VKF's order stack).

    Attributes
    ----------
    wheel_diameter, sleeper_spacing : float
        d_w and d_s, m.
    labels : tuple of str
        ``"sleeper"``, then the wheel orders ``"1"`` … ``"n"``.
    multipliers : ndarray, shape (s,)
        Order frequency per unit speed, Hz per m/s.
    bandwidth_per_speed : ndarray, shape (s,)
        Full -3 dB bandwidth per unit speed, Hz per m/s.
    floor_speed : float
        Speed below which the bandwidths stay at their value there, m/s (> 0).
    filter_order : int
        Order q of the VKF's structural equation.
    min_speed : float
        Samples slower than this do not count for indicators, m/s.
    notes : tuple of str
        What the recipe dropped and why (colliding orders), in plain words.
    """

    wheel_diameter: float
    sleeper_spacing: float
    labels: tuple[str, ...]
    multipliers: np.ndarray
    bandwidth_per_speed: np.ndarray
    floor_speed: float
    filter_order: int
    min_speed: float
    notes: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        s = len(self.labels)
        for name in ("multipliers", "bandwidth_per_speed"):
            a = np.array(getattr(self, name), dtype=np.float64)
            if a.shape != (s,):
                raise ValueError(f"{name} must have one entry per label ({s}), got shape {a.shape}")
            if not (np.all(np.isfinite(a)) and np.all(a > 0)):
                raise ValueError(f"{name} must be finite and > 0")
            a.setflags(write=False)
            object.__setattr__(self, name, a)
        if self.labels.count(SLEEPER) != 1:
            raise ValueError(f"labels must hold {SLEEPER!r} once, got {self.labels!r}")
        n_track = sum(not x.isdigit() for x in self.labels)
        if any(x.isdigit() for x in self.labels[:n_track]):
            raise ValueError(f"labels must list the track orders first, got {self.labels!r}")
        if not (math.isfinite(self.floor_speed) and self.floor_speed > 0):
            raise ValueError(f"floor_speed must be > 0 m/s, got {self.floor_speed!r}")

    # --- rows of the order stack ---------------------------------------------
    @property
    def sleeper_row(self) -> int:
        """Row of the sleeper-passage order."""
        return self.labels.index(SLEEPER)

    @property
    def wheel_orders(self) -> np.ndarray:
        """Numbers ``l`` of the tracked wheel orders (1 … n), int."""
        return np.array([int(x) for x in self.labels if x.isdigit()], dtype=np.int64)

    @property
    def harmonics(self) -> dict[int, int]:
        """Row of every extracted sleeper-passage harmonic: ``{1: row, 2: row, …}``."""
        return {h: self.labels.index(harmonic_label(h))
                for h in range(1, MAX_SLEEPER_HARMONIC + 1) if harmonic_label(h) in self.labels}

    @property
    def track_rows(self) -> np.ndarray:
        """Rows of the track orders (the sleeper passage and its harmonics; the first rows), int."""
        return np.array(list(self.harmonics.values()), dtype=np.int64)

    @property
    def powers(self) -> np.ndarray:
        """Harmonic number of every row within its group: ``h`` of a track order, ``l`` of a wheel order."""
        return np.array([1 if x == SLEEPER else int(x.rsplit("_", 1)[-1]) for x in self.labels], dtype=np.int64)

    @property
    def wheel_rows(self) -> np.ndarray:
        """Rows of the wheel orders, in the order of :attr:`wheel_orders`, int."""
        return np.array([i for i, x in enumerate(self.labels) if x.isdigit()], dtype=np.int64)

    # --- frequencies and bandwidths --------------------------------------------
    @property
    def bandwidth_floor(self) -> np.ndarray:
        """Lowest bandwidth of every order, Hz (its value at :attr:`floor_speed`)."""
        return self.bandwidth_per_speed * self.floor_speed

    def frequencies(self, speed: np.ndarray) -> OrderTrack:
        """Order frequencies over a speed signal, Hz (lazy ``(s, N)`` array).

        Parameters
        ----------
        speed : ndarray, shape (N,)
            Absolute speed, m/s.
        """
        return OrderTrack(speed, self.multipliers)

    def bandwidths(self, speed: np.ndarray) -> OrderTrack:
        """Order bandwidths over a speed signal, Hz (lazy ``(s, N)`` array).

        ``bandwidth_per_speed[n] × max(speed, floor_speed)``.

        Parameters
        ----------
        speed : ndarray, shape (N,)
            Absolute speed, m/s.
        """
        return OrderTrack(np.maximum(np.asarray(speed, dtype=np.float64), self.floor_speed),
                          self.bandwidth_per_speed)

    def bandwidth_range(self, v_min: float, v_max: float) -> tuple[float, float]:
        """(narrowest bandwidth at ``v_min``, widest at ``v_max``), Hz."""
        lo = self.bandwidth_per_speed * max(float(v_min), self.floor_speed)
        hi = self.bandwidth_per_speed * max(float(v_max), self.floor_speed)
        return float(lo.min()), float(hi.max())

    # --- phases and the solve ----------------------------------------------------
    def phase0(self, start_m: float = 0.0) -> np.ndarray:
        """Phase of every order at a start position ``start_m`` (m), rad."""
        return 2.0 * np.pi * self.multipliers * float(start_m)

    @property
    def stationary(self) -> np.ndarray:
        """Rows solved as stationary orders (bool, shape (s,)): the wheel orders inside a
        track order's band (:func:`in_band_wheel_orders`)."""
        rows = in_band_wheel_orders(self.labels, self.multipliers, self.bandwidth_per_speed)
        mask = np.zeros(len(self.labels), dtype=bool)
        mask[rows] = True
        return mask

    def solve(self, y: Any, fs: float, speed: np.ndarray, start_m: float = 0.0) -> VKFResult:
        """Extract the orders of a signal with the VKF (one unchunked solve).

        The wheel orders inside a track order's band are *stationary* orders of
        the engine (a wheel's out-of-roundness responds to the speed, not to the
        place: their envelopes are functions of frequency, see
        :mod:`app.analysis.vkf._stationary` and docs/indicator.md), so that they
        do not take the track orders' changes at their lines (issue 26).

        Parameters
        ----------
        y : array_like, shape (N,) or (channels, N)
            Axle-box acceleration (or force) of this wheel, m/s² (kN).
        fs : float
            Sample rate, Hz.
        speed : ndarray, shape (N,)
            Absolute speed, m/s.
        start_m : float
            Position of the first sample, m: the phase reference (see the
            module's phase convention).

        Returns
        -------
        VKFResult
            Envelopes of the orders (rows as :attr:`labels`); its ``close_orders`` name the
            pairs that came closer than their bandwidth.

        Warns
        -----
        VKFWarning
            If the solve is ill-conditioned. Orders closer than their bandwidth are the
            recipe's design (wide track orders beside narrow wheel orders; those that really
            collide are dropped, :func:`order_collisions`): that warning of the engine is not
            passed on (the pairs are in ``close_orders``).
        """
        stationary = self.stationary
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=CLOSE_ORDERS_MESSAGE, category=VKFWarning)
            return vkf(y, fs, self.frequencies(speed), self.bandwidths(speed), self.filter_order,
                       chunk_duration=np.inf, phase0=self.phase0(start_m),
                       stationary=stationary if stationary.any() else None)

    def order_phases(self, psi: np.ndarray) -> np.ndarray:
        """Phases of the orders, ``multipliers ⊗ psi``, rad, shape (s, len(psi))."""
        return np.multiply.outer(self.multipliers, psi)


def harmonic_label(h: int) -> str:
    """Label of the sleeper-passage harmonic ``h`` (1: :data:`SLEEPER`, 2: ``"sleeper_2"``, …)."""
    return SLEEPER if int(h) == 1 else f"{SLEEPER}_{int(h)}"


def track_bandwidth_per_speed(resolution_m: float, filter_order: int) -> float:
    """-3 dB bandwidth per unit speed that gives a track order a spatial resolution, Hz per m/s.

    For a stationary order the VKF is a zero-phase low-pass of the complex
    envelope, ``H(Δf) = 1 / (1 + (√2−1)(2Δf/B)^(2q))`` (B the full -3 dB
    bandwidth, ``|H(±B/2)| = 1/√2``; exact while B is far below the solve rate). Its step response rises from
    10 % to 90 % in ``Δt = c_q / B`` (:data:`STEP_WIDTH_FACTOR`), i.e. over
    ``Δx = v Δt = c_q v / B`` of track. A resolution ``Δx`` therefore needs
    ``B = c_q v / Δx``: a bandwidth proportional to speed, ``c_q / Δx`` Hz
    per m/s.

    Parameters
    ----------
    resolution_m : float
        10–90 % width of a step in the amplitude profile, m (> 0).
    filter_order : int
        q, 1–3.
    """
    if not (math.isfinite(resolution_m) and resolution_m > 0):
        raise ValueError(f"resolution_m must be > 0 m, got {resolution_m!r}")
    if filter_order not in STEP_WIDTH_FACTOR:
        raise ValueError(f"filter_order must be 1, 2 or 3, got {filter_order!r}")
    return STEP_WIDTH_FACTOR[filter_order] / float(resolution_m)


def order_bandwidths(
    labels: Sequence[str], wheel_diameter: float, settings: ProcessingSettings
) -> tuple[np.ndarray, float]:
    """The bandwidth rule of the order filters.

    Parameters
    ----------
    labels : sequence of str
        The tracked orders (:attr:`OrderRecipe.labels`).
    wheel_diameter : float
        d_w, m (> 0).
    settings : ProcessingSettings
        ``bandwidth_orders``, ``track_resolution_m``, ``filter_order``,
        ``min_speed_kmh``.

    Returns
    -------
    bandwidth_per_speed : ndarray, shape (len(labels),)
        Full -3 dB bandwidth per unit speed of every order, Hz per m/s: the
        wheel orders ``bandwidth_orders / (π d_w)`` (constant in wheel
        orders), the track orders :func:`track_bandwidth_per_speed` of
        ``track_resolution_m`` (the wheel orders' when it is None).
    floor_speed : float
        Speed below which the bandwidths keep their value, m/s:
        ``max(min_speed_kmh, 3.6)`` km/h, so that a slow or standing train
        still gives a finite filter.
    """
    wheel = float(settings.bandwidth_orders) / (math.pi * float(wheel_diameter))
    track = wheel
    if settings.track_resolution_m is not None:
        track = track_bandwidth_per_speed(float(settings.track_resolution_m), int(settings.filter_order))
    per_speed = np.array([wheel if x.isdigit() else track for x in labels], dtype=np.float64)
    return per_speed, max(float(settings.min_speed_kmh) / KMH_PER_MPS, 1.0)


def in_band_wheel_orders(labels: Sequence[str], multipliers: np.ndarray,
                         bandwidth_per_speed: np.ndarray) -> np.ndarray:
    """Rows of the wheel orders that lie inside a (wider) track order's band.

    A wheel order is inside the band of a track order when their frequencies
    are closer than the track order's full -3 dB bandwidth (both scale with
    speed, so this holds at every speed or at none): the track filter still
    passes ≥ 13 % there (q = 2). At the default 3 m resolution on 0.92 m wheels:
    wheel order 5 (0.18 orders from f_s), 9 and 10 (0.63 and 0.37 from 2·f_s);
    with ``track_resolution_m`` None (every order 0.1 orders wide): none.

    Parameters
    ----------
    labels : sequence of str
        Order labels (:attr:`OrderRecipe.labels`).
    multipliers, bandwidth_per_speed : ndarray, shape (s,)
        Hz per m/s.

    Returns
    -------
    ndarray of int
    """
    track = [i for i, x in enumerate(labels) if not x.isdigit()]
    rows = [j for j, x in enumerate(labels) if x.isdigit()
            and any(abs(float(multipliers[j]) - float(multipliers[i])) < float(bandwidth_per_speed[i])
                    and bandwidth_per_speed[i] > bandwidth_per_speed[j] for i in track)]
    return np.array(rows, dtype=np.int64)


def order_collisions(
    labels: Sequence[str], multipliers: np.ndarray, bandwidth_per_speed: np.ndarray
) -> tuple[set[str], list[str]]:
    """Orders that collide with another, and which of them to drop.

    Two orders collide when their frequencies lie closer than the narrower
    one's full -3 dB bandwidth (both scale with speed, so this holds at every
    speed or at none): the narrow filter then passes the other order's
    content too, and the coupled solve cannot tell them apart. A colliding
    sleeper harmonic is dropped; where the fundamental collides with a wheel
    order, the wheel order is dropped (the fundamental is the indicator).

    Parameters
    ----------
    labels : sequence of str
        Order labels (:attr:`OrderRecipe.labels`).
    multipliers, bandwidth_per_speed : ndarray, shape (s,)
        Hz per m/s.

    Returns
    -------
    dropped : set of str
        Labels to drop.
    notes : list of str
        One sentence per collision, for the job's warnings.
    """
    dropped: set[str] = set()
    notes: list[str] = []
    track = [i for i, x in enumerate(labels) if not x.isdigit()]
    wheel = [i for i, x in enumerate(labels) if x.isdigit()]
    for i in track:
        for j in wheel:
            gap = abs(float(multipliers[i]) - float(multipliers[j]))
            limit = min(float(bandwidth_per_speed[i]), float(bandwidth_per_speed[j]))
            if gap >= limit or labels[i] in dropped:
                continue
            gap_orders = gap * int(labels[j]) / float(multipliers[j])  # one wheel order: multiplier / l
            if labels[i] == SLEEPER:
                dropped.add(labels[j])
                notes.append(
                    f"the sleeper-passage order f_s lies {gap_orders:.3f} wheel orders from wheel order {labels[j]} "
                    f"(closer than the bandwidth): wheel order {labels[j]} is not extracted"
                )
            else:
                h = labels[i].rsplit("_", 1)[1]
                dropped.add(labels[i])
                notes.append(
                    f"the sleeper harmonic {h}·f_s lies {gap_orders:.3f} wheel orders from wheel order {labels[j]} "
                    f"(closer than the bandwidth): {h}·f_s is not extracted and the sleeper energy leaves it out"
                )
    return dropped, notes


def order_recipe(wheel_diameter: float, sleeper_spacing: float, settings: ProcessingSettings) -> OrderRecipe:
    """The recipe of a wheel of diameter d_w on sleepers spaced d_s.

    Parameters
    ----------
    wheel_diameter : float
        d_w, m (> 0).
    sleeper_spacing : float
        d_s, m (> 0).
    settings : ProcessingSettings
        ``n_wheel_orders``, ``sleeper_harmonics``, ``bandwidth_orders``,
        ``track_resolution_m``, ``filter_order``, ``min_speed_kmh``.

    Returns
    -------
    OrderRecipe
        The sleeper passage and its harmonics 2..``sleeper_harmonics``, then
        the wheel orders 1..n, the bandwidths of :func:`order_bandwidths`,
        less the orders :func:`order_collisions` drops (said in ``notes``).

    Raises
    ------
    ValueError
        If a length is not a finite number > 0.
    """
    d_w, d_s = float(wheel_diameter), float(sleeper_spacing)
    for name, value in (("wheel_diameter", d_w), ("sleeper_spacing", d_s)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be > 0 m, got {value!r}")
    n = int(settings.n_wheel_orders)
    n_h = int(settings.sleeper_harmonics)
    labels = (*[harmonic_label(h) for h in range(1, n_h + 1)], *[str(lvl) for lvl in range(1, n + 1)])
    wheel_mult = railway_multipliers(d_w, d_s, n)[1:]
    multipliers = np.concatenate([np.arange(1, n_h + 1) / d_s, wheel_mult])
    per_speed, floor_speed = order_bandwidths(labels, d_w, settings)
    dropped, notes = order_collisions(labels, multipliers, per_speed)
    keep = np.array([x not in dropped for x in labels])
    return OrderRecipe(
        wheel_diameter=d_w,
        sleeper_spacing=d_s,
        labels=tuple(x for x in labels if x not in dropped),
        multipliers=multipliers[keep],
        bandwidth_per_speed=per_speed[keep],
        floor_speed=floor_speed,
        filter_order=int(settings.filter_order),
        min_speed=float(settings.min_speed_kmh) / KMH_PER_MPS,
        notes=tuple(notes),
    )


def wheel_recipe(metadata: WheelGeometry, wheel: str, settings: ProcessingSettings) -> OrderRecipe:
    """The recipe of wheel ``wheel`` (``"11"`` … ``"42"``) of a run, from its metadata.

    Raises
    ------
    KeyError
        If the metadata hold no diameter of ``wheel``.
    """
    return order_recipe(float(metadata.wheel_diameters[wheel]), float(metadata.sleeper_spacing), settings)


def travel_phase(speed: np.ndarray, fs: float, start_m: float = 0.0) -> np.ndarray:
    """Phase per unit multiplier ``psi = 2π (start_m + Σ_{l≤k} |v_l| / fs)``, rad.

    Order ``n`` has the phase ``multipliers[n] × psi`` (see the module notes).

    Parameters
    ----------
    speed : ndarray, shape (N,)
        Absolute speed, m/s.
    fs : float
        Sample rate, Hz.
    start_m : float
        Position of the phase reference, m.
    """
    return 2.0 * np.pi * (float(start_m) + np.cumsum(speed) / fs)


def order_overlap(
    fs: float, speed: np.ndarray, recipes: Sequence[OrderRecipe], *, tol: float | None = None
) -> int:
    """Samples of signal the VKF of these recipes needs on each side of a stretch.

    Parameters
    ----------
    fs : float
        Sample rate, Hz.
    speed : array_like, shape (N,)
        Speed over (roughly) the stretch, m/s (its absolute value counts).
    recipes : sequence of OrderRecipe
        The wheels solved over the stretch; the overlap covers the highest
        order frequency of all of them and the bandwidths of the narrowest.
    tol : float, optional
        Neglected impulse-response tail (default: the engine's own, see
        :func:`app.analysis.vkf.vkf_overlap`); chunk seams use
        :data:`CHUNK_JOIN_TOL`.

    Returns
    -------
    int
        Overlap in samples.
    """
    if not recipes:
        raise ValueError("recipes must not be empty")
    v = np.abs(np.asarray(speed, dtype=np.float64))
    if v.size == 0:
        raise ValueError("speed must not be empty")
    v_min, v_max = float(v.min()), float(v.max())
    f_max = min(max(float(r.multipliers.max()) for r in recipes) * v_max, _F_MAX_OF_FS * fs)
    narrow = min(recipes, key=lambda r: float(r.bandwidth_per_speed.min()))
    bw_min, bw_max = narrow.bandwidth_range(v_min, v_max)
    extra = {} if tol is None else {"tol": tol}
    return vkf_overlap(fs, 0.0, f_max, bw_min, bw_max, narrow.filter_order, **extra)
