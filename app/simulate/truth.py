"""Ground truth of a simulated run and its file (``<run stem>.truth.h5``).

Truth file layout (``truth_format_version`` 1)::

    /  attrs   truth_format_version, run_file, seed, fs, n_samples, duration_s,
               distance_m, alpha, v_ref_mps, sleeper_spacing_m, bin_length_m,
               noise_std_mps2, noise_band_hz (2,), force_noise_std_kn,
               unsprung_mass_kg, static_load_kn, with_forces, km_start,
               km_increasing, km_error_m, axle_positions (JSON),
               speed_response (JSON, :mod:`app.simulate.amplitude`; files without it
               used the power law ``(v / v_ref) ** alpha``)
    /line      attrs first_bin, bin_length, amplitude_vref (JSON)
               type_code int8 (nb,), factor (2, nb)
    /line/sections   track_from_m, track_to_m, type (strings)
    /line/anomalies  track_from_m, track_to_m, factor, taper_m, kind (strings)
    /speed_profile   t0, duration, v0, v1
    /line/surface    (lines with a rail surface) attrs seed, spectrum (JSON or "null")
    /line/surface/impacts    track_m, length_m, depth_m, side, kind (strings)
    /line/surface/grindings  track_from_m, track_to_m, date (strings), roughness_scale
    /wheels/<w>      attrs diameter_m, reported_diameter_m, side, axle, axle_offset_m
                     [flat_length_m, flat_depth_m, flat_angle_rad: a wheel flat]
                     rho_um (11,), psi_rad (11,)
    /bins/<w>        bin, track_m, km, s_m, t_s, speed_mps, section, stiffness_factor,
                     amplitude_vref_mps2, amplitude_mps2   (one row per 25 cm bin)

Root attributes added with the rail surfaces (absent in older files: nothing of
them simulated): ``confounders`` (JSON of :class:`app.simulate.run.Confounders`'s
switches) and ``run_date`` (ISO date the surfaces were taken at).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from app.simulate.amplitude import PowerLawResponse, SpeedResponse, speed_response_from_json
from app.simulate.speed import SpeedProfile
from app.simulate.surface import RailGrinding, RailSurface, RoughnessSpectrum, TrackImpact
from app.simulate.track import (
    SUPERSTRUCTURE_AMPLITUDE,
    SUPERSTRUCTURE_TYPES,
    LineModel,
    StiffnessAnomaly,
    TrackSection,
)
from app.simulate.wheels import WheelFlat, WheelOOR

__all__ = [
    "TRUTH_FORMAT_VERSION",
    "WheelBins",
    "SimulationTruth",
    "truth_path_for",
    "save_truth",
    "load_truth",
]

TRUTH_FORMAT_VERSION = 1
#: Scalar attributes of :class:`SimulationTruth` stored as root attributes, with their type.
_SCALAR_ATTRS: dict[str, type] = {
    "seed": int,
    "fs": float,
    "n_samples": int,
    "duration_s": float,
    "distance_m": float,
    "alpha": float,
    "v_ref_mps": float,
    "sleeper_spacing_m": float,
    "bin_length_m": float,
    "noise_std_mps2": float,
    "force_noise_std_kn": float,
    "unsprung_mass_kg": float,
    "static_load_kn": float,
    "with_forces": bool,
    "km_start": float,
    "km_increasing": bool,
    "km_error_m": float,
}
#: Those that files written before they existed lack, with the value to assume.
_OPTIONAL_ATTRS: dict[str, float] = {"km_error_m": 0.0}
_BIN_FIELDS = (
    "bin",
    "track_m",
    "km",
    "s_m",
    "t_s",
    "speed_mps",
    "section",
    "stiffness_factor",
    "amplitude_vref_mps2",
    "amplitude_mps2",
)


@dataclass(frozen=True)
class WheelBins:
    """Truth per 25 cm bin of one wheel's track position (rows ordered along the run).

    Attributes
    ----------
    bin : numpy.ndarray
        ``floor(track_m / 0.25)`` (int64).
    track_m : numpy.ndarray
        Bin centre on the km axis, m (``1000 * km``).
    km : numpy.ndarray
        Bin centre, km.
    s_m : numpy.ndarray
        Distance travelled by the vehicle since the run start when the wheel
        passes the bin centre, m.
    t_s : numpy.ndarray
        Time of that passage since the run start, s.
    speed_mps : numpy.ndarray
        Speed at that passage, m/s.
    section : numpy.ndarray
        Superstructure type code (index into ``SUPERSTRUCTURE_TYPES``).
    stiffness_factor : numpy.ndarray
        Local stiffness factor of the wheel's rail.
    amplitude_vref_mps2 : numpy.ndarray
        ``K_type * factor``: sleeper-passage amplitude at v_ref, m/s².
    amplitude_mps2 : numpy.ndarray
        Expected sleeper-passage amplitude at the passage speed, m/s².
    """

    bin: np.ndarray
    track_m: np.ndarray
    km: np.ndarray
    s_m: np.ndarray
    t_s: np.ndarray
    speed_mps: np.ndarray
    section: np.ndarray
    stiffness_factor: np.ndarray
    amplitude_vref_mps2: np.ndarray
    amplitude_mps2: np.ndarray

    def __len__(self) -> int:
        return int(self.bin.size)

    def section_names(self) -> np.ndarray:
        """Superstructure type name per bin."""
        return np.asarray(SUPERSTRUCTURE_TYPES, dtype=object)[self.section]


@dataclass(frozen=True)
class SimulationTruth:
    """Everything the simulator put into a run.

    Attributes
    ----------
    run_path, truth_path : Path
        The run file and this truth file.
    seed : int
        Seed of the run.
    fs : float
        Sample rate, Hz.
    n_samples : int
        Samples per channel.
    duration_s, distance_m : float
        Duration (s) and distance covered by the position reference (m).
    alpha, v_ref_mps : float
        Speed exponent (NaN unless the power law was simulated) and reference
        speed (m/s) of the sleeper amplitude ``a_s = K_type * factor * R_type(v)``.
    sleeper_spacing_m, bin_length_m : float
        Sleeper spacing and profile bin length, m.
    noise_std_mps2 : float
        Standard deviation of the band-limited noise on Z, m/s².
    noise_band_hz : tuple of float
        Its pass band, Hz.
    force_noise_std_kn : float
        Standard deviation of the white noise on Q, kN.
    unsprung_mass_kg : float
        Unsprung mass per wheel ``m_u`` in ``Q = Q_static + m_u * Z``, kg.
    static_load_kn : float
        Static wheel load, kN.
    with_forces : bool
        Whether Q channels were written.
    km_start : float
        Line km of the position reference at the first sample.
    km_increasing : bool
        Direction of the km axis along the run.
    axle_positions : dict[str, float]
        Axle positions relative to the position reference, m.
    line : LineModel
        Sections, anomalies and stiffness grid.
    speed_profile : SpeedProfile
        The exact speed profile.
    wheels : dict[str, WheelOOR]
        True OOR and diameter per wheel.
    reported_diameters : dict[str, float]
        Wheel diameters written to the run metadata, m.
    bins : dict[str, WheelBins]
        Truth per 25 cm bin per wheel.
    km_error_m : float
        Odometry error of the metadata's ``km_start``, m (the metadata states
        ``km_start + km_error_m / 1000``; everything here is in real positions).
    speed_response : SpeedResponse or None
        ``R_type(v)`` (:mod:`app.simulate.amplitude`); None means the power law
        with ``alpha`` and ``v_ref_mps``.
    confounders : object or None
        The run's switches of the surface contributions
        (:class:`app.simulate.run.Confounders`, or a dict of them as read back);
        None: none simulated (files before them).
    run_date : str or None
        ISO date at which the rail surface was taken (grinding up to it applies).
    """

    run_path: Path
    truth_path: Path
    seed: int
    fs: float
    n_samples: int
    duration_s: float
    distance_m: float
    alpha: float
    v_ref_mps: float
    sleeper_spacing_m: float
    bin_length_m: float
    noise_std_mps2: float
    noise_band_hz: tuple[float, float]
    force_noise_std_kn: float
    unsprung_mass_kg: float
    static_load_kn: float
    with_forces: bool
    km_start: float
    km_increasing: bool
    axle_positions: dict[str, float]
    line: LineModel
    speed_profile: SpeedProfile
    wheels: dict[str, WheelOOR]
    reported_diameters: dict[str, float]
    bins: dict[str, WheelBins]
    km_error_m: float = 0.0
    speed_response: SpeedResponse | None = None
    confounders: object | None = None
    run_date: str | None = None

    def __post_init__(self) -> None:
        if self.speed_response is None:
            object.__setattr__(self, "speed_response", PowerLawResponse(self.alpha, self.v_ref_mps))

    @property
    def path(self) -> Path:
        """The truth file (same as ``truth_path``)."""
        return self.truth_path

    def switch(self, name: str) -> bool:
        """Whether the surface contribution ``name`` (``"roughness"``, ``"track_impacts"``,
        ``"wheel_flats"``) was simulated (it still needs the line or wheel to carry one)."""
        c = self.confounders
        if c is None:
            return False
        return bool(c.get(name, False) if isinstance(c, dict) else getattr(c, name, False))

    def track_impacts(self, wheel: str) -> tuple[TrackImpact, ...]:
        """The welds and joints of its rail that wheel ``wheel`` rolled over (nothing if not simulated)."""
        surface = self.line.surface
        if surface is None or not self.switch("track_impacts"):
            return ()
        x = self.track_m(np.array([0.0, self.distance_m]), wheel[0])
        return surface.impacts_between(float(x.min()), float(x.max()), int(wheel[1]))

    @property
    def wheel_diameters(self) -> dict[str, float]:
        """True wheel diameters, m."""
        return {w: o.diameter_m for w, o in self.wheels.items()}

    def section_table(self) -> list[dict[str, float | str]]:
        """Superstructure sections (km from–to, type) of the line."""
        return self.line.section_table()

    def track_m(self, s: np.ndarray, axle: str) -> np.ndarray:
        """Track position (m on the km axis) of an axle when the vehicle has travelled ``s`` m."""
        sign = 1.0 if self.km_increasing else -1.0
        return 1000.0 * self.km_start + sign * (np.asarray(s) + self.axle_positions[axle])


def truth_path_for(run_path: Path) -> Path:
    """``<stem>.truth.h5`` beside a run file."""
    run_path = Path(run_path)
    return run_path.with_name(f"{run_path.stem}.truth.h5")


def _strings(values: list[str]) -> np.ndarray:
    return np.array(values, dtype=h5py.string_dtype())


def _scalar(attrs: h5py.AttributeManager, key: str, cast: type) -> object:
    if key in _OPTIONAL_ATTRS:
        return cast(attrs.get(key, _OPTIONAL_ATTRS[key]))
    return cast(attrs[key])


def save_truth(truth: SimulationTruth, h5: h5py.File) -> None:
    """Write ``truth`` into an open HDF5 file (layout in the module docstring)."""
    a = h5.attrs
    a["truth_format_version"] = TRUTH_FORMAT_VERSION
    a["run_file"] = truth.run_path.name
    for key in _SCALAR_ATTRS:
        a[key] = getattr(truth, key)
    a["noise_band_hz"] = np.asarray(truth.noise_band_hz, dtype=np.float64)
    a["axle_positions"] = json.dumps(truth.axle_positions)
    a["speed_response"] = truth.speed_response.to_json()
    if truth.confounders is not None:
        c = truth.confounders
        a["confounders"] = json.dumps(dict(c) if isinstance(c, dict) else
                                      {k: bool(getattr(c, k)) for k in ("roughness", "track_impacts", "wheel_flats")})
    if truth.run_date is not None:
        a["run_date"] = truth.run_date
    line = truth.line
    g = h5.create_group("line")
    g.attrs["first_bin"] = line.first_bin
    g.attrs["bin_length"] = line.bin_length
    g.attrs["amplitude_vref"] = json.dumps(line.amplitude_vref)
    g.attrs["types"] = json.dumps(list(SUPERSTRUCTURE_TYPES))
    g.create_dataset("type_code", data=line.type_code, compression="gzip")
    g.create_dataset("factor", data=line.factor, compression="gzip")
    sec = g.create_group("sections")
    sec["track_from_m"] = np.array([s.track_from_m for s in line.sections], dtype=np.float64)
    sec["track_to_m"] = np.array([s.track_to_m for s in line.sections], dtype=np.float64)
    sec["type"] = _strings([s.type for s in line.sections])
    an = g.create_group("anomalies")
    an["track_from_m"] = np.array([x.track_from_m for x in line.anomalies], dtype=np.float64)
    an["track_to_m"] = np.array([x.track_to_m for x in line.anomalies], dtype=np.float64)
    an["factor"] = np.array([x.factor for x in line.anomalies], dtype=np.float64)
    an["taper_m"] = np.array([x.taper_m for x in line.anomalies], dtype=np.float64)
    an["kind"] = _strings([x.kind for x in line.anomalies])
    if line.surface is not None:
        _save_surface(line.surface, g.create_group("surface"))
    sp = h5.create_group("speed_profile")
    for key in ("t0", "duration", "v0", "v1"):
        sp[key] = getattr(truth.speed_profile, key)
    wg = h5.create_group("wheels")
    for w, oor in truth.wheels.items():
        g = wg.create_group(w)
        g.attrs["diameter_m"] = oor.diameter_m
        g.attrs["reported_diameter_m"] = truth.reported_diameters[w]
        g.attrs["side"] = int(w[1])
        g.attrs["axle"] = w[0]
        g.attrs["axle_offset_m"] = truth.axle_positions[w[0]]
        if oor.flat is not None:
            g.attrs["flat_length_m"] = oor.flat.length_m
            g.attrs["flat_depth_m"] = oor.flat.depth_m
            g.attrs["flat_angle_rad"] = oor.flat.angle_rad
        g["rho_um"] = oor.rho_um
        g["psi_rad"] = oor.psi_rad
    bg = h5.create_group("bins")
    for w, b in truth.bins.items():
        g = bg.create_group(w)
        for key in _BIN_FIELDS:
            g.create_dataset(key, data=getattr(b, key), compression="gzip", shuffle=True)


def _save_surface(surface: RailSurface, g: h5py.Group) -> None:
    g.attrs["seed"] = surface.seed
    sp = surface.spectrum
    g.attrs["spectrum"] = "null" if sp is None else json.dumps(
        {"a": sp.a, "wavelength_m": list(sp.wavelength_m), "scale": sp.scale})
    im = g.create_group("impacts")
    im["track_m"] = np.array([w.track_m for w in surface.impacts], dtype=np.float64)
    im["length_m"] = np.array([w.length_m for w in surface.impacts], dtype=np.float64)
    im["depth_m"] = np.array([w.depth_m for w in surface.impacts], dtype=np.float64)
    im["side"] = np.array([w.side for w in surface.impacts], dtype=np.int8)
    im["kind"] = _strings([w.kind for w in surface.impacts])
    gr = g.create_group("grindings")
    gr["track_from_m"] = np.array([x.track_from_m for x in surface.grindings], dtype=np.float64)
    gr["track_to_m"] = np.array([x.track_to_m for x in surface.grindings], dtype=np.float64)
    gr["date"] = _strings([x.date for x in surface.grindings])
    gr["roughness_scale"] = np.array([x.roughness_scale for x in surface.grindings], dtype=np.float64)


def _load_surface(g: h5py.Group) -> RailSurface:
    spec = json.loads(g.attrs["spectrum"])
    im, gr = g["impacts"], g["grindings"]
    impacts = tuple(
        TrackImpact(float(x), float(n), float(d), int(sd), str(k))
        for x, n, d, sd, k in zip(im["track_m"][()], im["length_m"][()], im["depth_m"][()], im["side"][()],
                                  im["kind"].asstr()[()], strict=True)
    )
    grindings = tuple(
        RailGrinding(float(a), float(b), str(d), float(sc))
        for a, b, d, sc in zip(gr["track_from_m"][()], gr["track_to_m"][()], gr["date"].asstr()[()],
                               gr["roughness_scale"][()], strict=True)
    )
    spectrum = None if spec is None else RoughnessSpectrum(float(spec["a"]), tuple(spec["wavelength_m"]),
                                                           float(spec["scale"]))
    return RailSurface(int(g.attrs["seed"]), spectrum, impacts, grindings)


def load_truth(path: Path | str) -> SimulationTruth:
    """Read a truth file written by :func:`app.simulate.run.simulate_run`.

    Parameters
    ----------
    path : Path or str
        The ``.truth.h5`` file.

    Returns
    -------
    SimulationTruth
    """
    path = Path(path)
    with h5py.File(path, "r") as h5:
        a = h5.attrs
        if int(a.get("truth_format_version", -1)) != TRUTH_FORMAT_VERSION:
            raise ValueError(f"path: {path.name} is not a trackvkf truth file (version 1)")
        g = h5["line"]
        types = json.loads(g.attrs["types"])
        if types != list(SUPERSTRUCTURE_TYPES[: len(types)]):  # types are only ever appended
            raise ValueError(f"path: unsupported superstructure types {types}")
        sec = g["sections"]
        sections = tuple(
            TrackSection(float(f), float(t), str(ty))
            for f, t, ty in zip(
                sec["track_from_m"][()], sec["track_to_m"][()], sec["type"].asstr()[()], strict=True
            )
        )
        an = g["anomalies"]
        anomalies = tuple(
            StiffnessAnomaly(float(f), float(t), float(fa), float(tp), str(k))
            for f, t, fa, tp, k in zip(
                an["track_from_m"][()],
                an["track_to_m"][()],
                an["factor"][()],
                an["taper_m"][()],
                an["kind"].asstr()[()],
                strict=True,
            )
        )
        line = LineModel(
            first_bin=int(g.attrs["first_bin"]),
            type_code=g["type_code"][()],
            factor=g["factor"][()],
            sections=sections,
            anomalies=anomalies,
            # a file written before a type was appended lacks it: the default (no bin of the file has it)
            amplitude_vref={**SUPERSTRUCTURE_AMPLITUDE, **json.loads(g.attrs["amplitude_vref"])},
            bin_length=float(g.attrs["bin_length"]),
            surface=_load_surface(g["surface"]) if "surface" in g else None,
        )
        sp = h5["speed_profile"]
        profile = SpeedProfile(sp["t0"][()], sp["duration"][()], sp["v0"][()], sp["v1"][()])
        wheels: dict[str, WheelOOR] = {}
        reported: dict[str, float] = {}
        for w, wg in h5["wheels"].items():
            flat = None
            if "flat_length_m" in wg.attrs:
                flat = WheelFlat(float(wg.attrs["flat_length_m"]), float(wg.attrs["flat_depth_m"]),
                                 float(wg.attrs["flat_angle_rad"]))
            wheels[w] = WheelOOR(
                w, float(wg.attrs["diameter_m"]), wg["rho_um"][()], wg["psi_rad"][()], flat
            )
            reported[w] = float(wg.attrs["reported_diameter_m"])
        bins = {
            w: WheelBins(**{key: bg[key][()] for key in _BIN_FIELDS})
            for w, bg in h5["bins"].items()
        }
        return SimulationTruth(
            run_path=path.with_name(str(a["run_file"])),
            truth_path=path,
            **{key: _scalar(a, key, cast) for key, cast in _SCALAR_ATTRS.items()},
            noise_band_hz=tuple(float(x) for x in a["noise_band_hz"]),  # type: ignore[arg-type]
            axle_positions=json.loads(a["axle_positions"]),
            speed_response=speed_response_from_json(a["speed_response"]) if "speed_response" in a else None,
            line=line,
            speed_profile=profile,
            wheels=wheels,
            reported_diameters=reported,
            bins=bins,
            confounders=json.loads(a["confounders"]) if "confounders" in a else None,
            run_date=str(a["run_date"]) if "run_date" in a else None,
        )
