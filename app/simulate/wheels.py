"""Wheel out-of-roundness (OOR): profiles and the axle-box acceleration they cause.

Phase convention
----------------
The wheel angle is ``theta = 2 s / d_w`` (rad) with ``s`` the distance (m) the
wheel has travelled since the start of the run and ``d_w`` its diameter. The
radius of the wheel at the point that touches the rail at angle ``theta`` is::

    r(theta) = d_w / 2 + sum_l rho_l cos(l theta + psi_l),   l = 1 … 11

Rigid contact on a straight, smooth rail lifts the axle box by
``z = r(theta(t)) - d_w / 2`` (z upward). With ``Omega = dtheta/dt = 2 v / d_w``
and ``dOmega/dt = 2 a / d_w`` (``a`` the longitudinal acceleration)::

    z''(t) = - sum_l rho_l [ (l Omega)^2 cos(l theta + psi_l)
                             + l (dOmega/dt) sin(l theta + psi_l) ]

The first term dominates (the second is below 0.5 % of it for |a| <= 1 m/s²
above 40 km/h), so order ``l`` appears in the acceleration as
``rho_l * omega_l^2 * cos(l theta + psi_l + pi)`` with ``omega_l = 2 l v / d_w``:
amplitude ``rho_l omega_l^2`` and phase ``psi_l + pi`` against the carrier
``l theta``. A pipeline that tracks order ``l`` with carrier ``l theta`` and
finds the complex envelope ``A e^{j phi}`` recovers ``rho_l = A / omega_l^2``
and ``psi_l = phi - pi``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["N_ORDERS", "WheelFlat", "WheelOOR", "random_wheel_oor", "oor_acceleration"]

#: Number of OOR orders simulated.
N_ORDERS = 11


@dataclass(frozen=True)
class WheelFlat:
    """A (rounded) wheel flat: a dip of the tread, met once per revolution.

    The tread drops by ``depth_m / 2 * (1 + cos(2 pi u / length_m))`` over
    ``|u| < length_m / 2``, ``u`` the arc length (m) from the flat's centre.
    A fresh flat of chord ``L`` on a wheel of radius ``R`` is ``L² / (8 R)``
    deep; rolled over, its edges round off and ``L² / (16 R)`` is the usual
    model of its depth (40 mm on a 0.92 m wheel: 0.22 mm).

    Attributes
    ----------
    length_m : float
        Length along the circumference, m (default 40 mm).
    depth_m : float
        Depth, m (default 0.2 mm).
    angle_rad : float
        Where the centre lies on the circumference: the wheel angle
        ``theta = 2 s / d_w`` (the OOR phase convention, module docstring) at
        which the flat's centre touches the rail, rad in [0, 2 pi).
    """

    length_m: float = 0.04
    depth_m: float = 0.2e-3
    angle_rad: float = 0.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.length_m) and 0.005 <= self.length_m <= 0.2):
            raise ValueError(f"length_m: must be within 5 … 200 mm, got {self.length_m!r}")
        if not (np.isfinite(self.depth_m) and 0 < self.depth_m <= 5e-3):
            raise ValueError(f"depth_m: must be within (0, 5] mm, got {self.depth_m!r}")
        if not np.isfinite(self.angle_rad):
            raise ValueError(f"angle_rad: must be finite, got {self.angle_rad!r}")
        object.__setattr__(self, "angle_rad", float(self.angle_rad) % (2 * np.pi))

    def height(self, s: np.ndarray, diameter_m: float) -> np.ndarray:
        """Tread height at the contact (m, <= 0) when the wheel has rolled ``s`` m since the run start."""
        circ = np.pi * diameter_m
        u = np.asarray(s, dtype=np.float64) - self.angle_rad * diameter_m / 2.0
        u = (u + 0.5 * circ) % circ - 0.5 * circ  # arc length from the centre, (-circ/2, circ/2]
        inside = np.abs(u) < 0.5 * self.length_m
        return np.where(inside, -0.5 * self.depth_m * (1.0 + np.cos(2 * np.pi * u / self.length_m)), 0.0)


@dataclass(frozen=True)
class WheelOOR:
    """OOR of one wheel.

    Attributes
    ----------
    wheel : str
        Wheel id (``"11"`` …).
    diameter_m : float
        True mean diameter, m.
    rho_um : numpy.ndarray
        Radius deviation per order ``l = 1 … len(rho_um)``, µm.
    psi_rad : numpy.ndarray
        Phase per order, rad (convention in the module docstring).
    flat : WheelFlat or None
        A wheel flat (an isolated dip of the tread), if any.
    """

    wheel: str
    diameter_m: float
    rho_um: np.ndarray
    psi_rad: np.ndarray
    flat: WheelFlat | None = None

    def __post_init__(self) -> None:
        if self.rho_um.shape != self.psi_rad.shape or self.rho_um.ndim != 1:
            raise ValueError("rho_um and psi_rad must be 1-D arrays of equal length")
        if not (0.3 < self.diameter_m < 1.5):
            raise ValueError(f"diameter_m must be in (0.3, 1.5) m, got {self.diameter_m!r}")

    @property
    def orders(self) -> np.ndarray:
        """Orders ``1 … L``."""
        return np.arange(1, self.rho_um.size + 1)

    def radius(self, theta: np.ndarray) -> np.ndarray:
        """Radius ``r(theta)`` at wheel angles ``theta`` (rad), m."""
        theta = np.asarray(theta, dtype=np.float64)
        r = np.full(theta.shape, self.diameter_m / 2.0)
        for order, rho, psi in zip(self.orders, self.rho_um, self.psi_rad, strict=True):
            r += rho * 1e-6 * np.cos(order * theta + psi)
        return r

    def acceleration_amplitude(self, speed_mps: float) -> np.ndarray:
        """``rho_l * omega_l^2`` per order at a speed (m/s), m/s²."""
        omega = 2.0 * self.orders * speed_mps / self.diameter_m
        return self.rho_um * 1e-6 * omega**2


def random_wheel_oor(rng: np.random.Generator, wheel: str, diameter_m: float) -> WheelOOR:
    """A plausible random OOR of a wheel in service.

    ``rho_l = rho_1 * l**(-beta) * lognormal(0, 0.35)`` with ``rho_1`` in
    60 … 250 µm and ``beta`` in 1.5 … 2.0, plus one polygon order (3 … 8) raised
    to 15 … 50 µm; clipped to 1 … 400 µm. Phases uniform in [0, 2 pi).
    """
    orders = np.arange(1, N_ORDERS + 1)
    rho1 = rng.uniform(60.0, 250.0)
    beta = rng.uniform(1.5, 2.0)
    rho = rho1 * orders ** (-beta) * rng.lognormal(0.0, 0.35, N_ORDERS)
    poly = int(rng.integers(3, 9))
    rho[poly - 1] = max(rho[poly - 1], rng.uniform(15.0, 50.0))
    rho = np.clip(rho, 1.0, 400.0)
    psi = rng.uniform(0.0, 2 * np.pi, N_ORDERS)
    return WheelOOR(wheel, float(diameter_m), rho, psi)


def oor_acceleration(oor: WheelOOR, s: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Vertical axle-box acceleration caused by OOR, m/s² (upward positive).

    Parameters
    ----------
    oor : WheelOOR
        The wheel.
    s : numpy.ndarray
        Distance travelled since the run start, m.
    v : numpy.ndarray
        Speed, m/s.
    a : numpy.ndarray
        Longitudinal acceleration, m/s².

    Returns
    -------
    numpy.ndarray
        ``z''`` of the module docstring.
    """
    d = oor.diameter_m
    theta = 2.0 * np.asarray(s, dtype=np.float64) / d
    omega = 2.0 * np.asarray(v, dtype=np.float64) / d
    omega_dot = 2.0 * np.asarray(a, dtype=np.float64) / d
    z = np.exp(1j * theta)
    c = oor.rho_um * 1e-6 * np.exp(1j * oor.psi_rad)
    orders = oor.orders.astype(np.float64)
    b1 = orders * c  # P1 = sum l c_l z^l
    b2 = orders**2 * c  # P2 = sum l^2 c_l z^l
    p1 = np.full(z.shape, b1[-1], dtype=np.complex128)
    p2 = np.full(z.shape, b2[-1], dtype=np.complex128)
    for k in range(len(orders) - 2, -1, -1):  # Horner
        p1 = p1 * z + b1[k]
        p2 = p2 * z + b2[k]
    p1 *= z
    p2 *= z
    return -(omega**2) * p2.real - omega_dot * p1.imag
