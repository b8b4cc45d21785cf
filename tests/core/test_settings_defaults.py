"""The service settings' defaults are the numerics' own: a service with no setting decides as the
numerics do by default (each package's settings group takes its defaults from the numerics'
constants; this checks that the composed settings and the parameter objects built from them agree)."""

from __future__ import annotations

from app.analysis.condition.extent_level import DEFAULT_AROUND_M, DEFAULT_MARGIN_M
from app.analysis.settings import ProcessingSettings
from app.analysis.units import MIN_SPEED_KMH
from app.analytics.reference_curves import CurveParams
from app.condition.config import DEFAULT_CONDITION_CONFIG, ConditionConfig
from app.oidc.config import OidcConfig
from app.places.config import PlacesConfig, default_places_config
from app.places.followup import DEFAULT_FOLLOWUP, FollowupPolicy
from app.settings import Settings


def test_the_settings_defaults_are_the_numerics_defaults():
    s = Settings()
    assert s.analytics_min_speed_kmh == MIN_SPEED_KMH == ProcessingSettings().min_speed_kmh
    assert (s.places_effect_around_m, s.places_effect_margin_m) == (DEFAULT_AROUND_M, DEFAULT_MARGIN_M)
    assert ConditionConfig.from_settings(s) == DEFAULT_CONDITION_CONFIG
    assert PlacesConfig.from_settings(s) == default_places_config()
    assert FollowupPolicy.from_settings(s) == DEFAULT_FOLLOWUP
    assert CurveParams.from_settings(s) == CurveParams()


def test_the_oidc_settings_defaults_are_the_configurations():
    s = Settings(oidc_issuer="https://idp.example/realms/rail", oidc_client_id="trackvkf", oidc_client_secret="x")
    assert OidcConfig.from_settings(s) == OidcConfig(issuer="https://idp.example/realms/rail", client_id="trackvkf",
                                                     client_secret="x")


def test_the_settings_load_without_the_numerics():
    """Every CLI command starts with the settings: they name the numerics' constants from light
    modules (lazy package ``__init__``, scipy imported where it is used), so that ``trackvkf migrate``,
    ``user``, ``key`` … do not pay the ~3 s CPU of importing scipy, pandas and numba."""
    import subprocess
    import sys

    code = ("import sys, app.settings; "
            "print(' '.join(m for m in ('scipy', 'pandas', 'numba', 'sqlalchemy') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=60)
    assert out.stdout.split() == [], f"app.settings imports {out.stdout.strip()}"
