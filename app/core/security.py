"""Security primitives: password hashing, session tokens, API keys, CSRF tokens.

Nothing here touches the database or the web framework; :mod:`app.db.auth_crud`
stores what these functions produce and :mod:`app.api.deps` checks requests
with them.

* Passwords are hashed with Argon2id (``argon2-cffi``); only the hash is stored. The cost of a
  new hash is a :class:`PasswordCost` (the operator's ``TRACKVKF_PASSWORD_HASH_*`` settings;
  default :data:`DEFAULT_PASSWORD_COST`, the library's defaults); a hash carries its own
  parameters, so a password is verified at the cost it was hashed with.
* Session tokens and API keys are 256-bit random strings (:mod:`secrets`).
  They are stored as their SHA-256 digest: a leaked database does not reveal
  a usable token, and the high entropy of the token makes a salt or a slow
  hash unnecessary.
* API keys look like ``tvk_<prefix>_<secret>``; the 8-character prefix is
  stored in clear so that a key can be recognised in listings and logs.
* CSRF tokens are bound to the session: ``HMAC-SHA256(secret_key, session
  token)``. The browser gets it in a readable cookie and sends it back in the
  ``X-CSRF-Token`` header (double submit); the server recomputes it, so a
  cookie planted by another site cannot be paired with a forged header.
* Device cookies mark a browser that logged in as a user before:
  ``<random id>.<HMAC-SHA256(secret_key, id and user name)>``. A brute-force
  attack on a user name (from anywhere) cannot lock its owner out of the
  browsers that carry one.
"""

from __future__ import annotations

import functools
import hashlib
import hmac
import os
import secrets
from dataclasses import dataclass
from typing import Literal

from argon2 import PasswordHasher
from argon2.exceptions import InvalidHashError, VerificationError, VerifyMismatchError

from app.core.i18n import _

__all__ = [
    "Principal",
    "Actor",
    "ROLES",
    "Role",
    "PasswordCost",
    "DEFAULT_PASSWORD_COST",
    "OWASP_ARGON2ID_MINIMUMS",
    "role_rank",
    "role_allows",
    "hash_password",
    "verify_password",
    "password_needs_rehash",
    "check_password_strength",
    "new_session_token",
    "token_digest",
    "NewApiKey",
    "new_api_key",
    "api_key_prefix",
    "csrf_token",
    "csrf_matches",
    "new_device_cookie",
    "device_cookie_id",
    "MIN_PASSWORD_LENGTH",
    "API_KEY_PREFIX",
]

Role = Literal["viewer", "engineer", "admin"]
#: Roles from least to most privileged; each role may do what the ones before it may.
ROLES: tuple[str, ...] = ("viewer", "engineer", "admin")
MIN_PASSWORD_LENGTH = 10
API_KEY_PREFIX = "tvk"


@dataclass(frozen=True)
class PasswordCost:
    """The Argon2id parameters of new password hashes.

    Attributes
    ----------
    time_cost : int
        Passes over the memory (>= 1).
    memory_kib : int
        Memory of one hash, KiB (>= 8 per lane).
    parallelism : int
        Lanes (threads) of one hash (>= 1).

    Raises
    ------
    ValueError
        For parameters Argon2 does not accept.
    """

    time_cost: int = 3
    memory_kib: int = 65536
    parallelism: int = 4

    def __post_init__(self) -> None:
        if self.time_cost < 1 or self.parallelism < 1:
            raise ValueError(f"Argon2 needs time_cost >= 1 and parallelism >= 1, got {self}")
        if self.memory_kib < 8 * self.parallelism:
            raise ValueError(f"Argon2 needs at least 8 KiB of memory per lane, got {self}")

    def meets_owasp_minimum(self) -> bool:
        """Whether the cost is at least one of OWASP's minimum Argon2id configurations
        (:data:`OWASP_ARGON2ID_MINIMUMS`: as much memory and as many passes or more)."""
        return any(self.memory_kib >= m and self.time_cost >= t for m, t in OWASP_ARGON2ID_MINIMUMS)


#: argon2-cffi's defaults (RFC 9106's second recommended option): 3 passes over 64 MiB, 4 lanes;
#: 0.4-0.8 s per hash measured on a busy shared 2-core machine
DEFAULT_PASSWORD_COST = PasswordCost()
#: OWASP Password Storage Cheat Sheet: the minimum Argon2id configurations, (memory KiB, passes),
#: each with 1 lane; they trade memory for passes at about the same defence
OWASP_ARGON2ID_MINIMUMS: tuple[tuple[int, int], ...] = ((47104, 1), (19456, 2), (12288, 3), (9216, 4), (7168, 5))

#: verifies a hash of any parameters (read from the hash)
_verifier = PasswordHasher()


@functools.lru_cache(maxsize=8)
def _hasher(cost: PasswordCost) -> PasswordHasher:
    return PasswordHasher(time_cost=cost.time_cost, memory_cost=cost.memory_kib, parallelism=cost.parallelism)


def role_rank(role: str) -> int:
    """Position of ``role`` in :data:`ROLES` (0 = viewer).

    Raises
    ------
    ValueError
        If ``role`` is not a known role.
    """
    try:
        return ROLES.index(role)
    except ValueError:
        raise ValueError(f"role must be one of {', '.join(ROLES)}, got {role!r}") from None


def role_allows(role: str, required: str) -> bool:
    """Whether a principal with ``role`` may do what needs ``required``."""
    return role_rank(role) >= role_rank(required)


def check_password_strength(password: str) -> None:
    """Reject passwords that are too short or too long.

    Raises
    ------
    ValueError
        Naming ``password``.
    """
    if not isinstance(password, str):
        raise ValueError(_("password must be a string"))
    if len(password) < MIN_PASSWORD_LENGTH:
        raise ValueError(_("password must have at least {n} characters", n=MIN_PASSWORD_LENGTH))
    if len(password) > 1024:
        raise ValueError(_("password must have at most 1024 characters"))


def hash_password(password: str, cost: PasswordCost = DEFAULT_PASSWORD_COST) -> str:
    """Argon2id hash of ``password`` at ``cost`` (encoded string with salt and parameters)."""
    check_password_strength(password)
    return _hasher(cost).hash(password)


def verify_password(password_hash: str, password: str) -> bool:
    """Whether ``password`` matches ``password_hash`` (constant-time in the library), at the cost
    the hash was made with."""
    if not password_hash or not isinstance(password, str) or len(password) > 1024:
        return False
    try:
        return _verifier.verify(password_hash, password)
    except (VerifyMismatchError, VerificationError, InvalidHashError):
        return False


def password_needs_rehash(password_hash: str, cost: PasswordCost = DEFAULT_PASSWORD_COST) -> bool:
    """Whether the hash was made with other parameters than ``cost``."""
    try:
        return _hasher(cost).check_needs_rehash(password_hash)
    except InvalidHashError:
        return True


def new_session_token() -> str:
    """A fresh random session token (256 bits, URL-safe text)."""
    return secrets.token_urlsafe(32)


def token_digest(token: str) -> str:
    """SHA-256 hex digest of a session token or API key: what the database stores."""
    return hashlib.sha256(token.encode("utf-8")).hexdigest()


@dataclass(frozen=True)
class NewApiKey:
    """A freshly generated API key.

    Attributes
    ----------
    key : str
        The full key, ``tvk_<prefix>_<secret>``: shown to its owner once.
    prefix : str
        8 characters stored in clear to recognise the key.
    digest : str
        SHA-256 hex digest of ``key``, stored.
    """

    key: str
    prefix: str
    digest: str


def new_api_key() -> NewApiKey:
    """Generate an API key."""
    prefix = secrets.token_hex(4)
    key = f"{API_KEY_PREFIX}_{prefix}_{secrets.token_urlsafe(32)}"
    return NewApiKey(key=key, prefix=prefix, digest=token_digest(key))


def api_key_prefix(key: str) -> str | None:
    """The prefix of a well-formed API key, else None."""
    parts = key.split("_", 2)
    if len(parts) != 3 or parts[0] != API_KEY_PREFIX or len(parts[1]) != 8:
        return None
    return parts[1]


def csrf_token(secret_key: str, session_token: str) -> str:
    """CSRF token bound to a session: ``HMAC-SHA256(secret_key, session_token)``, hex."""
    return hmac.new(
        secret_key.encode("utf-8"), b"csrf:" + session_token.encode("utf-8"), hashlib.sha256
    ).hexdigest()


def csrf_matches(secret_key: str, session_token: str, header: str | None) -> bool:
    """Whether ``header`` is the CSRF token of the session (constant-time compare)."""
    if not header:
        return False
    return hmac.compare_digest(csrf_token(secret_key, session_token), header.strip())


def _device_mac(secret_key: str, device_id: str, username: str) -> str:
    message = f"device:{device_id}:{username}".encode()
    return hmac.new(secret_key.encode("utf-8"), message, hashlib.sha256).hexdigest()


def new_device_cookie(secret_key: str, username: str) -> str:
    """Value of a device cookie: this browser logged in as ``username``.

    ``<random id>.<HMAC-SHA256(secret_key, id, user name)>``: only the server
    can make one, and it names one user.
    """
    device_id = secrets.token_urlsafe(16)
    return f"{device_id}.{_device_mac(secret_key, device_id, username)}"


def device_cookie_id(secret_key: str, cookie: str | None, username: str) -> str | None:
    """The device id of a valid device cookie of ``username``, else None (constant-time compare)."""
    if not cookie or len(cookie) > 200:
        return None
    device_id, _sep, mac = cookie.partition(".")
    if not device_id or not mac:
        return None
    if not hmac.compare_digest(_device_mac(secret_key, device_id, username), mac):
        return None
    return device_id


@dataclass(frozen=True)
class Principal:
    """Who makes a request.

    Attributes
    ----------
    name : str
        User name or API key name.
    role : str
        ``viewer``, ``engineer`` or ``admin``.
    kind : str
        ``anonymous`` (``auth_disabled``), ``user`` (session cookie), ``api_key``,
        ``oidc_token`` (an access token of the OpenID provider, :mod:`app.oidc`) or ``cli``
        (the ``trackvkf`` command).
    user_id, key_id : int or None
        Row id of the user or the API key.
    language : str or None
        The language the user chose (kept with the account); None: the browser's.
    """

    name: str
    role: Literal["viewer", "engineer", "admin"]
    kind: Literal["anonymous", "user", "api_key", "oidc_token", "cli"] = "anonymous"
    user_id: int | None = None
    key_id: int | None = None
    language: str | None = None


@dataclass(frozen=True)
class Actor:
    """Who makes an administrative write, and from where: what its audit entry records.

    The services that change something administrative (users, keys, webhooks, channel maps,
    geometries, reference data, runs) take an Actor, never the HTTP request: a route builds it
    from its principal and the peer's address, the command line with :meth:`command_line`.

    Attributes
    ----------
    principal : Principal or None
        Who acts; None for somebody not authenticated (a failed login), named by ``claimed``.
    address : str or None
        The client's address (the reverse proxy's when there is one); None on the command line.
    claimed : str or None
        The name an actor without a principal gave (the user name of a failed login).
    """

    principal: Principal | None
    address: str | None = None
    claimed: str | None = None

    @property
    def name(self) -> str:
        """The audit log's actor: the principal's name, else the claimed one, else ``unknown``."""
        if self.principal is not None:
            return self.principal.name
        return self.claimed if self.claimed is not None else "unknown"

    @property
    def kind(self) -> str:
        """The audit log's actor kind: the principal's kind, else ``none``."""
        return self.principal.kind if self.principal is not None else "none"

    @classmethod
    def command_line(cls, user: str | None = None) -> Actor:
        """The ``trackvkf`` command run by ``user`` (default: ``$USER``): ``cli:<user>``, an admin."""
        who = user if user is not None else os.environ.get("USER", "unknown")
        return cls(Principal(name=f"cli:{who}", role="admin", kind="cli"))
