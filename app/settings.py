"""The service's settings: the composition of every package's settings group.

Each service package declares its group (:class:`~app.core.config.SettingsGroup`: the fields with
their ``TRACKVKF_`` names, their defaults taken from the numerics' constants, their checks); this
module composes them into the one :class:`Settings` the API, the worker and the CLI read
(:func:`get_settings`). It sits above the services so that the groups can name the numerics'
constants; ``app.core`` holds the base and the core group only. :data:`GROUPS` is also the order of
the configuration reference (``docs/configuration.md``, :mod:`app.core.config_doc`).

A new setting goes into its package's group; a new group into :data:`GROUPS`.
"""

from __future__ import annotations

from functools import lru_cache

from app.accounts.settings import AccountSettings
from app.alerts.settings import WebhookSettings
from app.analytics.settings import AnalyticsSettings
from app.assets.settings import AssetSettings
from app.condition.settings import ConditionSettings
from app.core.config import DEFAULT_SECRET_KEY, CoreSettings, ProductionConfigError, SettingsGroup
from app.maps.settings import MapSettings
from app.oidc.settings import OidcSettings
from app.places.settings import PlacesSettings
from app.profiles.settings import ProfileSettings
from app.reference.settings import ReferenceSettings
from app.runs.settings import UploadSettings, WorkerSettings

__all__ = ["GROUPS", "Settings", "get_settings"]

#: The settings groups, in the order of the configuration reference.
GROUPS: tuple[type[SettingsGroup], ...] = (
    CoreSettings, UploadSettings, WorkerSettings, AccountSettings, OidcSettings, ProfileSettings,
    AnalyticsSettings, ConditionSettings, PlacesSettings, AssetSettings, ReferenceSettings, WebhookSettings,
    MapSettings,
)


class Settings(*reversed(GROUPS)):  # reversed: the fields in the order of GROUPS
    """Settings of the trackvkf service (API, worker, CLI): every group's settings in one object.

    ``Settings().places_gap_m`` is ``TRACKVKF_PLACES_GAP_M``; each setting is described in its
    group (:data:`GROUPS`) and in ``docs/configuration.md``.
    """

    def check_production(self) -> None:
        """Refuse unsafe settings in production mode (no-op in development).

        Raises
        ------
        ProductionConfigError
            Naming the setting: the default or a short ``secret_key``, an ``http://`` OIDC
            issuer, ``auth_disabled``, or a password hash cost below OWASP's minimum.
        """
        if not self.is_production:
            return
        if self.secret_key == DEFAULT_SECRET_KEY or len(self.secret_key) < 32:
            raise ProductionConfigError(
                "TRACKVKF_SECRET_KEY: production mode needs a secret key of at least 32 "
                "characters other than the development default "
                "(e.g. python -c 'import secrets; print(secrets.token_urlsafe(48))')"
            )
        if self.oidc_issuer and not self.oidc_issuer.startswith("https://"):
            raise ProductionConfigError(
                "TRACKVKF_OIDC_ISSUER: production mode needs an https:// issuer")
        if self.auth_disabled:
            raise ProductionConfigError(
                "TRACKVKF_AUTH_DISABLED: authentication cannot be disabled in production mode"
            )
        if not self.password_cost.meets_owasp_minimum():
            raise ProductionConfigError(
                "TRACKVKF_PASSWORD_HASH_TIME_COST, TRACKVKF_PASSWORD_HASH_MEMORY_KIB: production mode needs "
                "at least OWASP's minimum Argon2id cost (e.g. 19456 KiB with 2 passes; docs/security.md), "
                f"got {self.password_hash_memory_kib} KiB with {self.password_hash_time_cost} pass(es)"
            )


@lru_cache(maxsize=1)
def get_settings() -> Settings:
    """Return the process-wide settings read from the environment (cached)."""
    return Settings()
