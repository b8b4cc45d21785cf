"""The sign-in settings group (``TRACKVKF_AUTH_DISABLED``, ``TRACKVKF_ANONYMOUS_*``, ``TRACKVKF_SESSION_TTL_S``,
``TRACKVKF_LOGIN_*``, ``TRACKVKF_PASSWORD_HASH_*``): who a request runs as, sessions, the login limits and
the cost of password hashes (:mod:`app.accounts`)."""

from __future__ import annotations

from pydantic import Field, field_validator, model_validator

from app.core.config import SettingsGroup
from app.core.security import DEFAULT_PASSWORD_COST, ROLES, PasswordCost

__all__ = ["AccountSettings"]


class AccountSettings(SettingsGroup):
    """Sign-in: the anonymous principal, browser sessions, the login limits and password hashing.

    Attributes
    ----------
    anonymous_principal : str
        Name of the principal every request runs as until authentication is on.
    anonymous_role : str
        Role of that principal (viewer, engineer or admin).
    auth_disabled : bool
        Every request runs as the anonymous principal (``anonymous_principal``,
        ``anonymous_role``) without authentication. Development and tests
        only; refused in production.
    session_ttl_s : float
        Lifetime of a browser session after login, s (default 12 h).
    cookie_secure : bool
        Send the session cookies with the ``Secure`` flag (HTTPS only);
        always on in production.
    login_rate_limit, login_rate_window_s : int, float
        At most ``login_rate_limit`` login attempts per (client address, user
        name) within ``login_rate_window_s`` seconds (per API process); a
        browser holding the user's device cookie counts per device instead.
    login_address_rate_limit : int
        At most this many login attempts per client address over all user
        names within ``login_rate_window_s`` (per API process; not for
        browsers holding the user's device cookie).
    login_name_failure_limit, login_name_failure_window_s : int, float
        Failed logins of one user name from all addresses within the window
        (counted in the audit log: shared by all API processes) after which
        the name's logins are refused, except from browsers that logged in as
        that user before (device cookie). Brute force gets at most this many
        guesses per window; the user keeps logging in from their browser.
    password_hash_time_cost, password_hash_memory_kib, password_hash_parallelism : int, int, int
        Argon2id cost of a new password hash: passes over the memory, memory in KiB (at least 8
        per lane) and lanes. Default 3 passes over 64 MiB with 4 lanes (argon2-cffi's defaults,
        RFC 9106): 0.4-0.8 s per hash measured on a busy shared 2-core machine. A stored hash keeps the cost it was
        made with (a changed cost applies to passwords set afterwards). Production mode refuses a
        cost below OWASP's minimum: at least 46 MiB with 1 pass, 19 MiB with 2, 12 MiB with 3,
        9 MiB with 4 or 7 MiB with 5 (docs/security.md). Lower costs are for tests only.
    """

    anonymous_principal: str = "local"
    anonymous_role: str = "admin"
    auth_disabled: bool = False
    session_ttl_s: float = Field(default=12 * 3600.0, gt=0)
    cookie_secure: bool = False
    login_rate_limit: int = Field(default=10, ge=1)
    login_rate_window_s: float = Field(default=60.0, gt=0)
    login_address_rate_limit: int = Field(default=30, ge=1)
    login_name_failure_limit: int = Field(default=50, ge=1)
    login_name_failure_window_s: float = Field(default=3600.0, gt=0)
    password_hash_time_cost: int = Field(default=DEFAULT_PASSWORD_COST.time_cost, ge=1)
    password_hash_memory_kib: int = Field(default=DEFAULT_PASSWORD_COST.memory_kib, ge=8)
    password_hash_parallelism: int = Field(default=DEFAULT_PASSWORD_COST.parallelism, ge=1, le=64)

    @field_validator("anonymous_role")
    @classmethod
    def _check_role(cls, value: str) -> str:
        if value not in ROLES:
            raise ValueError(f"anonymous_role must be viewer, engineer or admin, got {value!r}")
        return value

    @model_validator(mode="after")
    def _check_password_cost(self) -> AccountSettings:
        try:
            PasswordCost(self.password_hash_time_cost, self.password_hash_memory_kib, self.password_hash_parallelism)
        except ValueError as exc:
            raise ValueError(f"password_hash_memory_kib, password_hash_parallelism: {exc}") from None
        return self

    @property
    def password_cost(self) -> PasswordCost:
        """The Argon2id cost of new password hashes (``TRACKVKF_PASSWORD_HASH_*``)."""
        return PasswordCost(self.password_hash_time_cost, self.password_hash_memory_kib,
                            self.password_hash_parallelism)
