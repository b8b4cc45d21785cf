"""The stored profile and the spectrogram's extracted components come from one recipe:
a change of the bandwidth rule in :mod:`app.analysis.recipe` alone changes both, exactly
as the same bandwidth asked for through the job's settings does."""

from __future__ import annotations

import io

import numpy as np
import pandas as pd
import pytest

from app.analysis import recipe
from app.analysis.settings import ProcessingSettings
from app.db.session import Database
from worker.runner import LocalWorker

pytestmark = pytest.mark.timeout(300)

WINDOW = {"wheel": "11", "km_from": 12.1, "km_to": 12.2}


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    from app.simulate.run import simulate_run

    path = tmp_path_factory.mktemp("tiny") / "tiny.h5"
    simulate_run(path, length_km=0.3, fs=5_000.0, seed=4, with_forces=False)
    return path


def _process(client, run_id: int, settings: dict | None = None) -> tuple[pd.DataFrame, dict]:
    """Process the run with a new job (the first one: already queued); its profile and spectrogram."""
    if settings is not None:
        assert client.post(f"/api/v1/runs/{run_id}/jobs", json=settings).status_code == 201
    db = Database(client.settings.database_url)
    try:
        assert LocalWorker(client.settings, db=db).run(exit_when_idle=True) == 1
    finally:
        db.dispose()
    assert client.get(f"/api/v1/runs/{run_id}").json()["latest_job"]["status"] == "done"
    r = client.get(f"/api/v1/runs/{run_id}/profile.parquet")
    assert r.status_code == 200, r.text
    profile = pd.read_parquet(io.BytesIO(r.content)).sort_values(["wheel", "bin"], ignore_index=True)
    spec = client.get(f"/api/v1/runs/{run_id}/spectrogram", params=WINDOW)
    assert spec.status_code == 200, spec.text
    return profile, spec.json()


def _db(spec: dict, key: str) -> np.ndarray:
    return np.array(spec[key], dtype=float)


def test_profile_and_spectrogram_follow_the_recipe(client, tiny_run, monkeypatch):
    with open(tiny_run, "rb") as fh:
        run_id = client.post("/api/v1/runs", files={"file": (tiny_run.name, fh)}).json()["id"]
    profile, spec = _process(client, run_id)

    rule = recipe.order_bandwidths

    def wider(labels, wheel_diameter, settings):
        per_speed, floor_speed = rule(labels, wheel_diameter, settings)
        return 1.5 * per_speed, floor_speed

    monkeypatch.setattr(recipe, "order_bandwidths", wider)
    wide_profile, wide_spec = _process(client, run_id, {})
    monkeypatch.undo()
    # 1.5x every bandwidth: wheel orders 0.15 orders, track orders 3 m / 1.5 = 2 m resolution
    asked = {"bandwidth_orders": 0.15, "track_resolution_m": ProcessingSettings().track_resolution_m / 1.5}
    asked_profile, asked_spec = _process(client, run_id, asked)

    # the recipe's change reached the stored profile and the spectrogram's components ...
    assert len(profile) > 1000 and len(wide_profile) == len(profile)
    assert not np.allclose(wide_profile["order_amp_01"], profile["order_amp_01"], rtol=1e-3)
    comp, wide_comp = _db(spec, "components_db"), _db(wide_spec, "components_db")
    assert np.max(np.abs(wide_comp - comp)) > 1.0
    np.testing.assert_array_equal(_db(wide_spec, "raw_db"), _db(spec, "raw_db"))  # the raw signal did not
    # ... as the same bandwidth asked for through the job's settings does
    for column in ("sleeper_amp", "sleeper_rms", "order_amp_01", "order_amp_11", "residual_rms"):
        np.testing.assert_allclose(wide_profile[column], asked_profile[column], rtol=1e-6, err_msg=column)
    np.testing.assert_allclose(wide_comp, _db(asked_spec, "components_db"), atol=0.011)
    assert asked_spec["settings"]["bandwidth_orders"] == 0.15 and wide_spec["settings"]["bandwidth_orders"] == 0.1
