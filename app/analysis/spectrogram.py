"""Spectrograms of a short window of a run: raw ABA and the VKF-extracted orders.

Paper figure fig3: (a) the spectrogram of the raw axle-box acceleration with
the tracked order frequencies drawn over it, (b) the spectrogram of the sum of
the extracted components (sleeper passage and wheel orders 1..n), (c) the
speed. :func:`window_spectrograms` computes all three for one wheel channel.

The components are extracted with the processing pipeline's railway order
recipe (:mod:`app.analysis.recipe`: the same orders, bandwidths, filter order
and phase convention), phases referred to the first sample of the window.

Frequency resolution follows the speed: a window of ``revolutions`` wheel
revolutions gives a resolution of ``f_1 / revolutions`` (``f_1`` the first
wheel order at the mean speed), i.e. the same distance resolution at any speed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.signal import ShortTimeFFT, resample_poly
from scipy.signal.windows import hann

from app.analysis.recipe import order_overlap, order_recipe, travel_phase
from app.analysis.settings import N_, ProcessingSettings, SettingError
from app.analysis.units import KMH_PER_MPS

__all__ = [
    "Spectrogram",
    "WindowSpectrograms",
    "psd_spectrogram",
    "component_padding",
    "extract_components",
    "window_spectrograms",
]

#: dynamic range kept below the raw spectrogram's maximum, dB
DYNAMIC_RANGE_DB = 90.0
#: display band: this factor above the highest tracked order
_BAND_MARGIN = 1.25


@dataclass(frozen=True)
class Spectrogram:
    """Power spectral density over time.

    Attributes
    ----------
    time_s : ndarray, shape (m,)
        Frame centres, s from the first sample of the analysed signal.
    freq_hz : ndarray, shape (k,)
        Frequencies, Hz.
    psd : ndarray, shape (k, m)
        One-sided power spectral density, (m/s²)²/Hz.
    """

    time_s: np.ndarray
    freq_hz: np.ndarray
    psd: np.ndarray


@dataclass(frozen=True)
class WindowSpectrograms:
    """Raw and component spectrograms of one window with the order tracks.

    Attributes
    ----------
    time_s : ndarray, shape (m,)
        Frame centres, s from the window's first sample.
    frame_index : ndarray of int, shape (m,)
        Sample index (within the window) of every frame centre.
    freq_hz : ndarray, shape (k,)
        Frequencies, Hz (0 to the display band).
    raw_db, components_db : ndarray, shape (k, m)
        PSD in dB re 1 (m/s²)²/Hz; values below the raw maximum minus
        :data:`DYNAMIC_RANGE_DB` are clipped to that floor.
    speed : ndarray, shape (m,)
        Mean absolute speed over each frame, m/s.
    order_labels : list of str
        ``"sleeper"``, then ``"1"`` … ``"n"`` (wheel orders).
    order_freq_hz : ndarray, shape (n + 1, m)
        Frequency of every tracked order at the frame centres, Hz.
    resolution_hz : float
        Frequency resolution (bin spacing of the STFT), Hz.
    """

    time_s: np.ndarray
    frame_index: np.ndarray
    freq_hz: np.ndarray
    raw_db: np.ndarray
    components_db: np.ndarray
    speed: np.ndarray
    order_labels: list[str]
    order_freq_hz: np.ndarray
    resolution_hz: float


def _check_signal(y: np.ndarray, name: str) -> np.ndarray:
    a = np.asarray(y, dtype=np.float64)
    if a.ndim != 1:
        raise ValueError(f"{name} must be 1-D, got shape {a.shape}")
    return a


def psd_spectrogram(
    y: np.ndarray, fs: float, *, f_max: float, resolution_hz: float, overlap: float = 0.875
) -> Spectrogram:
    """Power spectral density of a signal over time (Hann-windowed STFT).

    The signal is first resampled (anti-aliased, polyphase) to the lowest rate
    of the form ``fs / k`` that still covers ``f_max``; only full frames are
    returned.

    Parameters
    ----------
    y : array_like, shape (N,)
        Signal, e.g. m/s². NaN is not allowed.
    fs : float
        Sample rate, Hz (> 0).
    f_max : float
        Highest frequency of interest, Hz, in (0, fs/2].
    resolution_hz : float
        Wanted frequency resolution, Hz (> 0): sets the frame length
        ``≈ fs / resolution_hz`` (capped at the signal length).
    overlap : float, optional
        Overlap of consecutive frames, fraction in [0, 1). Default 0.875.

    Returns
    -------
    Spectrogram
        Frequencies up to ``f_max``.

    Raises
    ------
    ValueError
        If an argument is out of range or the signal is shorter than 16 samples.
    """
    x = _check_signal(y, "y")
    if not (math.isfinite(fs) and fs > 0):
        raise ValueError(f"fs must be a finite number > 0 Hz, got {fs!r}")
    if not (math.isfinite(f_max) and 0 < f_max <= fs / 2):
        raise ValueError(f"f_max must be in (0, fs/2 = {fs / 2:g}] Hz, got {f_max!r}")
    if not (math.isfinite(resolution_hz) and resolution_hz > 0):
        raise ValueError(f"resolution_hz must be a finite number > 0 Hz, got {resolution_hz!r}")
    if not 0 <= overlap < 1:
        raise ValueError(f"overlap must be in [0, 1), got {overlap!r}")
    if x.size < 16:
        raise ValueError(f"y must hold at least 16 samples, got {x.size}")
    if not np.all(np.isfinite(x)):
        raise ValueError("y contains NaN or inf")
    down = max(1, int(fs // (2.5 * f_max)))
    if down > 1:
        x = resample_poly(x, 1, down)
    rate = fs / down
    nperseg = int(min(max(16, round(rate / resolution_hz)), x.size))
    hop = max(1, int(round(nperseg * (1.0 - overlap))))
    sft = ShortTimeFFT(hann(nperseg, sym=False), hop, rate, fft_mode="onesided2X", scale_to="psd")
    p0 = sft.lower_border_end[1]
    p1 = max(sft.upper_border_begin(x.size)[1], p0 + 1)
    psd = sft.spectrogram(x, p0=p0, p1=p1)
    times = sft.t(x.size, p0=p0, p1=p1)
    freqs = sft.f
    keep = freqs <= f_max
    return Spectrogram(time_s=np.asarray(times), freq_hz=freqs[keep], psd=psd[keep])


def component_padding(
    fs: float, speed: np.ndarray, wheel_diameter: float, sleeper_spacing: float,
    settings: ProcessingSettings,
) -> int:
    """Samples of signal the VKF needs on each side of a window for settled envelopes.

    Parameters
    ----------
    fs : float
        Sample rate, Hz.
    speed : array_like, shape (N,)
        Speed over (roughly) the window, m/s.
    wheel_diameter, sleeper_spacing : float
        d_w and d_s, m.
    settings : ProcessingSettings
        Orders, bandwidth and filter order.

    Returns
    -------
    int
        The filter's impulse-response length (see :func:`app.analysis.vkf.vkf_overlap`).
    """
    v = _check_signal(speed, "speed")
    return order_overlap(fs, v, [order_recipe(wheel_diameter, sleeper_spacing, settings)])


def extract_components(
    y: np.ndarray,
    fs: float,
    speed: np.ndarray,
    *,
    wheel_diameter: float,
    sleeper_spacing: float,
    settings: ProcessingSettings,
    out_index: np.ndarray | None = None,
) -> np.ndarray:
    """Sum of the VKF-extracted orders (sleeper passage + wheel orders) of a signal.

    Parameters
    ----------
    y : array_like, shape (N,)
        Axle-box acceleration, m/s².
    fs : float
        Sample rate, Hz.
    speed : array_like, shape (N,)
        Speed, m/s (its absolute value sets the order frequencies).
    wheel_diameter, sleeper_spacing : float
        d_w and d_s, m.
    settings : ProcessingSettings
        ``n_wheel_orders``, ``bandwidth_orders``, ``filter_order``, ``min_speed_kmh``.
    out_index : array_like of int, optional
        Samples at which to evaluate the sum (default: every sample). The sum
        is band-limited to the tracked orders, so a reduced rate above twice the
        highest order frequency loses nothing.

    Returns
    -------
    ndarray, shape (len(out_index),)
        Extracted signal, m/s²; 0 where the orders are not trackable
        (speed below ``min_speed_kmh``).
    """
    x = _check_signal(y, "y")
    v = np.abs(_check_signal(speed, "speed"))
    if v.shape != x.shape:
        raise ValueError(f"speed must have the shape of y {x.shape}, got {v.shape}")
    if x.size < 2:
        raise ValueError("y must hold at least 2 samples")
    idx = np.arange(x.size) if out_index is None else np.asarray(out_index, dtype=np.int64)
    if idx.ndim != 1 or (idx.size and (idx.min() < 0 or idx.max() >= x.size)):
        raise ValueError(f"out_index must be 1-D indices in [0, {x.size})")
    recipe = order_recipe(wheel_diameter, sleeper_spacing, settings)
    env = recipe.solve(x, fs, v).envelope_at(idx)  # (s, m), NaN where not trackable
    # the recipe's phase convention, referred to the first sample
    wave = (env * np.exp(1j * recipe.order_phases(travel_phase(v, fs)[idx]))).real
    moving = v[idx] >= settings.min_speed_kmh / KMH_PER_MPS
    wave[:, ~moving] = 0.0
    return np.nansum(wave, axis=0)


def _to_db(psd: np.ndarray, floor_db: float) -> np.ndarray:
    with np.errstate(divide="ignore"):
        db = 10.0 * np.log10(psd)
    return np.maximum(db, floor_db)


def window_spectrograms(
    y: np.ndarray,
    fs: float,
    speed: np.ndarray,
    *,
    core: tuple[int, int],
    wheel_diameter: float,
    sleeper_spacing: float,
    settings: ProcessingSettings,
    revolutions: float = 8.0,
) -> WindowSpectrograms:
    """Raw and component spectrograms of the window ``y[core[0]:core[1]]``.

    Parameters
    ----------
    y : array_like, shape (N,)
        Axle-box acceleration including padding on both sides of the window
        (see :func:`component_padding`), m/s².
    fs : float
        Sample rate, Hz.
    speed : array_like, shape (N,)
        Speed, m/s.
    core : (int, int)
        The window ``[start, stop)`` within ``y``; the padding outside it only
        settles the VKF.
    wheel_diameter, sleeper_spacing : float
        d_w and d_s, m.
    settings : ProcessingSettings
        Settings of the processing job (orders, bandwidth, filter order).
    revolutions : float, optional
        Wheel revolutions per STFT frame (frequency resolution ``f_1 / revolutions``).
        Default 8.

    Returns
    -------
    WindowSpectrograms

    Raises
    ------
    ValueError
        If the window is empty or too short, or the train does not move in it.
    """
    x = _check_signal(y, "y")
    v_all = np.abs(_check_signal(speed, "speed"))
    if v_all.shape != x.shape:
        raise ValueError(f"speed must have the shape of y {x.shape}, got {v_all.shape}")
    lo, hi = (int(core[0]), int(core[1]))
    if not 0 <= lo < hi <= x.size:
        raise ValueError(f"core must satisfy 0 <= start < stop <= {x.size}, got {core!r}")
    if not (math.isfinite(revolutions) and revolutions >= 1):
        raise ValueError(f"revolutions must be >= 1, got {revolutions!r}")
    if hi - lo < 64:
        raise ValueError(f"core must span at least 64 samples, got {hi - lo}")
    v = v_all[lo:hi]
    v_mean = float(v.mean())
    if v_mean < settings.min_speed_kmh / KMH_PER_MPS:
        raise SettingError("min_speed_kmh", N_("speed: the mean speed in the window ({mean:.1f} km/h) is below "
                                                "min_speed_kmh = {limit:g} km/h"),
                           mean=v_mean * KMH_PER_MPS, limit=settings.min_speed_kmh)
    recipe = order_recipe(wheel_diameter, sleeper_spacing, settings)
    mult = recipe.multipliers
    f_top = min(_BAND_MARGIN * float(mult.max()) * float(v.max()), 0.5 * fs)
    f1 = v_mean / (math.pi * wheel_diameter)
    resolution = f1 / revolutions

    raw = psd_spectrogram(x[lo:hi], fs, f_max=f_top, resolution_hz=resolution)
    # components on the grid the raw spectrogram uses after its resampling
    down = max(1, int(fs // (2.5 * f_top)))
    grid = np.arange(lo, hi, down)
    comp_signal = extract_components(
        x, fs, v_all, wheel_diameter=wheel_diameter, sleeper_spacing=sleeper_spacing,
        settings=settings, out_index=grid,
    )
    comp = psd_spectrogram(comp_signal, fs / down, f_max=f_top, resolution_hz=resolution)
    n = min(raw.time_s.size, comp.time_s.size)
    raw_psd, comp_psd = raw.psd[:, :n], comp.psd[: raw.freq_hz.size, :n]
    times = raw.time_s[:n]
    floor_db = float(10.0 * np.log10(max(float(np.max(raw_psd)), 1e-300))) - DYNAMIC_RANGE_DB
    frame_index = np.clip(np.round(times * fs).astype(np.int64), 0, hi - lo - 1)
    half = max(1, int(round(fs / resolution / 2)))  # half a frame, samples
    speed_frames = np.array(
        [float(v[max(0, i - half) : i + half + 1].mean()) for i in frame_index]
    )
    return WindowSpectrograms(
        time_s=times,
        frame_index=frame_index,
        freq_hz=raw.freq_hz,
        raw_db=_to_db(raw_psd, floor_db),
        components_db=_to_db(comp_psd, floor_db),
        speed=speed_frames,
        order_labels=list(recipe.labels),
        order_freq_hz=np.multiply.outer(mult, speed_frames),
        resolution_hz=float(raw.freq_hz[1] - raw.freq_hz[0]) if raw.freq_hz.size > 1 else resolution,
    )
