"""The publish step applies a run to its line's places in its follow-up (after the publish commit, issue 24),
and a failure of the places leaves the run's results, condition rows and flags published, is reported and
retried after its back-off, the line's later runs waiting for it (both databases)."""

from __future__ import annotations

import numpy as np
from sqlalchemy import func, select, update

from app.db.models import ConditionRun, PlaceRun, PlacesPending
from app.simulate.fleet import FleetSimulator
from app.simulate.track import generate_line
from tests.condition.conftest import any_db, db  # noqa: F401  (fixtures)
from tests.condition.support import DAY0, publish_tracks


def test_publish_applies_places_and_survives_their_failure(any_db, monkeypatch):  # noqa: F811
    import datetime as dt

    import app.places.followup as followup
    import app.places.update as places_update
    from app.db.models import Job, utcnow

    sim = FleetSimulator(generate_line(12_000.0, 13_500.0, seed=7), grid_m=0.25)  # 25 cm rows, as a processed run
    _, tracks = sim.run(0.0, np.random.default_rng(1))
    run1, _, summary = publish_tracks(any_db, tracks, DAY0)
    assert summary["stored"] and summary["places"]["applied"], summary["places"]
    assert summary["places"]["method_version"].startswith("trackvkf-pipeline/")

    def broken(*args, **kwargs):
        raise RuntimeError("places broke")

    monkeypatch.setattr(places_update, "prepare_run", broken)
    monkeypatch.setattr(followup, "prepare_run", broken)
    _, tracks = sim.run(1.0, np.random.default_rng(2))
    run2, job2, summary = publish_tracks(any_db, tracks, DAY0 + dt.timedelta(days=1))
    assert summary["stored"]
    places = summary["places"]
    assert places["applied"] is False and places["reason"] == "error: RuntimeError: places broke"
    assert places["pending"] is True and places["attempts"] == 1 and places["retry_at"]
    # the next run of the line waits for it (the places are a history)
    _, tracks = sim.run(2.0, np.random.default_rng(3))
    run3, job3, summary = publish_tracks(any_db, tracks, DAY0 + dt.timedelta(days=2))
    assert summary["places"] == {"pending": True}
    monkeypatch.undo()
    with any_db.read() as s:
        assert s.get(ConditionRun, run2) is not None  # the run's condition rows are published
        assert sorted(s.scalars(select(PlaceRun.run_id))) == [run1]
        marker = s.get(PlacesPending, run2)
        assert marker.attempts == 1 and "places broke" in marker.last_error and not marker.gave_up
    assert followup.run_pending(any_db) == []  # run2 waits for its back-off, run3 for run2
    with any_db.write() as s:  # the back-off has passed
        s.execute(update(PlacesPending).where(PlacesPending.run_id == run2)
                  .values(next_attempt_at=utcnow() - dt.timedelta(seconds=1)))
    done = followup.run_pending(any_db)
    assert [(r.run_id, r.outcome) for r in done] == [(run2, "applied"), (run3, "applied")]
    with any_db.read() as s:
        assert s.scalar(select(func.count()).select_from(PlaceRun)) == 3
        assert s.scalar(select(func.count()).select_from(PlacesPending)) == 0
        for job_id in (job2, job3):
            assert s.get(Job, job_id).meta["condition"]["places"]["applied"] is True


def test_a_failing_places_update_is_given_up_after_its_attempts(any_db, monkeypatch, clock):  # noqa: F811
    import datetime as dt

    import app.places.followup as followup
    from app.db.models import Job

    def broken(*args, **kwargs):
        raise RuntimeError("places broke")

    monkeypatch.setattr(followup, "prepare_run", broken)
    policy = followup.FollowupPolicy(max_attempts=3)  # the default back-off: the clock moves on instead
    sim = FleetSimulator(generate_line(12_000.0, 13_500.0, seed=7), grid_m=0.25)
    _, tracks = sim.run(0.0, np.random.default_rng(0))
    run_id, job_id, _ = publish_tracks(any_db, tracks, DAY0, followup=False)
    outcomes = []
    for _ in range(4):
        outcomes += [r.outcome for r in followup.run_pending(any_db, policy=policy)]
        assert followup.run_pending(any_db, policy=policy) == []  # backing off: not due yet
        clock.advance(policy.retry_max_s + 1.0)
    assert outcomes == ["failed", "failed", "gave_up"]
    with any_db.read() as s:
        marker = s.get(PlacesPending, run_id)
        assert marker.gave_up and marker.attempts == 3 and marker.next_attempt_at is None
        places = s.get(Job, job_id).meta["condition"]["places"]
        assert places["applied"] is False and places["pending"] is False and places["attempts"] == 3
    monkeypatch.undo()
    # given up: the line's later run goes on
    _, tracks = sim.run(1.0, np.random.default_rng(1))
    assert publish_tracks(any_db, tracks, DAY0 + dt.timedelta(days=1))[2]["places"]["applied"]


def test_apply_places_command_applies_the_stored_runs_once(db, monkeypatch):  # noqa: F811
    from typer.testing import CliRunner

    from app.cli import app
    from app.condition.fleet import ingest_fleet
    from app.settings import get_settings

    sim = FleetSimulator(generate_line(0.0, 2_000.0, seed=3))
    ingest_fleet(db, sim, 6, line_id="C1", start=DAY0, seed=4, reference=False)
    monkeypatch.setenv("TRACKVKF_DATABASE_URL", str(db.engine.url))
    get_settings.cache_clear()
    try:
        first = CliRunner().invoke(app, ["apply-places", "--line-id", "C1"])
        again = CliRunner().invoke(app, ["apply-places", "--line-id", "C1"])
    finally:
        get_settings.cache_clear()
    assert first.exit_code == 0 and "6 run(s) applied" in first.output, first.output
    assert again.exit_code == 0 and "0 run(s) applied" in again.output, again.output
    with db.read() as s:
        assert s.scalar(select(func.count()).select_from(PlaceRun)) == 6


def test_places_alerts_can_be_switched_off(db):  # noqa: F811
    from dataclasses import replace

    from app.db.models import WebhookDelivery
    from app.db.webhooks import EVENT_PLACES, create_webhook
    from app.places.config import DEFAULT_PLACES_CONFIG, PlacesConfig
    from app.settings import Settings

    assert not PlacesConfig.from_settings(Settings(places_alerts=False)).alerts
    with db.write() as s:
        create_webhook(s, "https://hooks.example.com/x")
    sim = FleetSimulator(generate_line(12_000.0, 13_500.0, seed=7), grid_m=0.25)
    for i, alerts in enumerate((False, True)):
        import datetime as dt

        _, tracks = sim.run(float(i), np.random.default_rng(i))
        publish_tracks(db, tracks, DAY0 + dt.timedelta(days=i), places=replace(DEFAULT_PLACES_CONFIG, alerts=alerts))
        with db.read() as s:
            n = s.scalar(select(func.count()).select_from(WebhookDelivery).where(WebhookDelivery.event == EVENT_PLACES))
        if not alerts:
            assert n == 0
    assert n >= 1  # the generated line's places at the immediate tier are listed (and alerted) at once
