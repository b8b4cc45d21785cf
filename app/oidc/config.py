"""The OpenID Connect settings as one object: the provider, the client, the claims, groups → role."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from app.core.security import ROLES, role_rank

__all__ = ["OidcConfig", "USERNAME_MAX"]

#: longest user name trackvkf keeps (``users.username``)
USERNAME_MAX = 64
_USERNAME_CHARS = frozenset("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789._-@")


def _claim(claims: Mapping[str, Any], path: str) -> Any:
    """The value at a dotted ``path`` of ``claims`` (``realm_access.roles``), or None."""
    value: Any = claims
    for part in path.split("."):
        if not isinstance(value, Mapping) or part not in value:
            return None
        value = value[part]
    return value


@dataclass(frozen=True)
class OidcConfig:
    """What trackvkf needs to know of its OpenID provider (``TRACKVKF_OIDC_*``, docs/configuration.md).

    Attributes
    ----------
    issuer : str
        The provider's issuer identifier, exactly as in its tokens' ``iss``.
    provider_name : str
        Shown on the login page.
    client_id, client_secret : str
        trackvkf's client at the provider (no secret: a public client).
    token_auth_method : str
        ``client_secret_basic``, ``client_secret_post`` or ``none``.
    scopes : str
        Space separated, with ``openid``.
    username_claim, groups_claim : str
        Claim names (the groups claim may be a dotted path).
    role_groups : Mapping of str to str
        Group → role.
    default_role : str or None
        Role of a user in none of the groups (None: refused).
    redirect_uri, post_logout_redirect_uri : str or None
        Fixed URLs (None: derived from the request).
    api_audience : str or None
        ``aud`` of the access tokens the API accepts (None: none accepted).
    timeout_s, metadata_ttl_s, leeway_s : float
        Seconds.
    """

    issuer: str
    client_id: str
    provider_name: str = "corporate account"
    client_secret: str | None = None
    token_auth_method: str = "client_secret_basic"
    scopes: str = "openid profile email"
    username_claim: str = "preferred_username"
    groups_claim: str = "groups"
    role_groups: Mapping[str, str] = field(default_factory=dict)
    default_role: str | None = None
    redirect_uri: str | None = None
    post_logout_redirect_uri: str | None = None
    api_audience: str | None = None
    timeout_s: float = 10.0
    metadata_ttl_s: float = 3600.0
    leeway_s: float = 60.0

    def __post_init__(self) -> None:
        if not self.issuer or not self.client_id:
            raise ValueError("issuer, client_id: both are needed")
        for group, role in self.role_groups.items():
            if role not in ROLES:
                raise ValueError(f"role_groups[{group!r}]: must be one of {', '.join(ROLES)}, got {role!r}")
        if self.default_role is not None and self.default_role not in ROLES:
            raise ValueError(f"default_role: must be one of {', '.join(ROLES)}, got {self.default_role!r}")

    @classmethod
    def from_settings(cls, settings: Any) -> OidcConfig | None:
        """The configuration of ``settings`` (:class:`app.settings.Settings`); None when no
        provider is configured (``TRACKVKF_OIDC_ISSUER`` unset)."""
        if not getattr(settings, "oidc_issuer", None):
            return None
        return cls(
            issuer=settings.oidc_issuer, client_id=settings.oidc_client_id,
            provider_name=settings.oidc_provider_name, client_secret=settings.oidc_client_secret,
            token_auth_method=settings.oidc_token_auth_method, scopes=settings.oidc_scopes,
            username_claim=settings.oidc_username_claim, groups_claim=settings.oidc_groups_claim,
            role_groups=dict(settings.oidc_role_groups), default_role=settings.oidc_default_role,
            redirect_uri=settings.oidc_redirect_uri,
            post_logout_redirect_uri=settings.oidc_post_logout_redirect_uri,
            api_audience=settings.oidc_api_audience, timeout_s=settings.oidc_timeout_s,
            metadata_ttl_s=settings.oidc_metadata_ttl_s, leeway_s=settings.oidc_leeway_s,
        )

    def groups_of(self, claims: Mapping[str, Any]) -> list[str]:
        """The groups a token's ``claims`` carry in :attr:`groups_claim` (a list of strings, or one
        string); [] without the claim."""
        value = _claim(claims, self.groups_claim)
        if isinstance(value, str):
            return [value]
        if isinstance(value, list):
            return [g for g in value if isinstance(g, str)]
        return []

    def role_of(self, groups: list[str]) -> str | None:
        """The highest role any of ``groups`` maps to, else :attr:`default_role` (None: no access)."""
        roles = [self.role_groups[g] for g in groups if g in self.role_groups]
        if not roles:
            return self.default_role
        return max(roles, key=role_rank)

    def username_of(self, claims: Mapping[str, Any]) -> str | None:
        """The user name of a token: the first of :attr:`username_claim`, ``email`` and ``sub``
        that is a valid trackvkf user name (1–64 letters, digits and ``. _ - @``); None if none is."""
        for name in (self.username_claim, "email", "sub"):
            value = _claim(claims, name)
            if isinstance(value, str) and 1 <= len(value) <= USERNAME_MAX and set(value) <= _USERNAME_CHARS:
                return value
        return None

    @staticmethod
    def subject_of(claims: Mapping[str, Any]) -> str:
        """The provider's stable id of the user: ``"<iss> <sub>"``."""
        return f"{claims['iss']} {claims['sub']}"
