"""Processing settings of a run: the parameters that decide orders, bandwidth and binning.

A :class:`ProcessingSettings` object is stored with every processing job; the
worker, the ``process`` command and the API all read the orders, bandwidth and
binning from it (the railway order recipe, :mod:`app.analysis.recipe`, turns
them into the orders and bandwidths of a wheel), so every stored number can be
traced back to the settings that produced it.

The dataclass is the one description of the settings: each field's metadata
(:func:`setting_help`) carries its short help and range, from which the API's
request schema (:mod:`app.api.schemas.jobs`) and the ``process`` command's
options (:mod:`app.cli.processing`) are derived; the ranges are checked in
``__post_init__``.

Settings stored by older versions lack the keys added since; they must still
mean what they meant then. :meth:`ProcessingSettings.from_stored` reads a
stored dict and fills a missing key with its **legacy** value
(:data:`LEGACY_VALUES`: track orders as narrow as the wheel orders, no sleeper
harmonics, no static load removed), whereas :meth:`ProcessingSettings.from_dict`
(a new request) fills it with today's default.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

from app.analysis.units import MIN_SPEED_KMH

__all__ = ["ProcessingSettings", "SettingError", "LEGACY_VALUES", "MAX_SLEEPER_HARMONIC", "MAX_WHEEL_ORDERS",
           "setting_help"]


def N_(message: str) -> str:
    """Mark ``message`` for the service's catalogues (what ``app.core.i18n.N_`` does; the analysis
    imports nothing of the service): the service answers a :class:`SettingError` in the reader's language."""
    return message


class SettingError(ValueError):
    """A processing setting out of its range.

    Parameters
    ----------
    setting : str
        The setting at fault (``"settings"`` for the request as a whole).
    message : str
        The English text with ``str.format`` fields, marked with :func:`N_` (its message id).
    **params
        The values of the fields.

    Notes
    -----
    ``str(error)`` is the message with its values (``"bin_length_m must be in [0.05, 10] m, got 20"``).
    """

    def __init__(self, setting: str, message: str, **params: Any) -> None:
        self.setting, self.message, self.params = setting, message, params
        super().__init__(message.format(**params))

#: highest sleeper-passage harmonic that can be extracted (2·f_s and 3·f_s)
MAX_SLEEPER_HARMONIC = 3
#: most wheel out-of-roundness orders the pipeline tracks (the service stores fewer:
#: :data:`app.db.models.N_ORDER_COLUMNS`)
MAX_WHEEL_ORDERS = 30


def _setting(default: Any, help: str, valid: str) -> Any:  # noqa: A002 - the name of the metadata key
    """A field of :class:`ProcessingSettings` with its short help and its valid values (as text)."""
    return field(default=default, metadata={"help": help, "valid": valid})


def setting_help(name: str, *, valid: str | None = None) -> str:
    """One line on setting ``name``: its help, valid values (``valid`` overrides them) and default.

    What the API schema's descriptions and the command line's option help say.
    """
    f = {f.name: f for f in dataclasses.fields(ProcessingSettings)}[name]
    default = "none" if f.default is None else f"{f.default:g}" if isinstance(f.default, float) else f.default
    return f"{f.metadata['help']} ({valid or f.metadata['valid']}; default {default})"


#: what a stored settings dict without these keys meant (before issue 15)
LEGACY_VALUES: dict[str, Any] = {
    "track_resolution_m": None,
    "sleeper_harmonics": 1,
    "force_mean_window_m": 0.0,
    "edge_preserving_sd": 0.0,
}


@dataclass(frozen=True)
class ProcessingSettings:
    """Settings of the order-tracking pipeline for one run.

    Parameters
    ----------
    n_wheel_orders : int
        Number of wheel out-of-roundness orders tracked (orders 1..n), 1–30.
        Default 11 (the paper).
    bandwidth_orders : float
        Full -3 dB bandwidth of every **wheel** order's filter, expressed in
        wheel orders (multiples of the wheel rotation frequency
        ``v/(pi d_w)``), so that the bandwidth in Hz is proportional to speed.
        Default 0.1: at 160 km/h (44.4 m/s) and d_w = 0.92 m this is 1.54 Hz;
        the sleeper order lies 0.18 orders from wheel order 5, i.e. 1.8
        bandwidths away. Range 0.01–1. Wheel out-of-roundness does not change
        over a run, so a narrow band costs nothing and rejects the most.
        With ``track_resolution_m = None`` the track orders use it too.
    track_resolution_m : float or None
        Spatial resolution of the **track** orders (the sleeper passage and
        its harmonics): the 10–90 % width, m, over which a stiffness step
        appears in their amplitude profiles. Their -3 dB bandwidth is
        ``c_q v / track_resolution_m`` Hz (:func:`app.analysis.recipe.track_bandwidth_per_speed`;
        ``c_q`` = 0.659, 0.721, 0.767 for q = 1, 2, 3). Range 0.5–100 m.
        Default 3.0 (chosen by ``bench/bench_indicator.py``, BENCHMARKS.md).
        None: the track orders share ``bandwidth_orders`` (the behaviour
        before issue 15; about 21 m at 0.1 orders and 0.92 m wheels, q = 2).
    sleeper_harmonics : int
        Highest harmonic of the sleeper passage extracted: 1 (the fundamental
        ``f_s = v/d_s`` only), 2 (also ``2 f_s``) or 3 (also ``3 f_s``).
        Default 3.
    force_mean_window_m : float
        Length, m, of the moving mean (over travelled distance) subtracted from
        the force channels before the VKF, removing the static wheel load; 0
        keeps the load in (the behaviour before issue 15). A whole number of
        sleeper bays of the nominal 0.6 m is best (the mean then holds no
        sleeper-passage content). Range 0 or 1.2–200 m. Default 12.0 (20
        bays; measured in tests/pipeline/test_indicator.py: 3 m leaves the force
        amplitude 11–18 % off at the run ends, 12 m 1–2 %, 24 m 1–4 %).
    filter_order : int
        Order q of the difference operator of the VKF structural equation,
        1, 2 or 3. Default 2.
    edge_preserving_sd : float
        Edge-preserving smoothing of ``sleeper_amp`` by its stated 1-σ
        (:mod:`app.analysis.denoise`: total variation, a jump costs this many
        standard deviations; steps stay as sharp, the fluctuation between them
        flattens). 0: off. Range 0–20. Default 0: at 8 a −35 % step at 50 m/s,
        1.5 → 1.0 m/s², under 1 m/s² of noise reads 3.3 m wide with 7 % ringing
        instead of 36 m and 16 % (issue 33, ``bench_indicator.py --only
        weak-steps``), but a short soft spot loses about ``2 κ σ / n`` of its
        depth and a uniform run's mean moves by a few 1e-4 (the issue-26 physics
        tests), so it is a choice per job, not yet the default.
    bin_length_m : float
        Length of a profile bin along the track, m. Default 0.25.
    min_speed_kmh : float
        Samples slower than this (km/h) are not used for indicators: the
        orders then sit too close to 0 Hz to be separated. Default 25.
    chunk_seconds : float
        Core length of one processing chunk, s (the engine adds the overlap
        its impulse response needs). Default 60.
    """

    n_wheel_orders: int = _setting(11, "Wheel out-of-roundness orders tracked (orders 1..n)", "1..30")
    bandwidth_orders: float = _setting(
        0.1, "-3 dB bandwidth of each wheel order's filter, in wheel orders", "0.01..1")
    track_resolution_m: float | None = _setting(
        3.0, "Spatial resolution of the sleeper-passage orders: 10-90 % width of a stiffness step in "
        "their profiles, m; sets their bandwidth (c_q v / resolution Hz); none: as bandwidth_orders",
        "0.5..100 or none")
    sleeper_harmonics: int = _setting(
        3, "Highest sleeper-passage harmonic extracted: 1 (f_s only), 2 or 3 (also 2 f_s, 3 f_s)", "1, 2 or 3")
    force_mean_window_m: float = _setting(
        12.0, "Moving mean removed from the force channels (static wheel load), m; 0: off", "0 or 1.2..200")
    filter_order: int = _setting(2, "VKF structural order q", "1, 2 or 3")
    edge_preserving_sd: float = _setting(
        0.0, "Edge-preserving smoothing of sleeper_amp: a jump costs this many of its stated standard "
        "deviations (total variation); 0: off", "0..20")
    bin_length_m: float = _setting(0.25, "Profile bin length, m", "0.05..10")
    min_speed_kmh: float = _setting(MIN_SPEED_KMH, "Slowest speed used for indicators, km/h", "0..200")
    chunk_seconds: float = _setting(60.0, "Core length of a processing chunk, s", "1..3600")

    def __post_init__(self) -> None:
        if not 1 <= int(self.n_wheel_orders) <= MAX_WHEEL_ORDERS or int(self.n_wheel_orders) != self.n_wheel_orders:
            raise SettingError("n_wheel_orders", N_("n_wheel_orders must be an integer in 1..{limit}, got {value!r}"),
                               limit=MAX_WHEEL_ORDERS, value=self.n_wheel_orders)
        if not 0.01 <= float(self.bandwidth_orders) <= 1.0:
            raise SettingError("bandwidth_orders", N_("bandwidth_orders must be in [0.01, 1], got {value!r}"),
                               value=self.bandwidth_orders)
        if self.track_resolution_m is not None and not 0.5 <= float(self.track_resolution_m) <= 100.0:
            raise SettingError("track_resolution_m", N_("track_resolution_m must be in [0.5, 100] m (or null: as "
                                                        "bandwidth_orders), got {value!r}"), value=self.track_resolution_m)
        if self.sleeper_harmonics not in range(1, MAX_SLEEPER_HARMONIC + 1):
            raise SettingError("sleeper_harmonics", N_("sleeper_harmonics must be 1, 2 or {limit}, got {value!r}"),
                               limit=MAX_SLEEPER_HARMONIC, value=self.sleeper_harmonics)
        w = float(self.force_mean_window_m)
        if not (math.isfinite(w) and (w == 0.0 or 1.2 <= w <= 200.0)):
            raise SettingError("force_mean_window_m", N_("force_mean_window_m must be 0 (off) or in [1.2, 200] m, got {value!r}"),
                               value=self.force_mean_window_m)
        if self.filter_order not in (1, 2, 3):
            raise SettingError("filter_order", N_("filter_order must be 1, 2 or 3, got {value!r}"), value=self.filter_order)
        if not (math.isfinite(float(self.edge_preserving_sd)) and 0.0 <= float(self.edge_preserving_sd) <= 20.0):
            raise SettingError("edge_preserving_sd", N_("edge_preserving_sd must be in [0, 20], got {value!r}"),
                               value=self.edge_preserving_sd)
        if not 0.05 <= float(self.bin_length_m) <= 10.0:
            raise SettingError("bin_length_m", N_("bin_length_m must be in [0.05, 10] m, got {value!r}"), value=self.bin_length_m)
        if not 0.0 <= float(self.min_speed_kmh) <= 200.0:
            raise SettingError("min_speed_kmh", N_("min_speed_kmh must be in [0, 200] km/h, got {value!r}"), value=self.min_speed_kmh)
        if not 1.0 <= float(self.chunk_seconds) <= 3600.0:
            raise SettingError("chunk_seconds", N_("chunk_seconds must be in [1, 3600] s, got {value!r}"), value=self.chunk_seconds)

    def to_dict(self) -> dict[str, Any]:
        """Return the settings as a JSON-serialisable dict (every key, so it reads back the same)."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any] | None) -> ProcessingSettings:
        """Build settings of a new request from a dict; missing keys take their defaults.

        Raises
        ------
        ValueError
            If a key is unknown or a value is out of range.
        """
        data = dict(data or {})
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = set(data) - known
        if unknown:
            raise SettingError("settings", N_("unknown processing setting(s): {names}"), names=", ".join(sorted(unknown)))
        return cls(**data)

    @classmethod
    def from_stored(cls, data: dict[str, Any] | None) -> ProcessingSettings:
        """Read settings stored with a job; keys it lacks take their legacy values.

        A job stored before a setting existed was processed without it:
        :data:`LEGACY_VALUES` says what that was, so the settings read back
        describe (and reproduce) what that job did.

        Raises
        ------
        ValueError
            If a key is unknown or a value is out of range.
        """
        data = dict(data or {})
        for key, value in LEGACY_VALUES.items():
            data.setdefault(key, value)
        return cls.from_dict(data)
