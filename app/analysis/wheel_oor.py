r"""Wheel out-of-roundness (OOR) from the envelopes of the wheel orders.

Conventions
-----------
* Wheel angle ``theta = 2 * s / d_w`` (rad), with ``s`` the distance travelled
  by the wheel since the start of the run (m) and ``d_w`` the wheel diameter (m).
* Wheel radius (paper Eq. 27, label ``eq:27``)::

      r(theta) = d_w / 2 + sum_l rho_l * cos(l * theta + psi_l)

  with ``rho_l`` the radius deviation amplitude of order ``l`` (µm here) and
  ``psi_l`` its phase (rad). The radius phasor of order ``l`` is
  ``rho_l * exp(1j * psi_l)``.
* Z is positive upward; the axle rises by the radius deviation at the contact
  point, so the OOR axle-box acceleration is
  ``d²/dt² sum_l rho_l cos(l theta + psi_l) ≈ sum_l rho_l omega_l² cos(l theta + psi_l + pi)``
  with ``omega_l = 2 * l * v / d_w`` (rad/s) and ``v`` the speed (m/s); the terms
  from the change of speed are neglected.
* The VKF phase of wheel order ``l`` is ``phi_l = 2 pi ∫ l v / (pi d_w) dt = l * theta``
  and the VKF envelope ``e_l`` (complex, m/s²) satisfies
  ``waveform = Re(e_l * exp(1j * phi_l))``. Hence
  ``rho_l * exp(1j * psi_l) = -e_l / omega_l²``.
* Diameter drift: the wheel angle is only known through ``d_w``. If the true
  diameter is ``d = d_w (1 + delta)``, the envelope phase of order ``l`` drifts
  as ``2 l s (1/d - 1/d_w) ≈ -l * delta * theta``; :func:`refine_diameter`
  estimates ``d`` from that drift and :func:`apply_diameter_correction` removes
  it (and rescales ``omega_l²``) so that the phases refer to the true wheel angle.

Typical use (per wheel)::

    rho = radius_phasor(envelope, speed, d_w, orders)            # (L, n) µm
    win, centres = window_means(rho, distance, window_m=10.0)     # (L, W)
    d = refine_diameter(win, centres, d_w, order=orders)
    win = apply_diameter_correction(win, centres, orders, d_w, d)
    summary = summarize_oor(win, orders)
"""

from __future__ import annotations

import warnings

import numpy as np

from app.analysis._checks import positive_float

__all__ = [
    "apply_diameter_correction",
    "radius_phasor",
    "reconstruct_profile",
    "refine_diameter",
    "summarize_oor",
    "window_means",
]

_MAX_DIAMETER_CORRECTION = 0.05


def _check_orders(orders: object, n_rows: int | None = None, name: str = "orders") -> np.ndarray:
    arr = np.asarray(orders)
    if arr.ndim != 1 or arr.size == 0:
        raise ValueError(f"{name} must be a non-empty 1-D array of ints, got shape {arr.shape}")
    if not np.issubdtype(arr.dtype, np.integer):
        if not np.issubdtype(arr.dtype, np.floating) or not np.all(arr == np.round(arr)):
            raise ValueError(f"{name} must hold integers, got {arr!r}")
    arr = arr.astype(np.int64)
    if np.any(arr < 1):
        raise ValueError(f"{name} must be >= 1, got {arr.tolist()}")
    if n_rows is not None and arr.size != n_rows:
        raise ValueError(f"{name} must have {n_rows} entries (one per row), got {arr.size}")
    return arr


def _check_diameter(d: object, name: str) -> float:
    return positive_float(d, name, number="a number (m)", positive="a finite diameter > 0 m")


def _orders_by(values: object, name: str, columns: str) -> np.ndarray:
    """``values`` as a complex (orders, ``columns``) array; ValueError unless 2-D."""
    x = np.asarray(values)
    if x.ndim != 2:
        raise ValueError(f"{name} must be 2-D (orders, {columns}), got shape {x.shape}")
    return x.astype(np.complex128, copy=False)


def _along(values: object, name: str, n: int, like: str | None = None) -> np.ndarray:
    """``values`` as a float64 (n,) array (one value per column of the array named ``like``)."""
    x = np.asarray(values, dtype=np.float64)
    if x.shape != (n,):
        ref = f" like {like}" if like else ""
        raise ValueError(f"{name} must have shape {(n,)}{ref}, got {x.shape}")
    return x


def _check_n_angles(n_angles: int) -> int:
    if isinstance(n_angles, bool) or int(n_angles) != n_angles or n_angles < 1:
        raise ValueError(f"n_angles must be a positive integer, got {n_angles!r}")
    return int(n_angles)


def radius_phasor(
    envelope: np.ndarray,
    speed: np.ndarray,
    wheel_diameter: float,
    orders: np.ndarray,
) -> np.ndarray:
    """Radius phasors of the wheel orders from their VKF envelopes.

    Parameters
    ----------
    envelope : array_like, complex
        (L, n) VKF envelopes of wheel orders ``orders`` (m/s²), such that the
        order's waveform is ``Re(envelope * exp(1j * l * theta))``.
    speed : array_like
        (n,) speed, m/s.
    wheel_diameter : float
        Wheel diameter ``d_w`` used for the order frequencies, m.
    orders : array_like of int
        (L,) wheel order numbers ``l`` (>= 1).

    Returns
    -------
    numpy.ndarray
        (L, n) complex radius phasors ``rho_l exp(1j psi_l) = -e_l / omega_l²`` in µm,
        ``omega_l = 2 l v / d_w``; NaN where ``speed <= 0`` or not finite.

    Raises
    ------
    ValueError
        If shapes disagree, ``wheel_diameter`` is not positive or ``orders`` are
        not positive integers.
    """
    e = _orders_by(envelope, "envelope", "samples")
    v = _along(speed, "speed", e.shape[1], like="envelope")
    d = _check_diameter(wheel_diameter, "wheel_diameter")
    ords = _check_orders(orders, e.shape[0])
    moving = np.isfinite(v) & (v > 0)
    v_safe = np.where(moving, v, 1.0)
    omega = 2.0 * ords[:, None] * v_safe[None, :] / d  # rad/s
    rho = -e / omega**2 * 1e6  # µm
    rho[:, ~moving] = np.nan + 1j * np.nan
    return rho


def window_means(
    values: np.ndarray,
    distance_m: np.ndarray,
    window_m: float,
    weight: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """NaN-aware (weighted) means of complex values over distance windows.

    Window ``i`` holds the samples with ``floor(distance_m / window_m) == i``, so
    windows of different chunks of one run line up.

    Parameters
    ----------
    values : array_like, complex
        (L, n) values per order (e.g. radius phasors, µm).
    distance_m : array_like
        (n,) distance travelled since the run start, m (finite).
    window_m : float
        Window length, m (> 0).
    weight : array_like, optional
        (n,) sample weights >= 0 (e.g. crossfade weights or a speed mask);
        samples with weight 0 are ignored. Default: all 1.

    Returns
    -------
    windows : numpy.ndarray
        (L, W) complex weighted mean per order and window, over the samples where
        the value is finite; NaN where a window has none. Only windows holding at
        least one sample with weight > 0 are returned, in increasing distance.
    window_centres_m : numpy.ndarray
        (W,) window centres ``(i + 0.5) * window_m``, m.

    Raises
    ------
    ValueError
        If shapes disagree, ``distance_m`` or ``weight`` is not finite, ``weight``
        is negative or ``window_m`` is not positive.
    """
    x = _orders_by(values, "values", "samples")
    n = x.shape[1]
    s = _along(distance_m, "distance_m", n, like="values")
    if not np.all(np.isfinite(s)):
        raise ValueError("distance_m must be finite (found NaN or inf)")
    wm = positive_float(window_m, "window_m", number="a number (m)", positive="a finite length > 0 m")
    if weight is None:
        w = np.ones(n)
    else:
        w = _along(weight, "weight", n, like="values")
        if not np.all(np.isfinite(w)) or np.any(w < 0):
            raise ValueError("weight must be finite and >= 0")

    used = w > 0
    idx = np.floor(s[used] / wm).astype(np.int64)
    ub, inv = np.unique(idx, return_inverse=True)
    inv = inv.reshape(-1)
    nw = ub.size
    xu = x[:, used]
    wu = w[used]
    out = np.full((x.shape[0], nw), np.nan + 1j * np.nan)
    for i in range(x.shape[0]):
        finite = np.isfinite(xu[i])
        wf = np.where(finite, wu, 0.0)
        xf = np.where(finite, xu[i], 0.0)
        sw = np.bincount(inv, weights=wf, minlength=nw)
        sr = np.bincount(inv, weights=wf * xf.real, minlength=nw)
        si = np.bincount(inv, weights=wf * xf.imag, minlength=nw)
        ok = sw > 0
        out[i, ok] = (sr[ok] + 1j * si[ok]) / sw[ok]
    return out, (ub + 0.5) * wm


def _wrap(phase: np.ndarray) -> np.ndarray:
    return (phase + np.pi) % (2.0 * np.pi) - np.pi


def _weighted_line(s: np.ndarray, p: np.ndarray, w: np.ndarray) -> tuple[float, float, float]:
    """Weighted LS fit ``p ≈ a + b s``; returns (a, b, standard error of b)."""
    sw = w.sum()
    s_mean = (w * s).sum() / sw
    p_mean = (w * p).sum() / sw
    ds = s - s_mean
    sxx = (w * ds * ds).sum()
    b = (w * ds * (p - p_mean)).sum() / sxx
    a = p_mean - b * s_mean
    r = p - (a + b * s)
    dof = max(s.size - 2, 1)
    se = float(np.sqrt((w * r * r).sum() / dof / sxx))
    return float(a), float(b), se


def _drift_rate(s_ok: np.ndarray, z_ok: np.ndarray, w: np.ndarray) -> tuple[float, float, float]:
    """Phase drift rate (rad/m) of sorted window phasors; returns (k, se, coherence)."""
    # Coarse-to-fine drift rate: lag-m products of window phasors (m = 1, 4, 16, ...),
    # each on the demodulated phasors of the previous step, so no sequential
    # unwrapping of noisy phases is needed and gaps between windows do no harm.
    ds = np.diff(s_ok)
    base = float(ds[ds > 0].min()) if np.any(ds > 0) else 0.0
    k = 0.0
    if base > 0:
        # windows sit on a grid of the smallest spacing; pair them by grid distance
        grid = np.rint((s_ok - s_ok[0]) / base).astype(np.int64)
        m = 1
        while m <= grid[-1]:
            j = np.searchsorted(grid, grid + m)
            pair = j < grid.size
            pair[pair] = grid[j[pair]] == grid[pair] + m
            if pair.sum() >= 2:
                i_a, i_b = np.flatnonzero(pair), j[pair]
                u = z_ok * np.exp(-1j * k * s_ok)
                lag = np.sum(u[i_b] * np.conj(u[i_a]))
                if lag != 0:
                    k += float(np.angle(lag) / np.mean(s_ok[i_b] - s_ok[i_a]))
            m *= 4

    # Fine: weighted LS of the residual phase (wrapped around the fitted line).
    a = float(np.angle(np.sum(w * np.exp(1j * (np.angle(z_ok) - k * s_ok)))))
    b, se = 0.0, np.inf
    for _ in range(3):
        line = a + k * s_ok
        resid = _wrap(np.angle(z_ok) - line)
        da, b, se = _weighted_line(s_ok, resid, w)
        a += da
        k += b
    resid = _wrap(np.angle(z_ok) - (a + k * s_ok))
    coherence = float(np.abs(np.sum(w * np.exp(1j * resid))) / np.sum(w))
    return k, se, coherence


def refine_diameter(
    window_phasors: np.ndarray,
    window_centres_m: np.ndarray,
    nominal_diameter: float,
    order: int | np.ndarray = 1,
    *,
    min_windows: int = 5,
    amplitude_fraction: float = 0.5,
    significance: float = 3.0,
    min_coherence: float = 0.5,
) -> float:
    """Estimate the wheel diameter from the phase drift of the strongest order.

    If the true diameter is ``d`` and the envelopes were computed with the
    nominal ``d_w``, the phase of order ``l`` drifts with distance at
    ``k = 2 l (1/d - 1/d_w)`` rad/m (≈ ``-l delta theta`` for ``d = d_w (1 + delta)``).
    The strongest order (largest median |phasor|) is used; windows with
    ``|phasor| >= amplitude_fraction * median`` enter a weighted (|phasor|²)
    least-squares fit of the unwrapped phase against distance. The phase is
    unwrapped against a drift rate estimated coarse-to-fine from products of
    windows 1, 4, 16, ... windows apart, so noisy windows and gaps do not
    cause 2 pi slips. The rate must stay below ``pi / window spacing``
    (``2 l |delta| spacing / d_w < pi``: windows of 10 m allow |delta| up to
    ~14 % / l).

    Parameters
    ----------
    window_phasors : array_like, complex
        (L, W) window-mean radius phasors (µm) of the wheel orders, or (W,) for one order.
    window_centres_m : array_like
        (W,) window positions (distance since the run start), m.
    nominal_diameter : float
        Diameter used to compute the envelopes, m.
    order : int or array_like of int, optional
        Order numbers of the rows: an array (L,), or an int ``l0`` meaning rows are
        orders ``l0, l0 + 1, ...`` (default 1: rows are orders 1..L).
    min_windows : int, optional
        Minimum number of usable windows (default 5).
    amplitude_fraction : float, optional
        Windows weaker than this fraction of the order's median amplitude are
        left out (default 0.5).
    significance : float, optional
        The drift must exceed this many standard errors to be applied (default 3).
    min_coherence : float, optional
        Minimum phase coherence ``|sum w exp(j r)| / sum w`` of the residual phases
        ``r`` about the fitted line (1 = all windows on the line, ~0 = random
        phases); below it the data carry no usable phase and the nominal diameter
        is returned (default 0.5).

    Returns
    -------
    float
        The corrected diameter, m, clipped to ±5 % of ``nominal_diameter``; the
        nominal diameter if there are too few usable windows or the drift is
        not significant.

    Raises
    ------
    ValueError
        If shapes disagree or an argument is out of range.
    """
    p = np.asarray(window_phasors)
    if p.ndim == 1:
        p = p[None, :]
    if p.ndim != 2:
        raise ValueError(f"window_phasors must be 1-D or 2-D, got shape {p.shape}")
    p = p.astype(np.complex128, copy=False)
    n_rows, n_win = p.shape
    s = _along(window_centres_m, "window_centres_m", n_win)
    if not np.all(np.isfinite(s)):
        raise ValueError("window_centres_m must be finite")
    d0 = _check_diameter(nominal_diameter, "nominal_diameter")
    if np.ndim(order) == 0:
        ords = _check_orders([order], name="order")[0] + np.arange(n_rows, dtype=np.int64)
    else:
        ords = _check_orders(order, n_rows, name="order")
    if int(min_windows) < 3:
        raise ValueError(f"min_windows must be >= 3, got {min_windows!r}")
    if not 0 <= float(amplitude_fraction) < 1:
        raise ValueError(f"amplitude_fraction must be in [0, 1), got {amplitude_fraction!r}")
    if not float(significance) >= 0:
        raise ValueError(f"significance must be >= 0, got {significance!r}")
    if not 0 <= float(min_coherence) <= 1:
        raise ValueError(f"min_coherence must be in [0, 1], got {min_coherence!r}")

    amp = np.abs(p)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        med = np.nanmedian(amp, axis=1) if n_win else np.full(n_rows, np.nan)
    if not np.any(np.isfinite(med) & (med > 0)):
        return d0
    row = int(np.nanargmax(np.where(np.isfinite(med), med, -np.inf)))
    l_ref = int(ords[row])
    z = p[row]
    ok = np.isfinite(z) & (amp[row] >= amplitude_fraction * med[row]) & (amp[row] > 0)
    if ok.sum() < int(min_windows):
        return d0
    srt = np.argsort(s[ok], kind="stable")
    s_ok = s[ok][srt]
    z_ok = z[ok][srt]
    if np.ptp(s_ok) <= 0:
        return d0
    w = np.abs(z_ok) ** 2
    w = w / w.max()

    k, se, coherence = _drift_rate(s_ok, z_ok, w)
    if (
        not np.isfinite(k)
        or coherence < float(min_coherence)
        or abs(k) < float(significance) * se
        or k == 0
    ):
        return d0
    inv_d = k / (2.0 * l_ref) + 1.0 / d0
    lo, hi = d0 * (1 - _MAX_DIAMETER_CORRECTION), d0 * (1 + _MAX_DIAMETER_CORRECTION)
    if inv_d <= 0:
        return hi
    return float(np.clip(1.0 / inv_d, lo, hi))


def apply_diameter_correction(
    window_phasors: np.ndarray,
    window_centres_m: np.ndarray,
    orders: np.ndarray,
    nominal_diameter: float,
    corrected_diameter: float,
) -> np.ndarray:
    """Refer window radius phasors computed with ``nominal_diameter`` to the corrected one.

    Removes the phase drift ``2 l s (1/d - 1/d_w)`` and rescales the amplitude
    by ``(d / d_w)²`` (``omega_l²`` was computed with ``d_w``).

    Parameters
    ----------
    window_phasors : array_like, complex
        (L, W) window-mean radius phasors, µm.
    window_centres_m : array_like
        (W,) window positions (distance since the run start), m.
    orders : array_like of int
        (L,) order numbers of the rows.
    nominal_diameter, corrected_diameter : float
        Diameters ``d_w`` (used so far) and ``d`` (corrected), m.

    Returns
    -------
    numpy.ndarray
        (L, W) complex radius phasors referred to the wheel angle ``2 s / d``, µm.
    """
    p = _orders_by(window_phasors, "window_phasors", "windows")
    s = _along(window_centres_m, "window_centres_m", p.shape[1])
    ords = _check_orders(orders, p.shape[0])
    d0 = _check_diameter(nominal_diameter, "nominal_diameter")
    d1 = _check_diameter(corrected_diameter, "corrected_diameter")
    k = 2.0 * ords[:, None] * (1.0 / d1 - 1.0 / d0)
    return p * (d1 / d0) ** 2 * np.exp(-1j * k * s[None, :])


def reconstruct_profile(phasors: np.ndarray, orders: np.ndarray, n_angles: int = 360) -> np.ndarray:
    """Radius deviation around the wheel from its order phasors.

    Parameters
    ----------
    phasors : array_like, complex
        (L,) radius phasors ``rho_l exp(1j psi_l)``, µm, or (L, ...) for several
        profiles at once.
    orders : array_like of int
        (L,) order numbers ``l``.
    n_angles : int, optional
        Number of angles ``theta = 2 pi k / n_angles``, k = 0..n_angles-1 (default 360).

    Returns
    -------
    numpy.ndarray
        (n_angles,) (or (..., n_angles)) ``sum_l Re(rho_l exp(1j (l theta + psi_l)))``, µm.
        NaN phasors propagate.
    """
    p = np.asarray(phasors)
    if p.ndim < 1:
        raise ValueError("phasors must have at least 1 dimension (orders first)")
    p = p.astype(np.complex128, copy=False)
    ords = _check_orders(orders, p.shape[0])
    n_angles = _check_n_angles(n_angles)
    theta = 2.0 * np.pi * np.arange(n_angles) / n_angles
    basis = np.exp(1j * ords[:, None] * theta[None, :])  # (L, A)
    return np.real(np.tensordot(p, basis, axes=([0], [0])))


def summarize_oor(window_phasors: np.ndarray, orders: np.ndarray, n_angles: int = 360) -> dict:
    """Summary of a wheel's OOR over windows (JSON-ready: lists and floats).

    Only windows where every order is finite are used.

    Parameters
    ----------
    window_phasors : array_like, complex
        (L, W) window radius phasors, µm (after any diameter correction).
    orders : array_like of int
        (L,) order numbers.
    n_angles : int, optional
        Number of profile angles (default 360).

    Returns
    -------
    dict
        ``n_windows`` (int); ``orders``: list of ``{order, radius_um, radius_um_p05,
        radius_um_p95, phase_rad}`` (median, 5th and 95th percentile of |phasor| over
        windows, µm; angle of the complex mean over windows, rad); ``angles_deg``
        (n_angles floats); ``profile_um`` (profile of the complex-mean phasors, µm);
        ``profile_p05_um`` / ``profile_p95_um`` (per-angle 5th / 95th percentile of
        the per-window profiles, µm). Values are NaN when there is no usable window.
    """
    p = _orders_by(window_phasors, "window_phasors", "windows")
    ords = _check_orders(orders, p.shape[0])
    n_angles = _check_n_angles(n_angles)
    usable = np.all(np.isfinite(p), axis=0)
    q = p[:, usable]
    n_w = int(q.shape[1])
    angles = (360.0 * np.arange(n_angles) / n_angles).tolist()
    if n_w == 0:
        nan_list = [float("nan")] * n_angles
        return {
            "n_windows": 0,
            "orders": [
                {
                    "order": int(o),
                    "radius_um": float("nan"),
                    "radius_um_p05": float("nan"),
                    "radius_um_p95": float("nan"),
                    "phase_rad": float("nan"),
                }
                for o in ords
            ],
            "angles_deg": angles,
            "profile_um": list(nan_list),
            "profile_p05_um": list(nan_list),
            "profile_p95_um": list(nan_list),
        }
    amp = np.abs(q)
    mean = q.mean(axis=1)
    per_window = reconstruct_profile(q, ords, n_angles)  # (W, A)
    order_rows = [
        {
            "order": int(o),
            "radius_um": float(np.median(amp[i])),
            "radius_um_p05": float(np.percentile(amp[i], 5)),
            "radius_um_p95": float(np.percentile(amp[i], 95)),
            "phase_rad": float(np.angle(mean[i])),
        }
        for i, o in enumerate(ords)
    ]
    return {
        "n_windows": n_w,
        "orders": order_rows,
        "angles_deg": angles,
        "profile_um": reconstruct_profile(mean, ords, n_angles).tolist(),
        "profile_p05_um": np.percentile(per_window, 5, axis=0).tolist(),
        "profile_p95_um": np.percentile(per_window, 95, axis=0).tolist(),
    }
