"""The local account of a signed-in identity, its session and audit entry; bearer tokens.

A user who signs in at the provider for the first time gets an account (``auth_source``
``oidc``, no password, known by ``"<issuer> <sub>"``) named by the token's user name claim;
at every sign-in its role is set from its groups again (the provider is the source of the
role) and a session begins, holding the ID token for the provider's sign-out. Refused, and
audited as ``auth.login`` ``denied`` with the reason, like a wrong password: a token that names
no usable user name, a user in none of the mapped groups, a name that belongs to a local user
or to another subject, a deactivated account (admins deactivate accounts of either kind).
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass
from typing import Any

from app.audit import record
from app.core.security import Actor, Principal
from app.db import auth_crud
from app.db.models import utcnow
from app.db.session import Database
from app.oidc.flow import SignedIn
from app.oidc.provider import Provider
from app.oidc.tokens import TokenRejected, check_access_token

__all__ = ["SignInRefused", "SignInResult", "sign_in", "bearer_principal"]


class SignInRefused(PermissionError):
    """The provider vouched for the user, but trackvkf does not let them in; ``reason`` says why
    (for the page and the audit log)."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


@dataclass(frozen=True)
class SignInResult:
    """A session begun: who, and the session token (for the cookie)."""

    principal: Principal
    token: str
    created: bool


def _refusal(session: Any, config: Any, claims: dict[str, Any], username: str | None, groups: list[str],
             role: str | None) -> str | None:
    """Why this identity may not sign in, or None (read before anything is written)."""
    if username is None:
        return (f"the provider's token names no usable user name (claims {config.username_claim}, email, "
                "sub: 1 to 64 letters, digits and . _ - @)")
    if role is None:
        return (f"{username} is in none of the groups that give access to trackvkf "
                f"(claim {config.groups_claim}: {', '.join(groups[:20]) or 'none'})")
    user = auth_crud.user_by_external_subject(session, config.subject_of(claims))
    if user is None:
        other = auth_crud.get_user(session, username)
        if other is not None:
            kind = "a local user" if other.auth_source == "local" else "another account of the provider"
            return f"the user name {username} belongs to {kind}; an admin must rename or remove it"
    elif not user.active:
        return f"the account {user.username} is deactivated"
    return None


def sign_in(db: Database, provider: Provider, signed: SignedIn, *, address: str | None, ttl_s: float,
            previous_session: str | None = None) -> SignInResult:
    """Let a user the provider vouched for in: the account created or updated, a session begun,
    ``auth.login`` audited (``detail.method = "oidc"``).

    Parameters
    ----------
    db : Database
    provider : Provider
    signed : SignedIn
        The checked ID token (:func:`app.oidc.flow.finish`).
    address : str or None
        The client's address (of the session and the audit entry).
    ttl_s : float
        Lifetime of the session, s.
    previous_session : str, optional
        The browser's session token, ended (the same browser signs in again).

    Raises
    ------
    SignInRefused
        After the refusal was audited.
    """
    config = provider.config
    claims = signed.claims
    username = config.username_of(claims)
    groups = config.groups_of(claims)
    role = config.role_of(groups)
    matched = sorted(g for g in groups if g in config.role_groups)
    detail: dict[str, Any] = {"method": "oidc", "provider": config.provider_name, "groups": matched}
    with db.write() as session:
        refusal = _refusal(session, config, claims, username, groups, role)
        if refusal is not None:
            record(session, Actor(None, address, claimed=username or "oidc"), "auth.login",
                   target=username or str(claims.get("sub"))[:128], outcome="denied",
                   detail={**detail, "reason": refusal})
        else:
            subject = config.subject_of(claims)
            user = auth_crud.user_by_external_subject(session, subject)
            created = user is None
            if user is None:
                user = auth_crud.create_external_user(session, username, role, subject,
                                                      created_by=f"oidc:{config.provider_name}"[:128])
            elif user.role != role:
                detail["role_before"] = user.role
                user.role = role
                user.updated_at = utcnow()
            if previous_session:
                auth_crud.delete_session(session, previous_session)
            token = auth_crud.create_session(session, user, dt.timedelta(seconds=ttl_s), address,
                                             id_token=signed.id_token)
            principal = Principal(name=user.username, role=user.role, kind="user", user_id=user.id,
                                  language=user.language)
            record(session, Actor(principal, address), "auth.login", target=user.username,
                   detail={**detail, "role": role, "created": created})
    if refusal is not None:
        raise SignInRefused(refusal)
    return SignInResult(principal=principal, token=token, created=created)


def bearer_principal(db: Database, provider: Provider, token: str) -> Principal:
    """The principal of a provider's access token sent as ``Authorization: Bearer``.

    Its role comes from its groups (as at a sign-in); the account of its subject, if it ever
    signed in, must be active.

    Raises
    ------
    TokenRejected
    ProviderUnavailable
    """
    config = provider.config
    claims = check_access_token(token, provider)
    username = config.username_of(claims)
    role = config.role_of(config.groups_of(claims))
    if username is None:
        raise TokenRejected("the token names no usable user name")
    if role is None:
        raise TokenRejected(f"{username} is in none of the groups that give access to trackvkf")
    with db.read() as session:
        user = auth_crud.user_by_external_subject(session, config.subject_of(claims))
        if user is not None and not user.active:
            raise TokenRejected(f"the account {user.username} is deactivated")
        user_id = user.id if user is not None else None
    return Principal(name=username, role=role, kind="oidc_token", user_id=user_id)
