"""Simulate a measurement run in the canonical format, with its ground truth.

Signal model (per wheel ``w`` = axle + side, see ``docs/run-format.md``)::

    Z_w(t) = a_s(t) cos(2 pi x_w(t) / d_s)      sleeper passage
           + z''_OOR,w(t)                          wheel out-of-roundness
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
* ``Q`` uses the full ``Z`` (noise included): the broadband part stands for
  real vibration of the unsprung mass.

The run and the truth are generated and written block by block, so memory
does not grow with the run length.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from datetime import datetime
from pathlib import Path

import h5py
import numpy as np

from app.io import ACCEL_CHANNELS, FORCE_CHANNELS, WHEELS, Calibration, parse_metadata
from app.io.canonical import CanonicalWriter, Compression, atomic_output
from app.simulate.amplitude import SpeedResponse, speed_response
from app.simulate.noise import BandLimitedNoise
from app.simulate.speed import SpeedProfile
from app.simulate.track import LineModel, generate_line
from app.simulate.truth import SimulationTruth, WheelBins, save_truth, truth_path_for
from app.simulate.wheels import WheelOOR, oor_acceleration, random_wheel_oor

__all__ = ["simulate_run", "DEFAULT_TRUE_DIAMETERS_M"]

#: True wheel diameters used unless given, m (the axles were re-profiled at different times).
DEFAULT_TRUE_DIAMETERS_M: dict[str, float] = {"11": 0.920, "12": 0.920, "41": 0.912, "42": 0.912}
_KMH = 1.0 / 3.6


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


def simulate_run(
    dest: Path | str,
    *,
    length_km: float | None = None,
    duration_s: float | None = None,
    fs: float = 24_000.0,
    seed: int = 0,
    with_forces: bool = True,
    noise_std: float = 2.0,
    force_noise_std: float = 0.2,
    speed_profile: SpeedProfile | None = None,
    line: LineModel | None = None,
    line_seed: int | None = None,
    wheels: Mapping[str, WheelOOR] | None = None,
    wheel_diameters: Mapping[str, float] | None = None,
    reported_wheel_diameters: Mapping[str, float] | None = None,
    unsprung_mass_kg: float = 300.0,
    static_load_kn: float = 80.0,
    amplitude_model: str | SpeedResponse = "resonance",
    alpha: float = 1.5,
    v_ref_kmh: float = 100.0,
    sleeper_spacing: float = 0.6,
    axle_positions: Mapping[str, float] | None = None,
    km_start: float = 12.0,
    km_error_m: float = 0.0,
    km_increasing: bool = True,
    start_time: datetime | str = "2024-05-01T08:00:00+02:00",
    vehicle_id: str = "SIM-1",
    line_id: str = "SIM",
    track: str = "1",
    direction: str = "up",
    calibration: Mapping[str, Calibration | Mapping[str, float]] | None = None,
    block_samples: int = 2**18,
    compression: Compression = "auto",
) -> SimulationTruth:
    """Write a synthetic run (canonical HDF5) and its truth file ``<stem>.truth.h5``.

    Parameters
    ----------
    dest : Path or str
        Run file to write (atomically); the truth goes to ``<dest stem>.truth.h5``.
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
    wheels : mapping, optional
        OOR per wheel; default random (:func:`random_wheel_oor`) with the true
        ``wheel_diameters``.
    wheel_diameters : mapping, optional
        True diameters, m (default :data:`DEFAULT_TRUE_DIAMETERS_M`); ignored
        for wheels given in ``wheels``.
    reported_wheel_diameters : mapping, optional
        Diameters written to the metadata (default: the true ones).
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
        Written to the run metadata.
    calibration : mapping, optional
        Channel → ``{"gain", "offset"}``: the file stores ``(physical - offset) / gain``.
    block_samples : int
        Samples generated per block (memory bound).
    compression : {"auto", "lzf", "gzip", None}
        Dataset compression of the run file (see :class:`~app.io.canonical.CanonicalWriter`).

    Returns
    -------
    SimulationTruth
        Also written to ``<dest stem>.truth.h5`` (see :mod:`app.simulate.truth`).
    """
    dest = Path(dest)
    if length_km is not None and duration_s is not None:
        raise ValueError("give at most one of length_km and duration_s")
    if length_km is None and duration_s is None:
        length_km = 6.0
    fs = _positive("fs", fs)
    if not 1_000.0 <= fs <= 100_000.0:
        raise ValueError(f"fs must be within 1 kHz … 100 kHz, got {fs!r}")
    noise_std = _non_negative("noise_std", noise_std)
    force_noise_std = _non_negative("force_noise_std", force_noise_std)
    unsprung_mass_kg = _positive("unsprung_mass_kg", unsprung_mass_kg)
    static_load_kn = _positive("static_load_kn", static_load_kn)
    alpha = _non_negative("alpha", alpha)
    v_ref = _positive("v_ref_kmh", v_ref_kmh) * _KMH
    response = speed_response(amplitude_model, v_ref_mps=v_ref, alpha=alpha) \
        if isinstance(amplitude_model, str) else amplitude_model
    v_ref = float(response.v_ref_mps)
    alpha = float(getattr(response, "alpha", float("nan")))
    sleeper_spacing = _positive("sleeper_spacing", sleeper_spacing)
    if int(block_samples) != block_samples or block_samples < 256:
        raise ValueError(f"block_samples must be an integer >= 256, got {block_samples!r}")

    seq = np.random.SeedSequence(int(seed))
    rng_speed, rng_wheels, rng_noise = (np.random.default_rng(s) for s in seq.spawn(3))

    if speed_profile is None:
        if length_km is not None:
            speed_profile = SpeedProfile.random(
                rng_speed, length_m=_positive("length_km", length_km) * 1e3
            )
        else:
            speed_profile = SpeedProfile.random(
                rng_speed, duration_s=_positive("duration_s", duration_s)
            )
    if length_km is not None:
        t_end = float(
            speed_profile.time_at_distance(np.array([_positive("length_km", length_km) * 1e3]))[0]
        )
        n = int(round(t_end * fs)) + 1
    else:
        n = int(round(_positive("duration_s", duration_s) * fs))
    if n < 2:
        raise ValueError("the run is shorter than two samples")

    meta = parse_metadata(
        {
            "vehicle_id": vehicle_id,
            "start_time": start_time,
            "line_id": line_id,
            "track": track,
            "direction": direction,
            "km_start": km_start + float(km_error_m) / 1000.0,
            "km_increasing": km_increasing,
            "sleeper_spacing": sleeper_spacing,
            "axle_positions": dict(axle_positions or {}),
            "calibration": dict(calibration or {}),
            "sample_rate_hz": fs,
        }
    )
    axles = meta.axle_positions
    true_d = dict(DEFAULT_TRUE_DIAMETERS_M)
    true_d.update({k: float(v) for k, v in (wheel_diameters or {}).items()})
    oors: dict[str, WheelOOR] = {}
    for w in WHEELS:  # draw all four so the randomness does not depend on `wheels`
        drawn = random_wheel_oor(rng_wheels, w, true_d[w])
        oors[w] = wheels[w] if wheels is not None and w in wheels else drawn
    reported = {w: o.diameter_m for w, o in oors.items()}
    reported.update({k: float(v) for k, v in (reported_wheel_diameters or {}).items()})
    meta = parse_metadata({**meta.model_dump(), "wheel_diameters": reported})

    sign = 1.0 if km_increasing else -1.0
    ref0 = 1000.0 * km_start
    s_end = float(speed_profile.distance(np.array([(n - 1) / fs]))[0])
    ranges = {
        ax: sorted((ref0 + sign * off, ref0 + sign * (s_end + off))) for ax, off in axles.items()
    }
    lo = min(r[0] for r in ranges.values())
    hi = max(r[1] for r in ranges.values())
    if line is None:
        common = (
            max(r[0] for r in ranges.values()) + 10.0,
            min(r[1] for r in ranges.values()) - 10.0,
        )
        line = generate_line(
            lo - 50.0,
            hi + 50.0,
            np.random.default_rng([int(seed if line_seed is None else line_seed), 7]),
            anomaly_range_m=common,
        )
    elif not line.covers(lo, hi):
        raise ValueError(
            f"line covers {line.track_from_m:.1f} … {line.track_to_m:.1f} m but the run needs "
            f"{lo:.1f} … {hi:.1f} m"
        )

    noise_hi = min(0.4 * fs, 10_000.0)
    band = (2.0, noise_hi)
    z_noise = {
        w: BandLimitedNoise(r, fs, noise_std, band)
        for w, r in zip(WHEELS, rng_noise.spawn(4), strict=True)
    }
    q_rngs = dict(zip(WHEELS, rng_noise.spawn(4), strict=True))
    centres = line.centres()
    grids = {side: line.amplitude_grid(side) for side in (1, 2)}
    channels = (
        list(ACCEL_CHANNELS) + (list(FORCE_CHANNELS) if with_forces else []) + ["speed", "position"]
    )

    truth_path = truth_path_for(dest)
    with atomic_output(dest) as tmp_run:
        with h5py.File(tmp_run, "w") as h5:
            writer = CanonicalWriter(
                h5,
                fs=fs,
                metadata=meta,
                channels=channels,
                n_samples=n,
                compression=compression,
                source_format="simulated",
            )

            def put(name: str, a: int, phys: np.ndarray) -> None:
                gain, offset = meta.gain_offset(name)
                writer.write(
                    name, a, (phys - offset) / gain if (gain, offset) != (1.0, 0.0) else phys
                )

            for a in range(0, n, block_samples):
                b = min(a + block_samples, n)
                t = np.arange(a, b) / fs
                v, acc, s = speed_profile.evaluate(t)
                for w in WHEELS:
                    side = int(w[1])
                    x = ref0 + sign * (s + axles[w[0]])
                    z = (
                        np.interp(x, centres, grids[side])
                        * response.factor(_type_codes(line, x), v)
                        * np.cos(2 * np.pi * x / sleeper_spacing)
                    )
                    z += oor_acceleration(oors[w], s, v, acc)
                    z += z_noise[w].next(b - a)
                    put(f"Z{w}", a, z)
                    if with_forces:
                        q = static_load_kn + unsprung_mass_kg * z / 1000.0
                        if force_noise_std > 0:
                            q += force_noise_std * q_rngs[w].standard_normal(b - a)
                        put(f"Q{w}", a, q)
                put("speed", a, v)
                put("position", a, s)
            writer.finish(n)

        bins = {
            w: _wheel_bins(
                line,
                speed_profile,
                grids[int(w[1])],
                int(w[1]),
                axles[w[0]],
                ref0,
                sign,
                s_end,
                response,
            )
            for w in WHEELS
        }
        truth = SimulationTruth(
            run_path=dest,
            truth_path=truth_path,
            seed=int(seed),
            fs=fs,
            n_samples=n,
            duration_s=n / fs,
            distance_m=s_end,
            alpha=alpha,
            v_ref_mps=v_ref,
            sleeper_spacing_m=sleeper_spacing,
            bin_length_m=line.bin_length,
            noise_std_mps2=noise_std,
            noise_band_hz=band,
            force_noise_std_kn=force_noise_std if with_forces else 0.0,
            unsprung_mass_kg=unsprung_mass_kg,
            static_load_kn=static_load_kn,
            with_forces=bool(with_forces),
            km_start=float(km_start),
            km_increasing=bool(km_increasing),
            km_error_m=float(km_error_m),
            axle_positions=dict(axles),
            line=line,
            speed_profile=speed_profile,
            wheels=oors,
            reported_diameters=reported,
            bins=bins,
            speed_response=response,
        )
        with atomic_output(truth_path) as tmp_truth, h5py.File(tmp_truth, "w") as h5t:
            save_truth(truth, h5t)
    return truth


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
