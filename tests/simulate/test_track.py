"""Line model: sections, stiffness variation, anomalies."""

from __future__ import annotations

import numpy as np
import pytest

from app.simulate.track import (
    SUPERSTRUCTURE_AMPLITUDE,
    SUPERSTRUCTURE_TYPES,
    StiffnessAnomaly,
    TrackSection,
    generate_line,
)


def test_sections_cover_the_line_with_plausible_lengths() -> None:
    line = generate_line(10_000.0, 22_000.0, seed=1)
    secs = line.sections
    assert secs[0].track_from_m <= 10_000.0 and secs[-1].track_to_m >= 22_000.0
    for a, b in zip(secs[:-1], secs[1:], strict=True):
        assert a.track_to_m == b.track_from_m and a.type != b.type
    lengths = np.array([s.track_to_m - s.track_from_m for s in secs])
    assert np.all(lengths[:-1] >= 300.0) and np.all(lengths <= 1500.0 + 150.0)
    assert len({s.type for s in secs}) == 3
    # bin types follow the table
    for s in secs:
        x = np.linspace(s.track_from_m + 0.2, s.track_to_m - 0.2, 50)
        assert np.all(line.type_at(x) == SUPERSTRUCTURE_TYPES.index(s.type))


def test_stiffness_variation_is_mild_and_anomalies_are_recorded() -> None:
    line = generate_line(0.0, 9000.0, seed=2)
    assert len(line.anomalies) == 3
    soft = line.anomalies[0]
    assert soft.kind == "soft spot" and 0.45 <= soft.factor <= 0.6
    assert 100.0 <= soft.track_to_m - soft.track_from_m <= 200.0
    assert any(
        s.track_from_m + 20 <= soft.track_from_m and soft.track_to_m <= s.track_to_m - 20
        for s in line.sections
    )
    centres = line.centres()
    in_any = np.zeros(centres.size, dtype=bool)
    for an in line.anomalies:
        in_any |= (centres > an.track_from_m) & (centres < an.track_to_m)
    f = line.factor[:, ~in_any]
    assert 0.05 < f.std() < 0.11 and abs(f.mean() - 1.0) < 0.02
    assert np.corrcoef(f[0], f[1])[0, 1] > 0.5  # rails are correlated, not identical
    core = (centres > soft.track_from_m + soft.taper_m) & (centres < soft.track_to_m - soft.taper_m)
    outside = (centres > soft.track_from_m - 60) & (centres < soft.track_from_m - 10)
    ratio = line.factor[:, core].mean() / line.factor[:, outside].mean()
    assert ratio == pytest.approx(soft.factor, rel=0.1)


def test_amplitude_grid_orders_superstructures() -> None:
    assert (
        SUPERSTRUCTURE_AMPLITUDE["slab"]
        > SUPERSTRUCTURE_AMPLITUDE["b91_no_pads"]
        > SUPERSTRUCTURE_AMPLITUDE["b91_pads"]
    )
    secs = [
        TrackSection(0.0, 400.0, "slab"),
        TrackSection(400.0, 800.0, "b91_no_pads"),
        TrackSection(800.0, 1200.0, "b91_pads"),
    ]
    line = generate_line(0.0, 1200.0, seed=0, sections=secs, anomalies=[], variation_std=0.0)
    np.testing.assert_allclose(
        line.amplitude_at_vref(np.array([200.0, 600.0, 1000.0]), side=1), [3.0, 1.8, 0.8]
    )
    np.testing.assert_allclose(line.stiffness_factor(np.array([10.0, 700.0]), side=2), 1.0)


def test_given_anomaly_shape() -> None:
    an = StiffnessAnomaly(100.0, 250.0, 0.5, taper_m=10.0)
    np.testing.assert_allclose(
        an.weight(np.array([90.0, 100.0, 105.0, 110.0, 175.0, 245.0, 260.0])),
        [0, 0, 0.5, 1, 1, 0.5, 0],
    )
    line = generate_line(
        0.0,
        500.0,
        seed=0,
        sections=[TrackSection(0.0, 500.0, "slab")],
        anomalies=[an],
        variation_std=0.0,
    )
    np.testing.assert_allclose(line.stiffness_factor(np.array([50.0, 175.0]), 1), [1.0, 0.5])


def test_same_seed_same_line_and_validation() -> None:
    a, b = generate_line(0.0, 3000.0, seed=9), generate_line(0.0, 3000.0, seed=9)
    np.testing.assert_array_equal(a.factor, b.factor)
    assert a.sections == b.sections
    with pytest.raises(ValueError, match="track_from_m"):
        generate_line(10.0, 5.0)
    with pytest.raises(ValueError, match="unknown superstructure"):
        generate_line(0.0, 10.0, sections=[TrackSection(0.0, 10.0, "wooden")])
