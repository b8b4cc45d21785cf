"""A simulated run as a measurement recorder writes it: MDF4 or TDMS, odometry and GNSS.

The canonical simulated run (:func:`app.simulate.run.simulate_run`) is
re-written the way an on-board recorder stores it:

* group ``ABA`` at the run's sample rate: ``AccZ_1R`` … ``AccZ_4L`` in g and,
  with forces, ``Fz_1R`` … ``Fz_4L`` in N;
* group ``CAN`` at ``OdometrySimulation.rate_hz``: ``v_train`` (km/h) and
  ``odo`` (m) — the odometry, drifting from the truth by a scale error and a
  slow wander;
* group ``GNSS`` at ``GnssSimulation.rate_hz``: ``GPS_Lat``/``GPS_Lon``
  (degrees) of the position reference on the synthetic line geometry
  (:mod:`app.simulate.geometry`), with Gaussian noise (optionally
  time-correlated), a few multipath outliers and outages (no records).

Beside the file: the line geometry (GeoJSON), the channel map and the
metadata (JSON) that an operator would use to upload it. The truth of the
position reference's chainage at any time is :meth:`RecorderRun.true_chainage_m`.
"""

from __future__ import annotations

import datetime as dt
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from app.analysis.units import KMH_PER_MPS
from app.io import open_run
from app.io.channel_map import STANDARD_GRAVITY
from app.io.geometry import LineGeometry
from app.simulate.geometry import synthetic_line, write_geometry
from app.simulate.run import simulate_run
from app.simulate.truth import SimulationTruth

__all__ = [
    "GnssSimulation",
    "OdometrySimulation",
    "RecorderRun",
    "RECORDER_CHANNEL_MAP",
    "simulate_recorder_run",
    "write_recorder_file",
]

_SIDE = {"1": "R", "2": "L"}
#: The channel map of the simulated recorder (trackvkf channel → recorder channel).
RECORDER_CHANNEL_MAP: dict[str, Any] = {
    "name": "trackvkf simulated recorder",
    "channels": {
        **{f"Z{w}": {"source": f"AccZ_{w[0]}{_SIDE[w[1]]}", "unit": "g"} for w in ("11", "12", "41", "42")},
        **{f"Q{w}": f"Fz_{w[0]}{_SIDE[w[1]]}" for w in ("11", "12", "41", "42")},
        "speed": "v_train",
        "position": "odo",
        "lat": "GPS_Lat",
        "lon": "GPS_Lon",
    },
}


@dataclass(frozen=True)
class GnssSimulation:
    """GNSS receiver model.

    Attributes
    ----------
    rate_hz : float
        Fix rate, Hz (default 10).
    noise_m : float
        Standard deviation of the position noise per horizontal axis, m (default 3).
    noise_corr_s : float
        Correlation time of the noise (first-order Gauss–Markov), s; 0 = white.
    outage_s : float
        Length of each outage, s (default 30).
    outage_every_s : float
        One outage per this many seconds of run, the first after half of it (default 240).
    outlier_fraction : float
        Fraction of fixes with a multipath jump (default 0.005).
    outlier_m : float
        Size of a jump, m (default 80).
    """

    rate_hz: float = 10.0
    noise_m: float = 3.0
    noise_corr_s: float = 0.0
    outage_s: float = 30.0
    outage_every_s: float = 240.0
    outlier_fraction: float = 0.005
    outlier_m: float = 80.0


@dataclass(frozen=True)
class OdometrySimulation:
    """Odometry model: ``odo = (1 + scale_error) s + wander_m sin(2π s / wander_wavelength_m)``.

    Attributes
    ----------
    rate_hz : float
        Record rate of speed and odometry, Hz (default 100).
    scale_error : float
        Relative scale error (wheel diameter), default 0.004.
    wander_m : float
        Amplitude of the slow wander (slip), m (default 1).
    wander_wavelength_m : float
        Its wavelength along the track, m (default 5000).
    """

    rate_hz: float = 100.0
    scale_error: float = 0.004
    wander_m: float = 1.0
    wander_wavelength_m: float = 5000.0

    def odometry(self, s: np.ndarray) -> np.ndarray:
        """Odometry (m) at true distances ``s`` (m)."""
        return (1.0 + self.scale_error) * s + self.wander_m * np.sin(
            2.0 * np.pi * s / self.wander_wavelength_m
        )


@dataclass(frozen=True)
class RecorderRun:
    """A simulated recorder file and what belongs to it.

    Attributes
    ----------
    path : Path
        The recorder file.
    fmt : str
        ``"mdf4"`` or ``"tdms"``.
    canonical_path : Path
        The canonical run it was made from (the truth beside it).
    truth : SimulationTruth
        Truth of the canonical run.
    geometry : LineGeometry or None
        The line geometry (GNSS runs).
    geometry_path, channel_map_path, metadata_path : Path or None
        GeoJSON, channel map and metadata files.
    metadata : dict
        Upload metadata.
    channel_map : dict
        The channel map.
    outages : list of tuple
        GNSS outages ``(t_from, t_to)``, s.
    """

    path: Path
    fmt: str
    canonical_path: Path
    truth: SimulationTruth
    geometry: LineGeometry | None
    geometry_path: Path | None
    channel_map_path: Path
    metadata_path: Path
    metadata: dict[str, Any]
    channel_map: dict[str, Any]
    outages: list[tuple[float, float]] = field(default_factory=list)

    def true_chainage_m(self, t: np.ndarray) -> np.ndarray:
        """Line chainage (m, km × 1000) of the position reference at times ``t`` (s)."""
        s = self.truth.speed_profile.distance(np.asarray(t, dtype=np.float64))
        sign = 1.0 if self.truth.km_increasing else -1.0
        return 1000.0 * self.truth.km_start + sign * s


def _outages(duration: float, cfg: GnssSimulation) -> list[tuple[float, float]]:
    out = []
    t = cfg.outage_every_s / 2.0
    while t + cfg.outage_s < duration - cfg.outage_s:
        out.append((t, t + cfg.outage_s))
        t += cfg.outage_every_s
    return out


def _gnss(
    run: RecorderRun, geometry: LineGeometry, cfg: GnssSimulation, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    duration = run.truth.duration_s
    t = np.arange(0.0, duration, 1.0 / cfg.rate_hz)
    for a, b in run.outages:
        t = t[(t < a) | (t > b)]
    x, y = geometry.polyline().point_at(run.true_chainage_m(t))
    noise = rng.standard_normal((2, t.size)) * cfg.noise_m
    if cfg.noise_corr_s > 0:
        phi = math.exp(-1.0 / (cfg.rate_hz * cfg.noise_corr_s))
        innov = noise * math.sqrt(1.0 - phi * phi)
        noise[:, 0] = rng.standard_normal(2) * cfg.noise_m
        for k in range(1, t.size):
            noise[:, k] = phi * noise[:, k - 1] + innov[:, k]
    jumps = rng.random(t.size) < cfg.outlier_fraction
    angle = rng.uniform(0.0, 2.0 * np.pi, jumps.sum())
    noise[0, jumps] += cfg.outlier_m * np.cos(angle)
    noise[1, jumps] += cfg.outlier_m * np.sin(angle)
    lon, lat = geometry.from_local(x + noise[0], y + noise[1])
    return t, lat, lon


def write_recorder_file(
    canonical: Path,
    dest: Path,
    fmt: Literal["mdf4", "tdms"],
    *,
    odometry: np.ndarray,
    odometry_t: np.ndarray,
    speed_kmh: np.ndarray,
    gnss: tuple[np.ndarray, np.ndarray, np.ndarray] | None,
    start_time: dt.datetime,
    block_samples: int = 2**18,
) -> Path:
    """Write the channels of a canonical run plus slow groups as an MDF4 or TDMS file.

    Parameters
    ----------
    canonical : Path
        Canonical run file (its Z and Q channels are written block by block).
    dest : Path
        Recorder file to write.
    fmt : {"mdf4", "tdms"}
        Format.
    odometry, odometry_t, speed_kmh : numpy.ndarray
        The ``CAN`` group: odometry (m) and speed (km/h) at times ``odometry_t`` (s).
    gnss : (t, lat, lon) or None
        The ``GNSS`` group (s, degrees).
    start_time : datetime
        Recording start (written to the header / ``wf_start_time``).
    block_samples : int
        Samples of the ABA group written at once.
    """
    dest = Path(dest)
    with open_run(canonical) as run:
        names: dict[str, tuple[str, str, float]] = {}
        for c in run.channels:
            if c.startswith("Z"):
                names[c] = (f"AccZ_{c[1]}{_SIDE[c[2]]}", "g", 1.0 / STANDARD_GRAVITY)
            elif c.startswith("Q"):
                names[c] = (f"Fz_{c[1]}{_SIDE[c[2]]}", "N", 1000.0)
        slow = [("CAN", odometry_t, {"v_train": (speed_kmh, "km/h"), "odo": (odometry, "m")})]
        if gnss is not None:
            gt, lat, lon = gnss
            slow.append(("GNSS", gt, {"GPS_Lat": (lat, "deg"), "GPS_Lon": (lon, "deg")}))
        n, fs = run.n_samples, run.fs
        if fmt == "mdf4":
            _write_mdf4(run, dest, names, slow, start_time, n, fs, block_samples)
        elif fmt == "tdms":
            _write_tdms(run, dest, names, slow, start_time, n, fs, block_samples)
        else:
            raise ValueError(f"fmt must be 'mdf4' or 'tdms', got {fmt!r}")
    return dest


def _write_mdf4(run, dest, names, slow, start_time, n, fs, block) -> None:  # noqa: ANN001
    from asammdf import MDF, Signal

    mdf = MDF(version="4.10")
    mdf.header.start_time = start_time
    try:
        for a in range(0, n, block):
            b = min(a + block, n)
            t = np.arange(a, b) / fs
            values = [(run.read(c, a, b) * f).astype(np.float32) for c, (_, _, f) in names.items()]
            if a == 0:
                mdf.append(
                    [
                        Signal(v, t, name=nm, unit=u)
                        for v, (nm, u, _) in zip(values, names.values(), strict=True)
                    ],
                    acq_name="ABA",
                    comment="ABA",
                )
            else:
                mdf.extend(0, [(t, None), *((v, None) for v in values)])
        for label, t, chans in slow:
            mdf.append(
                [Signal(np.asarray(v), t, name=nm, unit=u) for nm, (v, u) in chans.items()],
                acq_name=label,
                comment=label,
            )
        mdf.save(dest, overwrite=True, compression=2)
    finally:
        mdf.close()


def _write_tdms(run, dest, names, slow, start_time, n, fs, block) -> None:  # noqa: ANN001
    from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

    start = np.datetime64(start_time.astimezone(dt.UTC).replace(tzinfo=None), "us")
    with TdmsWriter(dest) as writer:
        writer.write_segment([RootObject(properties={"name": "trackvkf simulated run"})])
        for a in range(0, n, block):
            b = min(a + block, n)
            objs: list[Any] = [GroupObject("ABA")]
            for c, (nm, u, f) in names.items():
                props = {"unit_string": u, "wf_increment": 1.0 / fs, "wf_start_offset": 0.0,
                         "wf_start_time": start}
                objs.append(ChannelObject("ABA", nm, (run.read(c, a, b) * f).astype(np.float32), props))
            writer.write_segment(objs)
        for label, t, chans in slow:
            objs = [GroupObject(label), ChannelObject(label, "Time", np.asarray(t, dtype=np.float64),
                                                      {"unit_string": "s"})]
            for nm, (v, u) in chans.items():
                objs.append(ChannelObject(label, nm, np.asarray(v, dtype=np.float64), {"unit_string": u}))
            writer.write_segment(objs)


def simulate_recorder_run(
    dest: Path | str,
    fmt: Literal["mdf4", "tdms"] = "mdf4",
    *,
    gnss: GnssSimulation | None = None,
    odometry: OdometrySimulation | None = None,
    seed: int = 0,
    **simulate_kwargs: Any,
) -> RecorderRun:
    """Simulate a run and write it as a recorder file with its upload companions.

    Parameters
    ----------
    dest : Path or str
        Recorder file (``.mf4`` or ``.tdms``). Beside it: ``<stem>.canonical.h5``
        (+ its truth), ``<stem>.channel-map.json``, ``<stem>.metadata.json`` and,
        with GNSS, ``<stem>.line.geojson``.
    fmt : {"mdf4", "tdms"}
        Recorder format.
    gnss : GnssSimulation, optional
        GNSS model; ``None`` writes no GNSS group (the metadata then gives
        ``km_start`` with relative positions).
    odometry : OdometrySimulation, optional
        Odometry model (default :class:`OdometrySimulation`).
    seed : int
        Seed of the run, the line layout and the GNSS noise.
    **simulate_kwargs
        Passed to :func:`app.simulate.run.simulate_run` (``length_km``, ``fs`` …).

    Returns
    -------
    RecorderRun
    """
    dest = Path(dest)
    odo_cfg = odometry or OdometrySimulation()
    canonical = dest.with_name(dest.stem + ".canonical.h5")
    truth = simulate_run(canonical, seed=seed, **simulate_kwargs)
    with open_run(canonical) as run:
        meta = run.metadata
    t_odo = np.arange(0.0, truth.duration_s + 0.5 / odo_cfg.rate_hz, 1.0 / odo_cfg.rate_hz)
    v, _, s = truth.speed_profile.evaluate(t_odo)
    metadata: dict[str, Any] = {
        "vehicle_id": meta.vehicle_id,
        "start_time": meta.start_time.isoformat(),
        "line_id": meta.line_id,
        "track": meta.track,
        "direction": meta.direction,
        "wheel_diameters": dict(meta.wheel_diameters),
        "axle_positions": dict(meta.axle_positions),
        "sleeper_spacing": meta.sleeper_spacing,
    }
    geometry = geometry_path = None
    outages: list[tuple[float, float]] = []
    rec = RecorderRun(
        path=dest, fmt=fmt, canonical_path=canonical, truth=truth, geometry=None,
        geometry_path=None, channel_map_path=dest.with_name(dest.stem + ".channel-map.json"),
        metadata_path=dest.with_name(dest.stem + ".metadata.json"), metadata=metadata,
        channel_map=json.loads(json.dumps(RECORDER_CHANNEL_MAP)), outages=outages,
    )
    if not truth.with_forces:
        rec.channel_map["channels"] = {
            k: v for k, v in rec.channel_map["channels"].items() if not k.startswith("Q")
        }
    gnss_arrays = None
    if gnss is not None:
        ends = rec.true_chainage_m(np.array([0.0, truth.duration_s])) / 1000.0
        axles = [float(x) for x in meta.axle_positions.values()]
        margin = (max(abs(a) for a in axles) + 500.0) / 1000.0
        geometry, doc = synthetic_line(
            float(ends.min()) - margin, float(ends.max()) + margin, seed=seed,
            line_id=meta.line_id, track=meta.track,
        )
        geometry_path = write_geometry(dest.with_name(dest.stem + ".line.geojson"), doc)
        outages.extend(_outages(truth.duration_s, gnss))
        gnss_arrays = _gnss(rec, geometry, gnss, np.random.default_rng([int(seed), 23]))
        metadata["position_kind"] = "gnss"
    else:
        metadata.update(
            {"km_start": meta.km_start, "km_increasing": meta.km_increasing, "position_kind": "relative"}
        )
        channels = dict(rec.channel_map["channels"])
        channels.pop("lat")
        channels.pop("lon")
        rec.channel_map["channels"] = channels
    write_recorder_file(
        canonical, dest, fmt, odometry=odo_cfg.odometry(s), odometry_t=t_odo, speed_kmh=v * KMH_PER_MPS,
        gnss=gnss_arrays, start_time=meta.start_time,
    )
    rec.channel_map_path.write_text(json.dumps(rec.channel_map, indent=1), encoding="utf-8")
    rec.metadata_path.write_text(json.dumps(metadata, indent=1), encoding="utf-8")
    return RecorderRun(**{**rec.__dict__, "geometry": geometry, "geometry_path": geometry_path})
