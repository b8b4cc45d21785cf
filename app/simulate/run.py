"""Simulate a measurement run in the canonical format, with its ground truth.

Signal model (per wheel ``w`` = axle + side, see ``docs/run-format.md``)::

    Z_w(t) = a_s(t) cos(2 pi x_w(t) / d_s)      sleeper passage
           + z''_OOR,w(t)                          wheel out-of-roundness
           + (h_type * r_w)(t)                     rail roughness, welds, joints, wheel flat
           + n_w(t)                                band-limited Gaussian noise
    Q_w(t) = Q_static + m_u Z_w(t) / 1000 + e_w(t) [kN]

* ``x_w`` is the wheel's track position on the km axis (m):
  ``1000 km_start ± (s(t) + axle offset)``; ``s(t)`` is the distance travelled
  since the run start (analytic, from the speed profile), so phases are
  continuous across blocks. Sleepers lie at ``x = k d_s``.
* ``a_s = K_type(x_w) f_side(x_w) R_type(v)`` (see :mod:`app.simulate.track`):
  ``K_type f_side`` is the amplitude at ``v_ref = 100 km/h`` and ``R_type`` the
  speed response (:mod:`app.simulate.amplitude`): by default the resonance of a
  wheel on a discretely supported rail with a support stiffness per
  superstructure type; ``amplitude_model="power_law"`` gives the separable
  ``(v / v_ref) ** alpha`` (``alpha = 1.5``) of earlier versions.
* ``z''_OOR`` is the second time derivative of the wheel radius at the contact
  point (:func:`app.simulate.wheels.oor_acceleration`; phase convention there).
* ``r_w`` is the height of the running surfaces under the wheel — its rail
  at ``x_w`` (:mod:`app.simulate.surface`, fixed to the track: the line's
  ``surface``) plus its flat at ``s`` — and ``h_type`` the impulse response of
  the wheel–track system of the superstructure type there
  (:mod:`app.simulate.contact`); ``confounders`` switches each part.
* ``Q`` uses the full ``Z`` (noise included): the broadband part stands for
  real vibration of the unsprung mass.

:func:`simulate_run` takes a :class:`SimulationConfig` (or its fields as
keywords) and works in stages: :func:`plan_run` (every random draw, the
line, the wheels, the surfaces), the signals, the truth. The run and the
truth are generated and written block by block, so memory does not grow with
the run length.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from datetime import datetime
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from app.analysis.units import KMH_PER_MPS
from app.io import ACCEL_CHANNELS, FORCE_CHANNELS, WHEELS, Calibration, RunMetadata, parse_metadata
from app.io.canonical import CanonicalWriter, Compression, atomic_output
from app.simulate.amplitude import ResonanceResponse, SpeedResponse, speed_response
from app.simulate.contact import ContactFilter
from app.simulate.noise import BandLimitedNoise
from app.simulate.speed import SpeedProfile
from app.simulate.surface import ROUGHNESS_STEP_M, RailSurface, as_date
from app.simulate.track import SUPERSTRUCTURE_TYPES, LineModel, generate_line
from app.simulate.truth import SimulationTruth, WheelBins, save_truth, truth_path_for
from app.simulate.wheels import WheelFlat, WheelOOR, oor_acceleration, random_wheel_oor

__all__ = ["simulate_run", "plan_run", "SimulationConfig", "Confounders", "RunPlan", "DEFAULT_TRUE_DIAMETERS_M"]

#: True wheel diameters used unless given, m (the axles were re-profiled at different times).
DEFAULT_TRUE_DIAMETERS_M: dict[str, float] = {"11": 0.920, "12": 0.920, "41": 0.912, "42": 0.912}
_KMH = 1.0 / KMH_PER_MPS
#: Track beyond the wheels' own range that the surface is generated for (the contact filter's memory), m.
_SURFACE_MARGIN_M = 40.0


def _positive(name: str, value: float) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    return v


def _non_negative(name: str, value: float) -> float:
    v = float(value)
    if not (math.isfinite(v) and v >= 0):
        raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
    return v


@dataclass(frozen=True)
class Confounders:
    """Which of the running surfaces' contributions a run simulates.

    Each switch applies what the line (:attr:`app.simulate.track.LineModel.surface`)
    and the wheels (:attr:`app.simulate.wheels.WheelOOR.flat`) carry; a line
    without a surface and wheels without flats add nothing whatever the
    switches say.

    Attributes
    ----------
    roughness : bool
        The rails' random roughness.
    track_impacts : bool
        Dipped welds and joints.
    wheel_flats : bool
        Wheel flats.
    """

    roughness: bool = True
    track_impacts: bool = True
    wheel_flats: bool = True

    @property
    def any(self) -> bool:
        """Whether any switch is on."""
        return self.roughness or self.track_impacts or self.wheel_flats


@dataclass(frozen=True)
class SimulationConfig:
    """Everything :func:`simulate_run` needs (all optional; see its parameters).

    Grouped: *extent* (``length_km``, ``duration_s``, ``speed_profile``), *signal*
    (``fs``, ``seed``, ``with_forces``, ``noise_std``, ``force_noise_std``,
    ``block_samples``, ``compression``, ``calibration``, ``sensor_gain``), *track* (``line``,
    ``line_seed``, ``rail_surface``, ``amplitude_model``, ``alpha``,
    ``v_ref_kmh``, ``sleeper_spacing``), *vehicle* (``wheels``,
    ``wheel_diameters``, ``reported_wheel_diameters``, ``wheel_flats``,
    ``unsprung_mass_kg``, ``static_load_kn``, ``axle_positions``,
    ``vehicle_id``), *where and when* (``km_start``, ``km_error_m``,
    ``km_increasing``, ``start_time``, ``line_id``, ``track``, ``direction``)
    and ``confounders``. Validated when made.
    """

    length_km: float | None = None
    duration_s: float | None = None
    fs: float = 24_000.0
    seed: int = 0
    with_forces: bool = True
    noise_std: float = 2.0
    force_noise_std: float = 0.2
    speed_profile: SpeedProfile | None = None
    line: LineModel | None = None
    line_seed: int | None = None
    rail_surface: bool | RailSurface = False
    wheels: Mapping[str, WheelOOR] | None = None
    wheel_diameters: Mapping[str, float] | None = None
    reported_wheel_diameters: Mapping[str, float] | None = None
    wheel_flats: Mapping[str, WheelFlat] | None = None
    unsprung_mass_kg: float = 300.0
    static_load_kn: float = 80.0
    amplitude_model: str | SpeedResponse = "resonance"
    alpha: float = 1.5
    v_ref_kmh: float = 100.0
    sleeper_spacing: float = 0.6
    axle_positions: Mapping[str, float] | None = None
    km_start: float = 12.0
    km_error_m: float = 0.0
    km_increasing: bool = True
    start_time: datetime | str = "2024-05-01T08:00:00+02:00"
    vehicle_id: str = "SIM-1"
    line_id: str = "SIM"
    track: str = "1"
    direction: str = "up"
    calibration: Mapping[str, Calibration | Mapping[str, float]] | None = None
    sensor_gain: float = 1.0
    block_samples: int = 2**18
    compression: Compression = "auto"
    confounders: Confounders = field(default_factory=Confounders)

    def __post_init__(self) -> None:
        if self.length_km is not None and self.duration_s is not None:
            raise ValueError("give at most one of length_km and duration_s")
        if self.length_km is None and self.duration_s is None:
            object.__setattr__(self, "length_km", 6.0)
        fs = _positive("fs", self.fs)
        if not 1_000.0 <= fs <= 100_000.0:
            raise ValueError(f"fs must be within 1 kHz … 100 kHz, got {self.fs!r}")
        _non_negative("noise_std", self.noise_std)
        _non_negative("force_noise_std", self.force_noise_std)
        _positive("unsprung_mass_kg", self.unsprung_mass_kg)
        _positive("static_load_kn", self.static_load_kn)
        _non_negative("alpha", self.alpha)
        _positive("v_ref_kmh", self.v_ref_kmh)
        _positive("sleeper_spacing", self.sleeper_spacing)
        _positive("sensor_gain", self.sensor_gain)
        if int(self.block_samples) != self.block_samples or self.block_samples < 256:
            raise ValueError(f"block_samples must be an integer >= 256, got {self.block_samples!r}")
        if not isinstance(self.confounders, Confounders):
            raise ValueError(f"confounders must be a Confounders, got {type(self.confounders).__name__}")
        for w in self.wheel_flats or {}:
            if w not in WHEELS:
                raise ValueError(f"wheel_flats: unknown wheel {w!r} (one of {', '.join(WHEELS)})")


@dataclass(frozen=True)
class RunPlan:
    """A run resolved from its :class:`SimulationConfig`: every random draw made, nothing written.

    Attributes
    ----------
    config : SimulationConfig
    fs : float
        Sample rate, Hz.
    n : int
        Samples per channel.
    speed_profile : SpeedProfile
    response : SpeedResponse
        ``R_type(v)`` of the sleeper-passage amplitude.
    meta : RunMetadata
        What the file's metadata will say.
    axles : dict
        Axle positions relative to the position reference, m.
    wheels : dict
        OOR (and flat) per wheel.
    reported : dict
        Diameters in the metadata, m.
    line : LineModel
    sign, ref0 : float
        Direction of the km axis (±1) and the reference's track position at the start, m.
    s_end : float
        Distance travelled by the reference, m.
    surface : dict
        Per rail side, ``(x0, step, height)`` of the running surface the wheels meet (m), or
        empty when no surface contribution is simulated.
    contact : dict
        Per superstructure type code present, the :class:`~app.simulate.contact.ContactFilter`.
    noise_rng : numpy.random.Generator
        Source of the noise (drawn in the write stage).
    """

    config: SimulationConfig
    fs: float
    n: int
    speed_profile: SpeedProfile
    response: SpeedResponse
    meta: RunMetadata
    axles: dict[str, float]
    wheels: dict[str, WheelOOR]
    reported: dict[str, float]
    line: LineModel
    sign: float
    ref0: float
    s_end: float
    surface: dict[int, tuple[float, float, np.ndarray]]
    contact: dict[int, ContactFilter]
    noise_rng: np.random.Generator

    def track_x(self, s: np.ndarray, axle: str) -> np.ndarray:
        """Track position of an axle after the reference travelled ``s``, m."""
        return self.ref0 + self.sign * (s + self.axles[axle])


def simulate_run(dest: Path | str, config: SimulationConfig | None = None, **options: Any) -> SimulationTruth:
    """Write a synthetic run (canonical HDF5) and its truth file ``<stem>.truth.h5``.

    Three stages: :func:`plan_run` resolves the configuration (every random
    draw, the line, the wheels, the surfaces), the signal stage writes the
    channels block by block, and the truth stage writes what went in.

    Parameters
    ----------
    dest : Path or str
        Run file to write (atomically); the truth goes to ``<dest stem>.truth.h5``.
    config : SimulationConfig, optional
        The run; ``options`` (the fields of :class:`SimulationConfig`, below)
        make one or override fields of ``config``.
    length_km : float, optional
        Length of the run, km. Default 6 km when ``duration_s`` is not given.
    duration_s : float, optional
        Duration of the run, s (instead of ``length_km``).
    fs : float
        Sample rate, Hz (1 kHz … 100 kHz; default 24 kHz).
    seed : int
        Seed of everything random (speed profile, OOR, noise; the line too
        unless ``line_seed`` or ``line`` is given).
    with_forces : bool
        Also write Q11 … Q42.
    noise_std : float
        Standard deviation of the band-limited noise on Z, m/s² (default 2).
    force_noise_std : float
        Standard deviation of the white noise on Q, kN (default 0.2).
    speed_profile : SpeedProfile, optional
        Default: :meth:`SpeedProfile.random` (40 … 200 km/h, |a| <= 0.9 m/s²).
    line : LineModel, optional
        The line to run over (km axis in m); default a random line from
        ``line_seed`` (default ``seed``) covering the run.
    line_seed : int, optional
        Seed of the random line (same seed → same line for other runs).
    rail_surface : bool or RailSurface
        Running surface of a generated line (ignored when ``line`` is given:
        the line carries its own): False (default) smooth rails, True a random
        one (:func:`app.simulate.surface.generate_surface`: Sato roughness of
        good rail, a dipped weld every 100–200 m), or this one.
    wheels : mapping, optional
        OOR per wheel; default random (:func:`random_wheel_oor`) with the true
        ``wheel_diameters``.
    wheel_diameters : mapping, optional
        True diameters, m (default :data:`DEFAULT_TRUE_DIAMETERS_M`); ignored
        for wheels given in ``wheels``.
    reported_wheel_diameters : mapping, optional
        Diameters written to the metadata (default: the true ones).
    wheel_flats : mapping, optional
        A :class:`~app.simulate.wheels.WheelFlat` per wheel, added to its OOR.
    unsprung_mass_kg : float
        ``m_u``, kg (default 300).
    static_load_kn : float
        Static wheel load, kN (default 80).
    amplitude_model : {"resonance", "power_law"} or SpeedResponse
        Speed response ``R_type(v)`` of the sleeper-passage amplitude
        (:mod:`app.simulate.amplitude`; default ``"resonance"``). A model
        object brings its own reference speed.
    alpha, v_ref_kmh : float
        Exponent of ``"power_law"`` (default 1.5) and the reference speed
        (default 100 km/h) of the named models.
    sleeper_spacing : float
        ``d_s``, m (default 0.6).
    axle_positions : mapping, optional
        Axle positions relative to the position reference, m (default
        ``{"1": 0.0, "4": -17.5}``).
    km_start : float
        Line km of the position reference at the start.
    km_error_m : float
        Odometry error, m: the metadata states ``km_start + km_error_m / 1000``
        while the train really starts at ``km_start`` (truth positions are the
        real ones), so run alignment can be tested against a known shift.
    km_increasing : bool
        Direction of the km axis along the run.
    start_time, vehicle_id, line_id, track, direction : metadata
        Written to the run metadata; ``start_time`` is also the date at which
        the rail surface is taken (grinding actions up to it apply).
    calibration : mapping, optional
        Channel → ``{"gain", "offset"}``: the file stores ``(physical - offset) / gain``.
    sensor_gain : float
        The accelerometers' true gain against what their calibration says (default 1): the Z
        channels read ``sensor_gain`` times the physical acceleration and nothing in the file says
        so (a vehicle whose sensors read 15 % high: 1.15). The forces are not affected.
    block_samples : int
        Samples generated per block (memory bound).
    compression : {"auto", "lzf", "gzip", None}
        Dataset compression of the run file (see :class:`~app.io.canonical.CanonicalWriter`).
    confounders : Confounders
        Which surface contributions are simulated (default all that the line
        and wheels carry).

    Returns
    -------
    SimulationTruth
        Also written to ``<dest stem>.truth.h5`` (see :mod:`app.simulate.truth`).
    """
    dest = Path(dest)
    config = SimulationConfig(**options) if config is None else replace(config, **options)
    plan = plan_run(config)
    truth_path = truth_path_for(dest)
    with atomic_output(dest) as tmp_run:
        with h5py.File(tmp_run, "w") as h5:
            _write_signals(plan, h5)
        truth = _truth(plan, dest, truth_path)
        with atomic_output(truth_path) as tmp_truth, h5py.File(tmp_truth, "w") as h5t:
            save_truth(truth, h5t)
    return truth


def plan_run(config: SimulationConfig) -> RunPlan:
    """Resolve a configuration: speed profile, length, metadata, wheels, line and surfaces.

    The random draws happen here, in a fixed order (speed profile, wheels,
    then the noise generators' seeds), so the same configuration gives the
    same run.
    """
    c = config
    fs = float(c.fs)
    v_ref = float(c.v_ref_kmh) * _KMH
    response = speed_response(c.amplitude_model, v_ref_mps=v_ref, alpha=float(c.alpha)) \
        if isinstance(c.amplitude_model, str) else c.amplitude_model

    seq = np.random.SeedSequence(int(c.seed))
    rng_speed, rng_wheels, rng_noise = (np.random.default_rng(s) for s in seq.spawn(3))

    speed_profile = c.speed_profile
    if speed_profile is None:
        if c.length_km is not None:
            speed_profile = SpeedProfile.random(rng_speed, length_m=_positive("length_km", c.length_km) * 1e3)
        else:
            speed_profile = SpeedProfile.random(rng_speed, duration_s=_positive("duration_s", c.duration_s))
    if c.length_km is not None:
        t_end = float(speed_profile.time_at_distance(np.array([_positive("length_km", c.length_km) * 1e3]))[0])
        n = int(round(t_end * fs)) + 1
    else:
        n = int(round(_positive("duration_s", c.duration_s) * fs))
    if n < 2:
        raise ValueError("the run is shorter than two samples")

    meta = parse_metadata(
        {
            "vehicle_id": c.vehicle_id,
            "start_time": c.start_time,
            "line_id": c.line_id,
            "track": c.track,
            "direction": c.direction,
            "km_start": c.km_start + float(c.km_error_m) / 1000.0,
            "km_increasing": c.km_increasing,
            "sleeper_spacing": float(c.sleeper_spacing),
            "axle_positions": dict(c.axle_positions or {}),
            "calibration": dict(c.calibration or {}),
            "sample_rate_hz": fs,
        }
    )
    axles = dict(meta.axle_positions)
    true_d = dict(DEFAULT_TRUE_DIAMETERS_M)
    true_d.update({k: float(v) for k, v in (c.wheel_diameters or {}).items()})
    oors: dict[str, WheelOOR] = {}
    for w in WHEELS:  # draw all four so the randomness does not depend on `wheels`
        drawn = random_wheel_oor(rng_wheels, w, true_d[w])
        oors[w] = c.wheels[w] if c.wheels is not None and w in c.wheels else drawn
    for w, flat in (c.wheel_flats or {}).items():
        oors[w] = replace(oors[w], flat=flat)
    reported = {w: o.diameter_m for w, o in oors.items()}
    reported.update({k: float(v) for k, v in (c.reported_wheel_diameters or {}).items()})
    meta = parse_metadata({**meta.model_dump(), "wheel_diameters": reported})

    sign = 1.0 if c.km_increasing else -1.0
    ref0 = 1000.0 * c.km_start
    s_end = float(speed_profile.distance(np.array([(n - 1) / fs]))[0])
    ranges = {ax: sorted((ref0 + sign * off, ref0 + sign * (s_end + off))) for ax, off in axles.items()}
    lo = min(r[0] for r in ranges.values())
    hi = max(r[1] for r in ranges.values())
    line = c.line
    if line is None:
        common = (max(r[0] for r in ranges.values()) + 10.0, min(r[1] for r in ranges.values()) - 10.0)
        line = generate_line(
            lo - 50.0,
            hi + 50.0,
            np.random.default_rng([int(c.seed if c.line_seed is None else c.line_seed), 7]),
            anomaly_range_m=common,
            surface=c.rail_surface,
        )
    elif not line.covers(lo, hi):
        raise ValueError(
            f"line covers {line.track_from_m:.1f} … {line.track_to_m:.1f} m but the run needs "
            f"{lo:.1f} … {hi:.1f} m"
        )
    surface, contact = _surfaces(c, line, oors, speed_profile, response, fs, lo, hi, meta)
    return RunPlan(config=c, fs=fs, n=n, speed_profile=speed_profile, response=response, meta=meta,
                   axles=axles, wheels=oors, reported=reported, line=line, sign=sign, ref0=ref0,
                   s_end=s_end, surface=surface, contact=contact, noise_rng=rng_noise)


def _surfaces(c: SimulationConfig, line: LineModel, oors: Mapping[str, WheelOOR], profile: SpeedProfile,
              response: SpeedResponse, fs: float, lo: float, hi: float, meta: RunMetadata,
              ) -> tuple[dict[int, tuple[float, float, np.ndarray]], dict[int, ContactFilter]]:
    """The rails' running surfaces over the run (on its date) and the contact filter of each type met."""
    sw = c.confounders
    rails = line.surface is not None and (sw.roughness or sw.track_impacts)
    flats = sw.wheel_flats and any(o.flat is not None for o in oors.values())
    if not (rails or flats):
        return {}, {}
    surface: dict[int, tuple[float, float, np.ndarray]] = {}
    if rails:
        assert line.surface is not None
        v_max = float(max(np.max(profile.v0), np.max(profile.v1)))
        # wavelengths shorter than ~2.5 samples at the top speed would alias: left out
        min_wl = 2.5 * v_max / fs
        for side in (1, 2):
            x, h = line.surface.profile(side, lo - _SURFACE_MARGIN_M, hi + _SURFACE_MARGIN_M, meta.start_time,
                                        roughness=sw.roughness, impacts=sw.track_impacts,
                                        min_wavelength_m=min_wl)
            surface[side] = (float(x[0]), ROUGHNESS_STEP_M, h)
    base = response if isinstance(response, ResonanceResponse) else ResonanceResponse(v_ref_mps=response.v_ref_mps)
    codes = np.unique(line.type_code)
    contact = {}
    for code in codes.tolist():
        name = SUPERSTRUCTURE_TYPES[code]
        contact[int(code)] = ContactFilter(base.params(name), fs)
    return surface, contact


def _surface_response(plan: RunPlan, w: str, a: int, b: int) -> np.ndarray:
    """Axle-box acceleration of wheel ``w`` caused by the running surfaces, samples ``a … b - 1``, m/s²."""
    out = np.zeros(b - a)
    if not plan.contact:
        return out
    flat = plan.wheels[w].flat if plan.config.confounders.wheel_flats else None
    if not plan.surface and flat is None:
        return out
    fs = plan.fs
    look = max(f.lookahead for f in plan.contact.values())
    hist = max(f.history for f in plan.contact.values())
    t = np.arange(a - hist, b + look) / fs
    s = plan.speed_profile.distance(t)  # s = v0 t before the start: the train was already rolling
    x = plan.track_x(s, w[0])
    r = np.zeros(t.size)
    if plan.surface:
        x0, step, h = plan.surface[int(w[1])]
        r += np.interp((x - x0) / step, np.arange(h.size), h)
    if flat is not None:
        r += flat.height(s, plan.wheels[w].diameter_m)
    codes = _type_codes(plan.line, x[hist : hist + (b - a)])
    for code, filt in plan.contact.items():
        m = codes == code
        if m.any():
            i0 = hist - filt.history
            y = filt.apply(r[i0 : i0 + filt.history + (b - a) + filt.lookahead])
            out[m] = y[m]
    return out


def _write_signals(plan: RunPlan, h5: h5py.File) -> None:
    """The signal stage: every channel, block by block (see the module docstring)."""
    c, meta, fs, n = plan.config, plan.meta, plan.fs, plan.n
    noise_hi = min(0.4 * fs, 10_000.0)
    band = (2.0, noise_hi)
    z_noise = {
        w: BandLimitedNoise(r, fs, float(c.noise_std), band)
        for w, r in zip(WHEELS, plan.noise_rng.spawn(4), strict=True)
    }
    q_rngs = dict(zip(WHEELS, plan.noise_rng.spawn(4), strict=True))
    line = plan.line
    centres = line.centres()
    grids = {side: line.amplitude_grid(side) for side in (1, 2)}
    channels = list(ACCEL_CHANNELS) + (list(FORCE_CHANNELS) if c.with_forces else []) + ["speed", "position"]
    writer = CanonicalWriter(h5, fs=fs, metadata=meta, channels=channels, n_samples=n,
                             compression=c.compression, source_format="simulated")

    def put(name: str, a: int, phys: np.ndarray) -> None:
        gain, offset = meta.gain_offset(name)
        writer.write(name, a, (phys - offset) / gain if (gain, offset) != (1.0, 0.0) else phys)

    for a in range(0, n, int(c.block_samples)):
        b = min(a + int(c.block_samples), n)
        t = np.arange(a, b) / fs
        v, acc, s = plan.speed_profile.evaluate(t)
        for w in WHEELS:
            side = int(w[1])
            x = plan.track_x(s, w[0])
            z = (
                np.interp(x, centres, grids[side])
                * plan.response.factor(_type_codes(line, x), v)
                * np.cos(2 * np.pi * x / float(c.sleeper_spacing))
            )
            z += oor_acceleration(plan.wheels[w], s, v, acc)
            if plan.contact:
                z += _surface_response(plan, w, a, b)
            z += z_noise[w].next(b - a)
            put(f"Z{w}", a, z * float(c.sensor_gain) if c.sensor_gain != 1.0 else z)
            if c.with_forces:
                q = float(c.static_load_kn) + float(c.unsprung_mass_kg) * z / 1000.0
                if c.force_noise_std > 0:
                    q += float(c.force_noise_std) * q_rngs[w].standard_normal(b - a)
                put(f"Q{w}", a, q)
        put("speed", a, v)
        put("position", a, s)
    writer.finish(n)


def _truth(plan: RunPlan, dest: Path, truth_path: Path) -> SimulationTruth:
    """The truth stage: what the run holds, per 25 cm bin and as parameters."""
    c = plan.config
    bins = {
        w: _wheel_bins(plan.line, plan.speed_profile, plan.line.amplitude_grid(int(w[1])), int(w[1]),
                       plan.axles[w[0]], plan.ref0, plan.sign, plan.s_end, plan.response)
        for w in WHEELS
    }
    noise_hi = min(0.4 * plan.fs, 10_000.0)
    return SimulationTruth(
        run_path=dest,
        truth_path=truth_path,
        seed=int(c.seed),
        fs=plan.fs,
        n_samples=plan.n,
        duration_s=plan.n / plan.fs,
        distance_m=plan.s_end,
        alpha=float(getattr(plan.response, "alpha", float("nan"))),
        v_ref_mps=float(plan.response.v_ref_mps),
        sleeper_spacing_m=float(c.sleeper_spacing),
        bin_length_m=plan.line.bin_length,
        noise_std_mps2=float(c.noise_std),
        noise_band_hz=(2.0, noise_hi),
        force_noise_std_kn=float(c.force_noise_std) if c.with_forces else 0.0,
        unsprung_mass_kg=float(c.unsprung_mass_kg),
        static_load_kn=float(c.static_load_kn),
        with_forces=bool(c.with_forces),
        km_start=float(c.km_start),
        km_increasing=bool(c.km_increasing),
        km_error_m=float(c.km_error_m),
        axle_positions=dict(plan.axles),
        line=plan.line,
        speed_profile=plan.speed_profile,
        wheels=plan.wheels,
        reported_diameters=plan.reported,
        bins=bins,
        speed_response=plan.response,
        confounders=c.confounders,
        run_date=as_date(plan.meta.start_time).isoformat(),
    )


def _wheel_bins(
    line: LineModel,
    profile: SpeedProfile,
    grid: np.ndarray,
    side: int,
    offset: float,
    ref0: float,
    sign: float,
    s_end: float,
    response: SpeedResponse,
) -> WheelBins:
    """Truth of the bins whose centre the wheel passes during the run."""
    bl = line.bin_length
    x0, x1 = sorted((ref0 + sign * offset, ref0 + sign * (s_end + offset)))
    b_lo = math.ceil(x0 / bl - 0.5)
    b_hi = math.floor(x1 / bl - 0.5)
    bins = np.arange(b_lo, b_hi + 1, dtype=np.int64)
    if sign < 0:
        bins = bins[::-1]
    centre = (bins + 0.5) * bl
    s_c = np.clip(sign * (centre - ref0) - offset, 0.0, s_end)
    t_c = profile.time_at_distance(s_c)
    v_c = profile.speed(t_c)
    idx = bins - line.first_bin
    amp_vref = grid[idx]
    return WheelBins(
        bin=bins,
        track_m=centre,
        km=centre / 1000.0,
        s_m=s_c,
        t_s=t_c,
        speed_mps=v_c,
        section=line.type_code[idx],
        stiffness_factor=line.factor[side - 1, idx],
        amplitude_vref_mps2=amp_vref,
        amplitude_mps2=amp_vref * response.factor(line.type_code[idx], v_c),
    )


def _type_codes(line: LineModel, track_m: np.ndarray) -> np.ndarray:
    """Superstructure type code of the grid cell holding each position (clipped to the grid)."""
    idx = np.floor(track_m / line.bin_length).astype(np.int64) - line.first_bin
    return line.type_code[np.clip(idx, 0, line.n_bins - 1)]
