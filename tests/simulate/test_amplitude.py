"""The simulator's speed response: the resonance model (default) and the power law (option)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from app.analysis.stiffness.track_dynamics import (
    TrackParameters,
    resonance_frequency,
    sleeper_passage_amplitude,
)
from app.simulate.amplitude import (
    PowerLawResponse,
    ResonanceResponse,
    speed_response,
    speed_response_from_json,
)
from app.simulate.run import simulate_run
from app.simulate.speed import SpeedProfile
from app.simulate.track import SUPERSTRUCTURE_TYPES
from app.simulate.truth import load_truth

V_REF = 100 / 3.6


def test_power_law_is_the_separable_model() -> None:
    m = PowerLawResponse(alpha=1.5, v_ref_mps=V_REF)
    v = np.array([15.0, V_REF, 50.0])
    np.testing.assert_allclose(m.factor(np.array([0, 1, 2]), v), (v / V_REF) ** 1.5)
    again = speed_response_from_json(m.to_json())
    assert again == m


def test_resonance_is_the_track_model_relative_to_v_ref() -> None:
    m = ResonanceResponse(v_ref_mps=V_REF)
    v = np.geomspace(11.0, 56.0, 60)
    for code, name in enumerate(SUPERSTRUCTURE_TYPES):
        f = m.factor(np.full(v.size, code), v)
        assert m.factor(np.array([code]), np.array([V_REF]))[0] == pytest.approx(1.0)
        exact = sleeper_passage_amplitude(m.params(name), v) / sleeper_passage_amplitude(
            m.params(name), np.array([V_REF]))[0]
        np.testing.assert_allclose(f, exact, rtol=1e-2)  # the table interpolates (< 1 %)
        # not a power law: the local log-log slope changes sign across the resonance
        slope = np.diff(np.log(f)) / np.diff(np.log(v))
        assert slope.max() - slope.min() > 2.0, name
    # stiffer support: the wheel–track resonance at a higher frequency
    f_res = [resonance_frequency(m.params(n)) for n in SUPERSTRUCTURE_TYPES]
    k = [dict(m.support_stiffness_mnm)[n] for n in SUPERSTRUCTURE_TYPES]
    assert np.argsort(f_res).tolist() == np.argsort(k).tolist()
    assert speed_response_from_json(m.to_json()) == m
    # another vehicle on the same line: its own resonance against the reference vehicle's amplitude at v_ref
    heavy = ResonanceResponse(v_ref_mps=V_REF, track=m.track.replace(wheel_mass=740.0), reference_track=m.track)
    ref = sleeper_passage_amplitude(m.params("b91_pads"), np.array([V_REF]))[0]
    assert heavy.factor(np.array([2]), np.array([40.0]))[0] == pytest.approx(
        sleeper_passage_amplitude(heavy.params("b91_pads"), np.array([40.0]))[0] / ref, rel=1e-2)
    assert speed_response_from_json(heavy.to_json()) == heavy
    # a truth written before a type was appended lacks it: the default stiffness of that type
    old = json.loads(m.to_json())
    del old["support_stiffness_mnm"]["timber"]
    assert speed_response_from_json(json.dumps(old)) == m
    with pytest.raises(ValueError, match="lacks types"):
        ResonanceResponse(support_stiffness_mnm=(("slab", 100.0),))
    with pytest.raises(ValueError, match="amplitude_model"):
        speed_response("cubic", v_ref_mps=V_REF)


def test_damping_lowers_the_resonance_peak() -> None:
    v = np.geomspace(30.0, 56.0, 80)
    light = ResonanceResponse(damping_factor=1.0).amplitude("b91_no_pads", v)
    heavy = ResonanceResponse(damping_factor=3.0).amplitude("b91_no_pads", v)
    assert light.max() > 1.5 * heavy.max()
    assert TrackParameters().replace(ballast_stiffness=1e8).ballast_stiffness == 1e8


def test_simulated_run_follows_the_chosen_model(tmp_path: Path) -> None:
    kw = {"duration_s": 4.0, "fs": 2000.0, "seed": 4, "noise_std": 0.0,
          "speed_profile": SpeedProfile.from_segments(12.0, [(4.0, 50.0)])}
    res = simulate_run(tmp_path / "r.h5", **kw)
    plaw = simulate_run(tmp_path / "p.h5", amplitude_model="power_law", **kw)
    assert isinstance(res.speed_response, ResonanceResponse) and np.isnan(res.alpha)
    assert isinstance(plaw.speed_response, PowerLawResponse) and plaw.alpha == 1.5
    b, p = res.bins["11"], plaw.bins["11"]
    np.testing.assert_array_equal(b.amplitude_vref_mps2, p.amplitude_vref_mps2)
    np.testing.assert_allclose(p.amplitude_mps2, p.amplitude_vref_mps2 * (p.speed_mps / V_REF) ** 1.5)
    np.testing.assert_allclose(b.amplitude_mps2,
                               b.amplitude_vref_mps2 * res.speed_response.factor(b.section, b.speed_mps))
    ratio = b.amplitude_mps2 / p.amplitude_mps2
    assert ratio.max() / ratio.min() > 1.5  # the two models differ along the ramp
    again = load_truth(res.truth_path)
    assert again.speed_response == res.speed_response
