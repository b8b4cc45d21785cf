"""The processing settings are typed once (app/analysis/settings.py): the API's request schema and
the process command's options are derived from the dataclass, and the service limits wheel orders
to what it stores."""

from __future__ import annotations

import dataclasses

import pytest
from typer.testing import CliRunner

from app.analysis.settings import MAX_WHEEL_ORDERS, ProcessingSettings
from app.api.schemas.jobs import ProcessingSettingsIn
from app.core.errors import ApiError
from app.db.models import N_ORDER_COLUMNS
from app.runs.jobs import settings_from_request

FIELDS = [f.name for f in dataclasses.fields(ProcessingSettings)]


def test_the_api_schema_has_every_setting_and_nothing_else():
    assert list(ProcessingSettingsIn.model_fields) == FIELDS
    assert all(v is None for v in ProcessingSettingsIn().model_dump().values())
    with pytest.raises(ValueError):
        ProcessingSettingsIn(unknown_setting=1)
    schema = ProcessingSettingsIn.model_json_schema()
    assert f"1..{N_ORDER_COLUMNS}" in schema["properties"]["n_wheel_orders"]["description"]


def test_the_service_stores_fewer_wheel_orders_than_the_pipeline_tracks():
    """The drift of 1..11 (schema) against 1..30 (dataclass), decided: the pipeline tracks up to 30
    (the process command), the service stores 11 order columns and answers 422 beyond."""
    assert N_ORDER_COLUMNS < MAX_WHEEL_ORDERS
    assert ProcessingSettings(n_wheel_orders=MAX_WHEEL_ORDERS).n_wheel_orders == MAX_WHEEL_ORDERS
    assert settings_from_request(None, {"n_wheel_orders": N_ORDER_COLUMNS}).n_wheel_orders == N_ORDER_COLUMNS
    with pytest.raises(ApiError) as err:
        settings_from_request(None, {"n_wheel_orders": N_ORDER_COLUMNS + 1})
    assert (err.value.status_code, err.value.field) == (422, "n_wheel_orders")


def test_the_process_command_has_an_option_per_setting():
    from app.cli import app as cli

    text = CliRunner().invoke(cli, ["process", "--help"], terminal_width=200).output
    for name in FIELDS:
        assert f"--{name.replace('_', '-')}" in text, name
    assert "1..30; default 11" in text


def test_a_bad_option_value_names_the_setting(tmp_path):
    from app.cli import app as cli

    run = tmp_path / "r.h5"
    run.write_bytes(b"not read: the settings are checked first")
    result = CliRunner().invoke(cli, ["process", str(run), "--filter-order", "7"])
    assert result.exit_code == 2
    assert "filter_order" in result.output
