"""A synthetic fleet history: many runs over one simulated line, with planted changes.

Simulating and processing the raw accelerations of a year of daily runs over a
50 km line would take days; the condition store only needs what the pipeline
leaves of each run: per wheel, the sleeper-passage amplitude and the speed
along the track. :class:`FleetSimulator` writes those directly from the
simulator's truth (:class:`~app.simulate.track.LineModel`) on a grid of
``grid_m`` (default 1 m):

    A(x, day) = K_type(x) · f_side(x) · (v(x) / v_ref) ** alpha · planted(x, day) · exp(ε)

with ``v(x)`` the run's speed (its own level, ± ``speed_spread``, and a smooth
variation along the line), ``planted`` the changes of a :class:`FleetPlan`
(steps, gradual trends, maintenance actions with their recovery and the
degradation after it) and ``ε`` the repeatability noise of :class:`FleetNoise`:
a per-run and wheel offset plus noise along the track that is smooth over
``correlation_m``. Its defaults are about twice what the real pipeline gives
on simulated runs at equal speed (``bench/bench_condition_noise.py``: 0.018
per 10 m segment, 0.011 per 100 m, wheels independent), because the field adds
what the simulator leaves out (rail temperature, wheel wear, sensor mounting).

Everything is reproducible from the seed; :meth:`FleetPlan.factor` is the
truth a detection is scored against (:mod:`app.simulate.fleet_scoring`). The runs' segments
with the store's index and their change tests are the condition store's business
(:func:`app.condition.fleet.fleet_history`, :func:`app.condition.fleet.ingest_fleet`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from app.analysis.condition import RunAssessment, SegmentStats
from app.analysis.units import DAYS_PER_YEAR, KMH_PER_MPS
from app.simulate.track import LineModel

__all__ = [
    "FleetNoise",
    "PlantedStep",
    "PlantedTrend",
    "PlantedAction",
    "FleetPlan",
    "random_plan",
    "WheelTrack",
    "FleetSimulator",
    "FLEET_WHEELS",
    "FleetDay",
]

#: Wheels of the simulated vehicle: axle 1 and 4, sides 1 (right) and 2 (left).
FLEET_WHEELS: tuple[str, ...] = ("11", "12", "41", "42")


@dataclass(frozen=True)
class FleetNoise:
    """Run-to-run repeatability of the simulated amplitude (natural log units).

    Attributes
    ----------
    segment_sd : float
        Standard deviation of a 10 m segment's mean log amplitude between runs
        at equal speed, from the noise along the track.
    correlation_m : float
        Correlation length of that noise along the track, m.
    run_sd : float
        Standard deviation of a per-run and wheel offset (calibration, temperature).
    speed_spread : float
        Runs pass at the nominal speed times ``1 ± speed_spread`` (uniform).
    speed_wobble : float
        Relative variation of the speed along the line (smooth over kilometres).
    """

    segment_sd: float = 0.04
    correlation_m: float = 20.0
    run_sd: float = 0.02
    speed_spread: float = 0.08
    speed_wobble: float = 0.04

    def __post_init__(self) -> None:
        for name in ("segment_sd", "run_sd", "speed_spread", "speed_wobble"):
            value = getattr(self, name)
            if not (np.isfinite(value) and 0 <= value < 1):
                raise ValueError(f"{name}: must be in [0, 1), got {value!r}")
        if not (np.isfinite(self.correlation_m) and self.correlation_m > 0):
            raise ValueError(f"correlation_m: must be > 0 m, got {self.correlation_m!r}")


@dataclass(frozen=True)
class PlantedStep:
    """The amplitude over ``[track_from_m, track_to_m)`` is multiplied by ``factor`` from ``day`` on."""

    track_from_m: float
    track_to_m: float
    day: float
    factor: float

    def factor_at(self, x: np.ndarray, day: float) -> np.ndarray:
        """Multiplicative factor at positions ``x`` (m) on ``day``."""
        inside = (x >= self.track_from_m) & (x < self.track_to_m)
        return np.where(inside & (day >= self.day), self.factor, 1.0)


@dataclass(frozen=True)
class PlantedTrend:
    """From ``day`` on the amplitude over the extent grows by ``rate_per_year`` (relative) per year."""

    track_from_m: float
    track_to_m: float
    day: float
    rate_per_year: float

    def factor_at(self, x: np.ndarray, day: float) -> np.ndarray:
        """Multiplicative factor at positions ``x`` (m) on ``day``."""
        inside = (x >= self.track_from_m) & (x < self.track_to_m)
        years = max(day - self.day, 0.0) / DAYS_PER_YEAR
        return np.where(inside, (1.0 + self.rate_per_year) ** years, 1.0)


@dataclass(frozen=True)
class PlantedAction:
    """A maintenance action: on ``day`` the amplitude over the extent drops by ``recovery``
    (relative), then grows back by ``regrowth_per_year`` (relative to the level before) until it
    is where it was."""

    track_from_m: float
    track_to_m: float
    day: float
    type: str = "tamping"
    recovery: float = 0.15
    regrowth_per_year: float = 0.10

    def factor_at(self, x: np.ndarray, day: float) -> np.ndarray:
        """Multiplicative factor at positions ``x`` (m) on ``day``."""
        if day < self.day:
            return np.ones_like(x, dtype=np.float64)
        years = (day - self.day) / DAYS_PER_YEAR
        level = min(1.0 - self.recovery + self.regrowth_per_year * years, 1.0)
        inside = (x >= self.track_from_m) & (x < self.track_to_m)
        return np.where(inside, level, 1.0)

    @property
    def half_life_days(self) -> float:
        """Days until half the recovery is lost again."""
        if self.regrowth_per_year <= 0:
            return float("inf")
        return 0.5 * self.recovery / self.regrowth_per_year * DAYS_PER_YEAR


@dataclass(frozen=True)
class FleetPlan:
    """The planted changes of a fleet history (positions in m on the km axis, days from day 0)."""

    steps: tuple[PlantedStep, ...] = ()
    trends: tuple[PlantedTrend, ...] = ()
    actions: tuple[PlantedAction, ...] = ()

    def factor(self, x: np.ndarray, day: float) -> np.ndarray:
        """Product of all planted factors at positions ``x`` (m) on ``day``."""
        out = np.ones(np.shape(x), dtype=np.float64)
        for event in (*self.steps, *self.trends, *self.actions):
            out *= event.factor_at(np.asarray(x, dtype=np.float64), day)
        return out


def random_plan(
    track_from_m: float,
    track_to_m: float,
    n_days: int,
    seed: int | np.random.Generator = 0,
    *,
    n_steps: int = 6,
    n_trends: int = 3,
    n_actions: int = 4,
    step_length_m: float = 20.0,
    step_size: float = 0.2,
    trend_rate_per_year: float = 0.10,
    trend_length_m: tuple[float, float] = (200.0, 500.0),
    action_length_m: tuple[float, float] = (100.0, 400.0),
    gap_m: float = 300.0,
) -> FleetPlan:
    """Random planted changes that do not overlap (at least ``gap_m`` apart; the long ones are
    placed first, fewer are placed where they do not fit).

    Steps (``step_size`` up or down over ``step_length_m``) happen in the second
    half of the history, trends (``trend_rate_per_year``, up) start in its
    middle third, maintenance actions (tamping) anywhere after the first
    quarter.
    """
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    placed: list[tuple[float, float]] = []

    def place(length: float) -> tuple[float, float] | None:
        for _ in range(1000):
            a = float(rng.uniform(track_from_m + gap_m, track_to_m - gap_m - length))
            b = a + length
            if all(b + gap_m <= lo or hi + gap_m <= a for lo, hi in placed):
                placed.append((a, b))
                return a, b
        return None

    steps, trends, actions = [], [], []
    for _ in range(n_trends):
        where = place(float(rng.uniform(*trend_length_m)))
        if where is not None:
            trends.append(PlantedTrend(*where, day=float(rng.uniform(1 / 3, 2 / 3) * n_days),
                                       rate_per_year=trend_rate_per_year))
    for _ in range(n_actions):
        where = place(float(rng.uniform(*action_length_m)))
        if where is not None:
            actions.append(PlantedAction(*where, day=float(rng.uniform(0.25, 0.8) * n_days)))
    for i in range(n_steps):
        where = place(step_length_m)
        if where is not None:
            sign = 1.0 if i % 2 == 0 else -1.0
            day = float(rng.uniform(0.5, 0.95) * n_days)
            steps.append(PlantedStep(*where, day=day, factor=1.0 + sign * step_size))
    return FleetPlan(tuple(steps), tuple(trends), tuple(actions))


@dataclass(frozen=True)
class WheelTrack:
    """What the pipeline leaves of one wheel of a run: amplitude and speed along the track.

    Attributes
    ----------
    position_m : numpy.ndarray
        Grid positions on the km axis, m (cell centres).
    amplitude : numpy.ndarray
        Sleeper-passage amplitude, m/s².
    speed_mps : numpy.ndarray
        Speed, m/s.
    """

    position_m: np.ndarray
    amplitude: np.ndarray
    speed_mps: np.ndarray


def _smooth(rng: np.random.Generator, n: int, corr_cells: float) -> np.ndarray:
    """Unit-variance noise with a Gaussian autocorrelation of ``corr_cells`` cells (FFT convolution)."""
    if corr_cells < 0.5:
        return rng.standard_normal(n)
    half = int(np.ceil(3 * corr_cells))
    k = np.arange(-half, half + 1)
    kernel = np.exp(-0.5 * (k / corr_cells) ** 2)
    kernel /= np.sqrt(np.sum(kernel**2))
    white = rng.standard_normal(n + 2 * half)
    size = 1 << int(np.ceil(np.log2(white.size + kernel.size)))
    out = np.fft.irfft(np.fft.rfft(white, size) * np.fft.rfft(kernel, size), size)
    return out[2 * half: 2 * half + n]


@dataclass
class FleetSimulator:
    """Runs of a fleet over one line (see the module docstring).

    Parameters
    ----------
    line : LineModel
        The line (stiffness truth).
    plan : FleetPlan
        Planted changes.
    noise : FleetNoise
        Repeatability.
    speed_kmh : float
        Nominal speed of the runs, km/h.
    alpha : float
        Speed exponent of the amplitude.
    v_ref_kmh : float
        Speed at which ``K_type`` holds, km/h.
    grid_m : float
        Grid step of the simulated tracks, m (a multiple of the line's bin length).
    """

    line: LineModel
    plan: FleetPlan = field(default_factory=FleetPlan)
    noise: FleetNoise = field(default_factory=FleetNoise)
    speed_kmh: float = 120.0
    alpha: float = 1.5
    v_ref_kmh: float = 100.0
    grid_m: float = 1.0

    def __post_init__(self) -> None:
        ratio = self.grid_m / self.line.bin_length
        self._k = int(round(ratio))
        if self._k < 1 or abs(ratio - self._k) > 1e-9:
            raise ValueError(f"grid_m: must be a multiple of the line's bin length {self.line.bin_length}")
        if not (np.isfinite(self.speed_kmh) and self.speed_kmh > 0):
            raise ValueError(f"speed_kmh: must be > 0, got {self.speed_kmh!r}")
        n = self.line.n_bins // self._k
        self._position = self.line.track_from_m + (np.arange(n) + 0.5) * self.grid_m
        self._base = {side: self.line.amplitude_grid(side)[: n * self._k].reshape(n, self._k).mean(axis=1)
                      for side in (1, 2)}
        # the point noise's sd that gives segment_sd for a 10 m mean
        probe = np.random.default_rng(12345)
        corr = self.noise.correlation_m / self.grid_m
        cells = max(int(round(10.0 / self.grid_m)), 1)
        sample = _smooth(probe, cells * 4000, corr)
        self._point_sd = 1.0 / max(float(sample.reshape(-1, cells).mean(axis=1).std()), 1e-12)

    @property
    def position_m(self) -> np.ndarray:
        """Grid positions on the km axis, m."""
        return self._position

    def run(self, day: float, seed: int | np.random.Generator) -> tuple[float, dict[str, WheelTrack]]:
        """One run on ``day``: its nominal speed (km/h) and each wheel's track."""
        rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
        x = self._position
        n = x.size
        nz = self.noise
        v_run = self.speed_kmh * (1.0 + rng.uniform(-nz.speed_spread, nz.speed_spread))
        wobble = 1.0 + nz.speed_wobble * np.clip(_smooth(rng, n, 2000.0 / self.grid_m), -2.5, 2.5)
        v = v_run / KMH_PER_MPS * wobble
        speed_law = (v / (self.v_ref_kmh / KMH_PER_MPS)) ** self.alpha
        planted = self.plan.factor(x, day)
        corr = nz.correlation_m / self.grid_m
        tracks = {}
        for wheel in FLEET_WHEELS:
            eps = nz.run_sd * rng.standard_normal() + nz.segment_sd * self._point_sd * _smooth(rng, n, corr)
            amp = self._base[int(wheel[1])] * speed_law * planted * np.exp(eps)
            tracks[wheel] = WheelTrack(x, amp, v)
        return v_run, tracks


@dataclass(frozen=True)
class FleetDay:
    """One generated run with its assessment (what :func:`app.condition.fleet.fleet_history` yields)."""

    number: int
    day: float
    speed_kmh: float
    tracks: dict[str, WheelTrack]
    segments: dict[float, dict[str, SegmentStats]]
    assessment: RunAssessment
