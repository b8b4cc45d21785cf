"""The corporate sign-in's settings group (``TRACKVKF_OIDC_*``, read by :mod:`app.oidc.config`)."""

from __future__ import annotations

from pydantic import Field, field_validator, model_validator

from app.core.config import SettingsGroup
from app.core.security import ROLES
from app.oidc.config import OidcConfig

__all__ = ["OidcSettings"]


class OidcSettings(SettingsGroup):
    """Corporate sign-in: OpenID Connect — the provider, its claims and the roles they give.

    Attributes
    ----------
    oidc_issuer : str, optional
        Issuer URL of an OpenID Connect provider for corporate sign-in (Keycloak:
        ``https://<host>/realms/<realm>``; Microsoft Entra ID:
        ``https://login.microsoftonline.com/<tenant id>/v2.0``). Its discovery document is
        read from ``<issuer>/.well-known/openid-configuration``. Default: none (local users
        and API keys only). See docs/security.md ("Corporate sign-in").
    oidc_provider_name : str
        The provider's name on the login page ("Sign in with <name>").
    oidc_client_id : str, optional
        trackvkf's client id at the provider (needed with ``oidc_issuer``).
    oidc_client_secret : str, optional
        Its client secret (a confidential client); none: a public client (PKCE alone).
    oidc_token_auth_method : str
        How trackvkf authenticates at the token endpoint: ``client_secret_basic``
        (default), ``client_secret_post`` or ``none`` (a public client).
    oidc_scopes : str
        Scopes asked for (space separated; must include ``openid``).
    oidc_username_claim : str
        The ID token claim that names the user in trackvkf (``preferred_username``;
        Entra ID: ``preferred_username`` or ``email``); without it the ``email``, then the
        ``sub`` claim.
    oidc_groups_claim : str
        The claim that carries the user's groups or roles: a list of strings (``groups``;
        Entra ID app roles: ``roles``; a dotted path reaches into objects, Keycloak realm
        roles: ``realm_access.roles``).
    oidc_role_groups : dict of str to str
        Groups → trackvkf role (viewer, engineer, admin), JSON:
        ``{"track-admins": "admin", "track-engineers": "engineer"}``. A user gets the
        highest role of their groups; a user in none of them is refused unless
        ``oidc_default_role`` is set.
    oidc_default_role : str, optional
        Role of a signed-in user in none of the mapped groups. Default: none (refused).
    oidc_redirect_uri : str, optional
        The callback URL registered at the provider (``https://<host>/login/oidc/callback``).
        Default: derived from the request (set it behind a reverse proxy).
    oidc_post_logout_redirect_uri : str, optional
        Where the provider sends the browser after sign-out (register it there too).
        Default: the login page, derived from the request.
    oidc_api_audience : str, optional
        Accept the provider's JWT access tokens as ``Authorization: Bearer`` on the API
        when their ``aud`` holds this value (the provider's API/application id URI of
        trackvkf). Default: none (provider tokens are not accepted by the API; sign in with
        the browser or use an API key).
    oidc_timeout_s : float
        Time limit of one request to the provider (discovery, keys, token), s.
    oidc_metadata_ttl_s : float
        How long each API process keeps the provider's discovery document and keys, s (an
        unknown key id fetches the keys again at once, at most every 10 s).
    oidc_leeway_s : float
        Clock difference tolerated on the tokens' ``exp``, ``iat`` and ``nbf``, s.
    """

    oidc_issuer: str | None = Field(default=None, max_length=500)
    oidc_provider_name: str = Field(default=OidcConfig.provider_name, min_length=1, max_length=80)
    oidc_client_id: str | None = Field(default=None, max_length=255)
    oidc_client_secret: str | None = Field(default=None, max_length=1000)
    oidc_token_auth_method: str = Field(
        default=OidcConfig.token_auth_method, pattern="^(client_secret_basic|client_secret_post|none)$")
    oidc_scopes: str = Field(default=OidcConfig.scopes, max_length=500)
    oidc_username_claim: str = Field(default=OidcConfig.username_claim, min_length=1, max_length=100)
    oidc_groups_claim: str = Field(default=OidcConfig.groups_claim, min_length=1, max_length=200)
    oidc_role_groups: dict[str, str] = Field(default_factory=dict)
    oidc_default_role: str | None = None
    oidc_redirect_uri: str | None = Field(default=None, max_length=500)
    oidc_post_logout_redirect_uri: str | None = Field(default=None, max_length=500)
    oidc_api_audience: str | None = Field(default=None, max_length=500)
    oidc_timeout_s: float = Field(default=OidcConfig.timeout_s, gt=0, le=120)
    oidc_metadata_ttl_s: float = Field(default=OidcConfig.metadata_ttl_s, gt=0)
    oidc_leeway_s: float = Field(default=OidcConfig.leeway_s, ge=0, le=600)

    @field_validator("oidc_role_groups")
    @classmethod
    def _check_role_groups(cls, value: dict[str, str]) -> dict[str, str]:
        for group, role in value.items():
            if role not in ROLES:
                raise ValueError(f"oidc_role_groups[{group!r}] must be viewer, engineer or admin, got {role!r}")
        return value

    @field_validator("oidc_default_role")
    @classmethod
    def _check_default_role(cls, value: str | None) -> str | None:
        if value is not None and value not in ROLES:
            raise ValueError(f"oidc_default_role must be viewer, engineer or admin, got {value!r}")
        return value

    @field_validator("oidc_scopes")
    @classmethod
    def _check_scopes(cls, value: str) -> str:
        if "openid" not in value.split():
            raise ValueError(f"oidc_scopes must include openid, got {value!r}")
        return " ".join(value.split())

    @field_validator("oidc_issuer", "oidc_redirect_uri", "oidc_post_logout_redirect_uri")
    @classmethod
    def _check_url(cls, value: str | None, info) -> str | None:
        if value is None or not value.strip():
            return None
        value = value.strip()
        if not value.startswith(("https://", "http://")):
            raise ValueError(f"{info.field_name} must be an http(s) URL, got {value!r}")
        return value  # the issuer exactly as the provider writes it into its tokens' "iss"

    @model_validator(mode="after")
    def _check_oidc(self) -> OidcSettings:
        if self.oidc_api_audience and not self.oidc_issuer:
            raise ValueError("oidc_api_audience: needs oidc_issuer (whose tokens to accept)")
        if self.oidc_issuer and not self.oidc_client_id:
            raise ValueError("oidc_client_id: needed with oidc_issuer")
        if self.oidc_issuer and self.oidc_token_auth_method != "none" and not self.oidc_client_secret:
            raise ValueError(
                f"oidc_client_secret: needed with oidc_token_auth_method={self.oidc_token_auth_method} "
                "(or set oidc_token_auth_method=none for a public client)")
        return self

    @property
    def oidc_enabled(self) -> bool:
        """Whether corporate sign-in (OpenID Connect) is configured."""
        return bool(self.oidc_issuer)
