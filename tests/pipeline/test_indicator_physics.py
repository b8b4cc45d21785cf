"""The indicator against the independent physics runs (../shared/physics), through the real pipeline.

Uniform track: the steady bays of every physics run, tiled (bench/physics_runs.py), written as Z11 of a
canonical run and processed with the default settings: the sleeper amplitude and its harmonics equal
the lock-in amplitudes of cases.csv within 1 %. Resolution: a stiffness step and a 6 m soft spot
spliced at a sleeper meet the issue's targets, also with a 90 µm order-5 wheel polygon added.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))

from physics_runs import D_S, PHYSICS, cases, polygon, steady_unit, write_run  # noqa: E402

from app.analysis.settings import ProcessingSettings  # noqa: E402
from app.pipeline import run_pipeline  # noqa: E402

pytestmark = pytest.mark.skipif(not (PHYSICS / "cases.csv").is_file(), reason="no ../shared/physics")


def _profile(tmp_path: Path, name: str, z: np.ndarray, fs: float, v: float):
    res = run_pipeline(write_run(tmp_path / f"{name}.h5", z, fs, v), ProcessingSettings(), tmp_path / f"w-{name}")
    p = res.profiles[res.profiles["wheel"] == "11"].sort_values("bin")
    return (p["bin"].to_numpy() + 0.5) * 0.25, p, res


@pytest.mark.parametrize("name", sorted(cases()) if (PHYSICS / "cases.csv").is_file() else [])
def test_uniform_amplitudes_equal_the_lock_in(tmp_path, name):
    c = cases()[name]
    unit, v, fs, nb = steady_unit(name)
    z = np.tile(unit, -(-100 // int(nb * D_S)))
    x, p, res = _profile(tmp_path, "u", z, fs, v)
    inner = p[(x > 15) & (x < x[-1] - 15)]
    for col, key in (("sleeper_amp", "A_lockin"), ("sleeper_2_amp", "A2"), ("sleeper_3_amp", "A3")):
        err = inner[col].mean() - c[key]
        # 1 % of the harmonic; a harmonic under a tenth of the fundamental: 0.1 % of the fundamental
        # (measured worst: 2·f_s of k320 at 50 m/s, 0.85 beside 53.8 m/s², +3 % = 0.05 % of f_s)
        assert abs(err) <= max(0.01 * c[key], 0.001 * c["A_lockin"]), f"{name} {col}: {err:+.4f} m/s² vs {key}"
    expect_rms = np.sqrt((c["A_lockin"] ** 2 + c["A2"] ** 2 + c["A3"] ** 2) / 2)
    assert inner["sleeper_rms"].mean() == pytest.approx(expect_rms, rel=0.01)
    assert res.meta["warnings"] == []


def _splice(v: int, k_a: int, k_b: int, bays_b: int | None, with_polygon: bool):
    ua, va, fs, na = steady_unit(f"grid_k{k_a}_v{v}.npz")
    ub, _, _, nb = steady_unit(f"grid_k{k_b}_v{v}.npz")
    lead = 100

    def bays(u, n, count):
        return np.tile(u, -(-count // n))[: count * (u.size // n)]

    parts = [bays(ua, na, lead), bays(ub, nb, lead if bays_b is None else bays_b)]
    if bays_b is not None:
        parts.append(bays(ua, na, lead))
    z = np.concatenate(parts)
    if with_polygon:
        z = z + polygon(z.size, fs, va)
    return z, fs, va, lead * D_S


@pytest.mark.parametrize("with_polygon", [False, True])
@pytest.mark.parametrize("k_a, k_b", [(40, 160), (80, 20)])
def test_step_and_soft_spot_resolution(tmp_path, k_a, k_b, with_polygon):
    """At 35 m/s (f_s 58 Hz): 40 → 160 MN/m (1.12 → 3.34 m/s²) and 80 → 20 MN/m (5.69 → 0.56 m/s²)."""
    c = cases()
    a1, a2 = c[f"grid_k{k_a}_v35.npz"]["A_lockin"], c[f"grid_k{k_b}_v35.npz"]["A_lockin"]
    z, fs, v, x0 = _splice(35, k_a, k_b, None, with_polygon)
    x, p, _ = _profile(tmp_path, "step", z, fs, v)
    sel = (x > x0 - 30) & (x < x0 + 30)
    xs, s = x[sel], (p["sleeper_amp"].to_numpy()[sel] - a1) / (a2 - a1)
    i90 = int(np.argmax(s >= 0.9))
    i10 = int(np.flatnonzero(s[:i90] < 0.1)[-1])
    x10 = np.interp(0.1, s[i10 : i10 + 2], xs[i10 : i10 + 2])
    x90 = np.interp(0.9, s[i90 - 1 : i90 + 1], xs[i90 - 1 : i90 + 1])
    i50 = i10 + int(np.argmax(s[i10 : i90 + 1] >= 0.5))
    x50 = np.interp(0.5, s[i50 - 1 : i50 + 1], xs[i50 - 1 : i50 + 1])
    assert x90 - x10 <= 6.0
    assert abs(x50 - x0) <= 2.0
    assert max(s.max() - 1.0, -s.min()) <= 0.10
    far = (x > 20) & (x < x0 - 20)
    assert abs(p["sleeper_amp"].to_numpy()[far].mean() / a1 - 1) <= 0.05  # polygon or not
    z, fs, v, x0 = _splice(35, k_a, k_b, 10, with_polygon)  # a 6 m spot of k_b in k_a
    x, p, _ = _profile(tmp_path, "spot", z, fs, v)
    centre = (x > x0 + 2.5) & (x < x0 + 3.5)
    kept = (p["sleeper_amp"].to_numpy()[centre].mean() - a1) / (a2 - a1)
    assert kept >= 0.70
