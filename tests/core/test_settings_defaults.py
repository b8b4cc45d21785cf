"""The service settings' defaults are the numerics' own: a service with no setting decides as the
numerics do by default (Settings sits below the numerics and cannot name their constants, so this
checks that the two agree)."""

from __future__ import annotations

from app.analysis.condition.extent_level import DEFAULT_AROUND_M, DEFAULT_MARGIN_M
from app.analysis.settings import ProcessingSettings
from app.analysis.units import MIN_SPEED_KMH
from app.condition.config import DEFAULT_CONDITION_CONFIG, ConditionConfig
from app.core.config import Settings
from app.places.config import PlacesConfig, default_places_config


def test_the_settings_defaults_are_the_numerics_defaults():
    s = Settings()
    assert s.analytics_min_speed_kmh == MIN_SPEED_KMH == ProcessingSettings().min_speed_kmh
    assert (s.places_effect_around_m, s.places_effect_margin_m) == (DEFAULT_AROUND_M, DEFAULT_MARGIN_M)
    assert ConditionConfig.from_settings(s) == DEFAULT_CONDITION_CONFIG
    assert PlacesConfig.from_settings(s) == default_places_config()
