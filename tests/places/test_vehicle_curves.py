"""Each vehicle's own reference curves where a line's runs are of more than one vehicle (issue 33): a vehicle's
unsprung mass, wheels and sensors change the amplitude the same track gives (the real line's second vehicle reads
15 % high), so its typical track is its own; a speed its own runs do not cover takes the fleet's curve."""

from __future__ import annotations

import numpy as np
import pytest

from app.analysis.condition.run_places import segment_index
from app.analysis.condition.segment_curves import fit_segment_curves
from app.places.config import DEFAULT_PLACES_CONFIG
from app.places.index import _vehicle_curves

N_SEG = 120  # 1.2 km of one class, both rails: 240 locations


def _rows(rng: np.random.Generator) -> tuple[np.ndarray, dict[int, str | None]]:
    """Store rows (run, wheel code, segment, ln A, speed, sd) of 8 runs: V1 at 26 and 40 m/s, V2 at 40 m/s
    reading +0.14 (15 % high) everywhere."""
    rows, vehicles = [], {}
    seg = np.arange(1000, 1000 + N_SEG)
    track = rng.normal(0.0, 0.05, N_SEG)
    for run in range(1, 9):
        vehicle = "V2" if run % 4 == 0 else "V1"
        v = 40.0 if (run % 2 == 0) else 26.0
        vehicles[run] = vehicle
        for wheel in range(4):
            la = 1.0 + 1.2 * np.log(v / 30.0) + track + rng.normal(0, 0.02, N_SEG) + (0.14 if vehicle == "V2" else 0.0)
            rows.append(np.column_stack([np.full(N_SEG, run), np.full(N_SEG, wheel), seg, la, np.full(N_SEG, v),
                                         np.full(N_SEG, 0.05)]))
    return np.vstack(rows), vehicles


def test_a_second_vehicle_reads_its_own_typical_track_and_the_fleets_where_it_has_no_curve():
    values, vehicles = _rows(np.random.default_rng(4))
    wheel_of = np.array(["11", "12", "41", "42"], dtype=object)
    row_cls = np.full(values.shape[0], "b91", dtype=object)
    fit = np.ones(values.shape[0], dtype=bool)
    own = _vehicle_curves(values, fit, wheel_of, row_cls, vehicles, DEFAULT_PLACES_CONFIG)
    assert sorted(own) == ["V1", "V2"]
    fleet = fit_segment_curves(values[:, 2].astype(np.int64), values[:, 3], values[:, 4], values[:, 0],
                               wheel_of[values[:, 1].astype(np.int64)], row_cls)
    v2 = values[(values[:, 0] == 4) & (values[:, 1] == 0)]
    cls = np.full(N_SEG, "b91", dtype=object)
    by_fleet = segment_index(v2[:, 3], v2[:, 4], cls, fleet)
    by_own = segment_index(v2[:, 3], v2[:, 4], cls, own["V2"])
    # against the fleet's 40 m/s curve (mostly V1's passes) the second vehicle reads high everywhere; against its own
    # it reads the track
    assert np.nanmedian(by_fleet) > 0.05
    assert np.nanmedian(by_own) == pytest.approx(0.0, abs=0.02)
    # V2 never ran at 26 m/s: no curve of its own there (the fleet's stands in, app.places.index.run_index)
    assert np.isnan(segment_index(np.array([1.0]), np.array([26.0]), np.array(["b91"], dtype=object), own["V2"])).all()
    # one vehicle (or none stated): no curves of its own, the fleet's are the vehicle's
    assert _vehicle_curves(values, fit, wheel_of, row_cls, {r: "V1" for r in vehicles}, DEFAULT_PLACES_CONFIG) == {}
    assert _vehicle_curves(values, fit, wheel_of, row_cls, {r: None for r in vehicles}, DEFAULT_PLACES_CONFIG) == {}
