"""The service's settings are the composition of the packages' groups (app/settings.py): every
``TRACKVKF_`` variable that worked before the groups (``settings_env_names.txt``, the names of the
one settings class of app/core/config.py, dumped before it was split) still works, each in one group."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from pydantic import ValidationError
from pydantic_settings import EnvSettingsSource

from app.core.config import CoreSettings
from app.places.settings import PlacesSettings
from app.settings import GROUPS, Settings, get_settings

BEFORE = (Path(__file__).parent / "settings_env_names.txt").read_text(encoding="utf-8").split()


def test_every_variable_of_before_is_a_setting_of_one_group():
    names = [n for g in GROUPS for n in g.env_names()]
    assert len(names) == len(set(names))  # no setting in two groups
    assert sorted(names) == sorted(BEFORE)
    assert sorted(f"TRACKVKF_{n.upper()}" for n in Settings.model_fields) == sorted(BEFORE)


def _env_value(value) -> str:
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, (dict, list, tuple)):
        return json.dumps(value)
    return str(value)


def test_every_variable_of_before_is_read_from_the_environment(monkeypatch):
    """Each name set in the environment reaches its setting (read by pydantic-settings' own source)."""
    defaults = Settings().model_dump()
    for name in BEFORE:
        field = name.removeprefix("TRACKVKF_").lower()
        value = defaults[field]
        monkeypatch.setenv(name, _env_value(value if value is not None else "x"))
    read = EnvSettingsSource(Settings)()
    assert sorted(f"TRACKVKF_{k.upper()}" for k in read) == sorted(BEFORE)


#: one variable of each group and a value other than its default
_ONE_EACH = {
    "CoreSettings": ("TRACKVKF_DATABASE_URL", "sqlite:///elsewhere.db", "sqlite:///elsewhere.db"),
    "UploadSettings": ("TRACKVKF_UPLOAD_BLOCK_BYTES", "65536", 65536),
    "WorkerSettings": ("TRACKVKF_WORKER_CHUNK_PROCESSES", "3", 3),
    "AccountSettings": ("TRACKVKF_ANONYMOUS_ROLE", "viewer", "viewer"),
    "OidcSettings": ("TRACKVKF_OIDC_ROLE_GROUPS", '{"track-admins": "admin"}', {"track-admins": "admin"}),
    "ProfileSettings": ("TRACKVKF_PROFILE_RETENTION_DAYS", "90", 90),
    "AnalyticsSettings": ("TRACKVKF_ANALYTICS_MIN_SPEED_KMH", "30", 30.0),
    "ConditionSettings": ("TRACKVKF_CONDITION_MIN_HISTORY", "6", 6),
    "PlacesSettings": ("TRACKVKF_PLACES_LEVEL_LIMITS", '{"": [0.2, 0.3, 0.5]}', {"": [0.2, 0.3, 0.5]}),
    "AssetSettings": ("TRACKVKF_ASSETS_IMPORT_MAX_LINES", "10", 10),
    "ReferenceSettings": ("TRACKVKF_MAX_REFERENCE_BYTES", "1000", 1000),
    "WebhookSettings": ("TRACKVKF_WEBHOOK_MAX_ATTEMPTS", "3", 3),
    "MapSettings": ("TRACKVKF_MAP_TILE_ATTRIBUTION", "© tiles", "© tiles"),
}


@pytest.mark.parametrize("group", GROUPS, ids=lambda g: g.__name__)
def test_a_variable_reaches_its_group_and_the_composition(monkeypatch, group):
    """Each group reads its variables alone, and the composed settings read the same value."""
    name, text, value = _ONE_EACH[group.__name__]
    field = name.removeprefix("TRACKVKF_").lower()
    assert name in group.env_names() and getattr(group(), field) != value
    monkeypatch.setenv(name, text)
    assert getattr(group(), field) == value
    assert getattr(Settings(), field) == value


def test_get_settings_reads_the_environment_once(monkeypatch):
    get_settings.cache_clear()
    try:
        monkeypatch.setenv("TRACKVKF_PLACES_GAP_M", "12.5")
        assert get_settings().places_gap_m == 12.5
        monkeypatch.setenv("TRACKVKF_PLACES_GAP_M", "20")
        assert get_settings().places_gap_m == 12.5
    finally:
        get_settings.cache_clear()


def test_the_groups_checks_hold_in_the_composition():
    with pytest.raises(ValidationError, match="places_change_limits"):
        Settings(places_change_limits=[0.3, 0.2, 0.5])
    with pytest.raises(ValidationError, match="places_change_limits"):
        PlacesSettings(places_change_limits=[0.3, 0.2, 0.5])
    with pytest.raises(ValidationError, match="worker_stale_after_s"):
        Settings(worker_heartbeat_s=20.0, worker_stale_after_s=30.0)
    with pytest.raises(ValidationError, match="oidc_client_id"):
        Settings(oidc_issuer="https://idp.example")
    with pytest.raises(ValidationError, match="env must be"):
        CoreSettings(env="staging")
    assert Settings(env="PRODUCTION").is_production


def test_a_dot_env_file_serves_every_group(monkeypatch, tmp_path):
    """A ``.env`` file in the working directory holds settings of several groups: each group reads its
    own and ignores the others'; the composition reads them all."""
    for name in ("TRACKVKF_PLACES_GAP_M", "TRACKVKF_DATABASE_URL"):
        monkeypatch.delenv(name, raising=False)
    (tmp_path / ".env").write_text("TRACKVKF_PLACES_GAP_M=12.5\nTRACKVKF_DATABASE_URL=sqlite:///from-env-file.db\n",
                                   encoding="utf-8")
    monkeypatch.chdir(tmp_path)
    assert PlacesSettings().places_gap_m == 12.5
    assert CoreSettings().database_url == "sqlite:///from-env-file.db"
    s = Settings()
    assert (s.places_gap_m, s.database_url) == (12.5, "sqlite:///from-env-file.db")
