"""A real OpenID Provider for the tests, on 127.0.0.1: Authlib's server components in a small
Flask app, served by werkzeug in a thread of the test process.

What it offers is what a corporate provider (Keycloak, Microsoft Entra ID) offers trackvkf:

* discovery (``/.well-known/openid-configuration``) and the signing keys (``/jwks``, RSA,
  a ``kid`` per key);
* the authorization code flow with PKCE (S256 required) at ``/authorize`` (a login form)
  and ``/token`` (client_secret_basic or client_secret_post), ID tokens signed with RS256
  carrying ``nonce``, ``preferred_username``, ``email`` and the user's ``groups``;
* JWT access tokens (RFC 9068) for the API, audience ``api_audience`` (default: the client
  id), with the same ``groups``;
* RP-initiated logout (``/logout``, Authlib's ``EndSessionEndpoint``): validates the
  ``id_token_hint``, records the logout in :attr:`OpenIDProvider.logouts` and redirects to a
  registered ``post_logout_redirect_uri``.

Nothing of trackvkf is imported here: the provider knows trackvkf only as a registered client.
``id_token_lifetime_s`` / ``access_token_lifetime_s`` may be set negative to make it issue
tokens that are already expired (a real provider's token past its lifetime).
"""

from __future__ import annotations

import html
import secrets
import threading
import time
from dataclasses import dataclass, field
from typing import Any

from authlib.integrations.flask_oauth2 import AuthorizationServer
from authlib.oauth2 import OAuth2Error
from authlib.oauth2.rfc6749 import AuthorizationCodeMixin, ClientMixin
from authlib.oauth2.rfc6749.grants import AuthorizationCodeGrant
from authlib.oauth2.rfc7636 import CodeChallenge
from authlib.oauth2.rfc9068 import JWTBearerTokenGenerator
from authlib.oidc.core import UserInfo
from authlib.oidc.core.grants import OpenIDCode
from authlib.oidc.rpinitiated import EndSessionEndpoint
from flask import Flask, jsonify, request
from joserfc.jwk import KeySet, RSAKey
from werkzeug.serving import WSGIRequestHandler, make_server

__all__ = ["OpenIDProvider", "ProviderUser"]


@dataclass
class ProviderUser:
    """An account at the provider."""

    sub: str
    username: str
    password: str
    groups: list[str]
    email: str = ""
    name: str = ""

    def get_user_id(self) -> str:
        return self.sub


@dataclass
class _Client(ClientMixin):
    client_id: str
    client_secret: str
    redirect_uris: list[str]
    post_logout_redirect_uris: list[str]
    scope: str = "openid profile email"

    @property
    def client_metadata(self) -> dict[str, Any]:
        return {"post_logout_redirect_uris": self.post_logout_redirect_uris}

    def get_client_id(self) -> str:
        return self.client_id

    def get_default_redirect_uri(self) -> str:
        return self.redirect_uris[0]

    def get_allowed_scope(self, scope: str) -> str:
        allowed = set(self.scope.split())
        return " ".join(s for s in (scope or "").split() if s in allowed)

    def check_redirect_uri(self, redirect_uri: str) -> bool:
        return redirect_uri in self.redirect_uris

    def check_client_secret(self, client_secret: str) -> bool:
        return secrets.compare_digest(self.client_secret, client_secret or "")

    def check_endpoint_auth_method(self, method: str, endpoint: str) -> bool:
        return method in ("client_secret_basic", "client_secret_post")

    def check_response_type(self, response_type: str) -> bool:
        return response_type == "code"

    def check_grant_type(self, grant_type: str) -> bool:
        return grant_type == "authorization_code"


@dataclass
class _Code(AuthorizationCodeMixin):
    code: str
    client_id: str
    redirect_uri: str
    scope: str
    user: ProviderUser
    nonce: str | None
    code_challenge: str | None
    code_challenge_method: str | None
    auth_time: int = field(default_factory=lambda: int(time.time()))

    def get_redirect_uri(self) -> str:
        return self.redirect_uri

    def get_scope(self) -> str:
        return self.scope

    def get_nonce(self) -> str | None:
        return self.nonce

    def get_auth_time(self) -> int:
        return self.auth_time

    def get_acr(self) -> str | None:
        return None

    def get_amr(self) -> list[str] | None:
        return ["pwd"]


_LOGIN_FORM = """<!doctype html><html lang="en"><head><meta charset="utf-8"><title>{title} · sign in</title></head>
<body><h1>{title}</h1><form method="post" action="{action}">
<label>User <input name="username" id="op-username" autocomplete="off"></label>
<label>Password <input name="password" id="op-password" type="password"></label>
<button type="submit" id="op-submit">Sign in</button><p id="op-error">{error}</p></form></body></html>"""


class _QuietHandler(WSGIRequestHandler):
    """No access log on stderr (the tests' output stays readable)."""

    def log_request(self, *args: Any, **kwargs: Any) -> None:
        pass


class OpenIDProvider:
    """The provider app and its server thread.

    Parameters
    ----------
    title : str
        Shown on its login page.
    users : list of ProviderUser

    Attributes
    ----------
    id_token_lifetime_s, access_token_lifetime_s : int
        Lifetime of the tokens it issues, s (negative: issued expired).
    api_audience : str or None
        ``aud`` of its access tokens (default: the client's id).
    logouts : list of dict
        The claims of the ``id_token_hint`` of every RP-initiated logout it performed.
    """

    def __init__(self, title: str = "Test provider", users: list[ProviderUser] | None = None) -> None:
        self.title = title
        self.users = {u.username: u for u in (users or [])}
        self.clients: dict[str, _Client] = {}
        self.codes: dict[str, _Code] = {}
        self.logouts: list[dict[str, Any]] = []
        self.id_token_lifetime_s = 300
        self.access_token_lifetime_s = 300
        self.api_audience: str | None = None
        self.key = RSAKey.generate_key(2048, parameters={"kid": secrets.token_hex(8), "use": "sig"},
                                       private=True)
        self.keys = KeySet([self.key])
        self._server = make_server("127.0.0.1", 0, self._build_app(), threaded=True,
                                   request_handler=_QuietHandler)
        self._access_tokens.issuer = self.issuer
        self._thread: threading.Thread | None = None

    # --- running -------------------------------------------------------------------
    @property
    def port(self) -> int:
        return int(self._server.server_port)

    @property
    def issuer(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(self) -> OpenIDProvider:
        self._thread = threading.Thread(target=self._server.serve_forever, name="oidc-provider",
                                        daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._server.shutdown()
        self._server.server_close()
        if self._thread is not None:
            self._thread.join(timeout=10)

    def __enter__(self) -> OpenIDProvider:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def register_client(self, client_id: str, client_secret: str, redirect_uris: list[str],
                        post_logout_redirect_uris: list[str] | None = None) -> None:
        self.clients[client_id] = _Client(client_id, client_secret, list(redirect_uris),
                                          list(post_logout_redirect_uris or []))

    def public_jwks(self) -> dict[str, Any]:
        return self.keys.as_dict(private=False)

    # --- the app -------------------------------------------------------------------------
    def _build_app(self) -> Flask:  # noqa: C901 - one closure per endpoint
        provider = self
        app = Flask(f"oidc-provider-{id(self)}")
        app.config["OAUTH2_TOKEN_EXPIRES_IN"] = {"authorization_code": 300}

        def claims_of(user: ProviderUser, scope: str) -> dict[str, Any]:
            info = UserInfo(sub=user.sub, preferred_username=user.username, name=user.name or user.username,
                            email=user.email or f"{user.username}@example.test").filter(scope)
            info["preferred_username"] = user.username
            info["groups"] = list(user.groups)
            return dict(info)

        class Code(AuthorizationCodeGrant):
            TOKEN_ENDPOINT_AUTH_METHODS = ["client_secret_basic", "client_secret_post"]

            def save_authorization_code(self, code: str, req: Any) -> None:
                provider.codes[code] = _Code(
                    code=code, client_id=req.client.get_client_id(), redirect_uri=req.payload.redirect_uri,
                    scope=req.scope, user=req.user, nonce=req.payload.data.get("nonce"),
                    code_challenge=req.payload.data.get("code_challenge"),
                    code_challenge_method=req.payload.data.get("code_challenge_method"),
                )

            def query_authorization_code(self, code: str, client: _Client) -> _Code | None:
                item = provider.codes.get(code)
                return item if item is not None and item.client_id == client.get_client_id() else None

            def delete_authorization_code(self, authorization_code: _Code) -> None:
                provider.codes.pop(authorization_code.code, None)

            def authenticate_user(self, authorization_code: _Code) -> ProviderUser:
                return authorization_code.user

        class IdToken(OpenIDCode):
            def exists_nonce(self, nonce: str, req: Any) -> bool:
                return any(c.nonce == nonce for c in provider.codes.values())

            def resolve_client_private_key(self, client: _Client) -> KeySet:
                return provider.keys

            def get_client_algorithm(self, client: _Client) -> str:
                return "RS256"

            def get_encode_header(self, client: _Client) -> dict[str, str]:
                return {"alg": "RS256", "kid": provider.key.kid}

            def get_client_claims(self, client: _Client) -> dict[str, Any]:
                now = int(time.time())
                return {"iss": provider.issuer, "aud": [client.get_client_id()], "iat": now,
                        "exp": now + provider.id_token_lifetime_s}

            def generate_user_info(self, user: ProviderUser, scope: str) -> UserInfo:
                return UserInfo(claims_of(user, scope))

        class AccessToken(JWTBearerTokenGenerator):
            def get_jwks(self) -> KeySet:
                return provider.keys

            def get_audiences(self, client: _Client, user: ProviderUser, scope: str) -> str:
                return provider.api_audience or client.get_client_id()

            def get_extra_claims(self, client: _Client, grant_type: str, user: ProviderUser,
                                 scope: str) -> dict[str, Any]:
                return {"groups": list(user.groups), "preferred_username": user.username}

        class Logout(EndSessionEndpoint):
            def get_server_jwks(self) -> KeySet:
                return provider.keys

            def end_session(self, end_session_request: Any) -> None:
                provider.logouts.append(dict(end_session_request.id_token_claims or {}))

        server = AuthorizationServer(app, query_client=self.clients.get, save_token=lambda token, req: None)
        # "iss" of the access tokens: set once the socket is bound (the port is not known yet)
        self._access_tokens = AccessToken(
            issuer="", expires_generator=lambda client, grant_type: provider.access_token_lifetime_s)
        server.register_token_generator("default", self._access_tokens)
        server.register_grant(Code, [CodeChallenge(required=True), IdToken(require_nonce=True)])
        server.register_endpoint(Logout)

        @app.get("/.well-known/openid-configuration")
        def discovery() -> Any:
            base = provider.issuer
            return jsonify({
                "issuer": base,
                "authorization_endpoint": f"{base}/authorize",
                "token_endpoint": f"{base}/token",
                "jwks_uri": f"{base}/jwks",
                "end_session_endpoint": f"{base}/logout",
                "response_types_supported": ["code"],
                "subject_types_supported": ["public"],
                "id_token_signing_alg_values_supported": ["RS256"],
                "scopes_supported": ["openid", "profile", "email"],
                "grant_types_supported": ["authorization_code"],
                "code_challenge_methods_supported": ["S256"],
                "token_endpoint_auth_methods_supported": ["client_secret_basic", "client_secret_post"],
                "claims_supported": ["sub", "iss", "aud", "exp", "iat", "nonce", "preferred_username",
                                     "email", "name", "groups"],
            })

        @app.get("/jwks")
        def jwks() -> Any:
            return jsonify(provider.public_jwks())

        @app.route("/authorize", methods=["GET", "POST"])
        def authorize() -> Any:
            try:
                grant = server.get_consent_grant(end_user=None)
            except OAuth2Error as error:
                return jsonify(dict(error.get_body())), 400
            action = html.escape(request.full_path, quote=True)
            if request.method == "GET":
                return _LOGIN_FORM.format(title=html.escape(provider.title), action=action, error="")
            user = provider.users.get(request.form.get("username", ""))
            if user is None or not secrets.compare_digest(user.password, request.form.get("password", "")):
                return _LOGIN_FORM.format(title=html.escape(provider.title), action=action,
                                          error="wrong user or password"), 200
            return server.create_authorization_response(grant_user=user, grant=grant)

        @app.post("/token")
        def token() -> Any:
            return server.create_token_response()

        @app.route("/logout", methods=["GET", "POST"])
        def logout() -> Any:
            return server.create_endpoint_response("end_session") or "signed out of the provider"

        return app
