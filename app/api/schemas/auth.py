"""Schemas of authentication, users, API keys and the audit log."""

from __future__ import annotations

import datetime as dt
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from app.api.schemas.text import Text

__all__ = [
    "LoginIn",
    "LogoutOut",
    "MeOut",
    "MePatch",
    "UserIn",
    "UserPatch",
    "UserOut",
    "UserList",
    "KeyIn",
    "KeyOut",
    "KeyCreated",
    "KeyList",
    "AuditOut",
    "AuditList",
    "PasswordChangeIn",
]

RoleName = Literal["viewer", "engineer", "admin"]
#: the languages of the service (app.core.i18n.LANGUAGES)
LanguageCode = Literal["en", "de", "fr", "it"]
Username = str


class LoginIn(BaseModel):
    """Credentials of a browser login."""

    model_config = ConfigDict(extra="forbid")

    username: Text = Field(min_length=1, max_length=64)
    password: str = Field(min_length=1, max_length=1024)


class MeOut(BaseModel):
    """The authenticated principal."""

    name: str
    role: RoleName
    kind: Literal["anonymous", "user", "api_key", "oidc_token"] = Field(
        description="anonymous (authentication off), user (browser session), api_key, "
                    "oidc_token (an access token of the OpenID provider)")
    language: LanguageCode | None = Field(
        None, description="The language the user chose (pages, messages, error texts); null: the browser's")
    answered_in: LanguageCode = Field(
        "en", description="The language of this request's answers: the user's, else the browser's Accept-Language")


class MePatch(BaseModel):
    """What users change of their own account."""

    model_config = ConfigDict(extra="forbid")

    language: LanguageCode | None = Field(
        description="en, de, fr or it; null: follow the browser's Accept-Language")


class LogoutOut(BaseModel):
    """A session begun at the OpenID provider has ended here; the browser signs out there too."""

    end_session_url: str = Field(description="The provider's sign-out (RP-initiated logout) for this session")


class PasswordChangeIn(BaseModel):
    """A user's own password change."""

    model_config = ConfigDict(extra="forbid")

    current_password: str = Field(min_length=1, max_length=1024)
    new_password: Text = Field(min_length=10, max_length=1024)


class UserIn(BaseModel):
    """A new user."""

    model_config = ConfigDict(extra="forbid")

    username: Text = Field(
        min_length=1, max_length=64, pattern=r"^[A-Za-z0-9._@-]+$", description="Login name"
    )
    password: Text = Field(min_length=10, max_length=1024)
    role: RoleName


class UserPatch(BaseModel):
    """Changes to a user; omitted fields stay."""

    model_config = ConfigDict(extra="forbid")

    password: Text | None = Field(None, min_length=10, max_length=1024)
    role: RoleName | None = None
    active: bool | None = None


class UserOut(BaseModel):
    """A user (never its password hash)."""

    model_config = ConfigDict(from_attributes=True)  # validated from the database row

    username: str
    role: RoleName
    active: bool
    demo_credentials: bool = Field(description="Password printed by `trackvkf demo`, never changed")
    created_by: str | None = None
    created_at: dt.datetime
    updated_at: dt.datetime | None = None
    last_login_at: dt.datetime | None = None
    auth_source: Literal["local", "oidc"] = Field(
        default="local", description="local: a password here; oidc: signs in at the OpenID provider")


class UserList(BaseModel):
    """All users."""

    items: list[UserOut]


class KeyIn(BaseModel):
    """A new API key."""

    model_config = ConfigDict(extra="forbid")

    name: Text = Field(min_length=1, max_length=64, description="What the key is for")
    role: RoleName
    expires_in_days: int | None = Field(None, ge=1, le=3650, description="Lifetime, days")


class KeyOut(BaseModel):
    """An API key as listed (never the key itself)."""

    model_config = ConfigDict(from_attributes=True)  # validated from the database row

    id: int
    name: str
    prefix: str = Field(description="First characters after `tvk_`: recognise the key")
    role: RoleName
    created_by: str | None = None
    created_at: dt.datetime
    expires_at: dt.datetime | None = None
    last_used_at: dt.datetime | None = Field(None, description="Last use, to the minute")
    revoked_at: dt.datetime | None = None


class KeyCreated(KeyOut):
    """A new key: ``key`` is shown this once and stored only as a hash."""

    key: str


class KeyList(BaseModel):
    """All API keys, newest first."""

    items: list[KeyOut]


class AuditOut(BaseModel):
    """One audit log entry."""

    model_config = ConfigDict(from_attributes=True)  # validated from the database row

    id: int
    at: dt.datetime
    actor: str
    actor_kind: str
    action: str
    target: str | None = None
    outcome: str
    client_ip: str | None = None
    detail: dict[str, Any] | None = None


class AuditList(BaseModel):
    """A page of the audit log, newest first."""

    items: list[AuditOut]
    total: int
    limit: int
    offset: int
