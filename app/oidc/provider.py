"""The OpenID provider as trackvkf sees it: its discovery document and its signing keys.

Both are fetched over HTTP(S) (``<issuer>/.well-known/openid-configuration``, then its
``jwks_uri``) and kept per process for ``TRACKVKF_OIDC_METADATA_TTL_S``; a token signed with a
key id the kept keys do not hold fetches the keys again at once (a key rotation), at most every
:data:`KEY_REFRESH_MIN_S`. A provider that cannot be reached, answers with an error or answers
something that is not its discovery document raises :class:`ProviderUnavailable`, which names
what failed (the sign-in page shows it).
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Any

import httpx
from joserfc.jwk import KeySet

from app.oidc.config import OidcConfig

__all__ = ["ProviderUnavailable", "ProviderMetadata", "Provider", "provider_for", "provider_of_settings",
           "forget_providers",
           "KEY_REFRESH_MIN_S", "MAX_DOCUMENT_BYTES"]

#: a key id not in the kept keys fetches them again, at most this often, s
KEY_REFRESH_MIN_S = 10.0
#: largest discovery document or key set read, bytes
MAX_DOCUMENT_BYTES = 1024 * 1024


class ProviderUnavailable(RuntimeError):
    """The provider cannot be reached or answers something unusable; ``reason`` says what."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


@dataclass(frozen=True)
class ProviderMetadata:
    """What trackvkf uses of the discovery document (OpenID Connect Discovery 1.0)."""

    issuer: str
    authorization_endpoint: str
    token_endpoint: str
    jwks_uri: str
    end_session_endpoint: str | None
    signing_algorithms: tuple[str, ...]


def _get_json(client: httpx.Client, url: str, what: str) -> dict[str, Any]:
    try:
        response = client.get(url, headers={"Accept": "application/json"})
    except httpx.HTTPError as exc:
        raise ProviderUnavailable(f"{what} {url}: {type(exc).__name__}: {exc or 'no answer'}") from None
    if response.status_code != 200:
        raise ProviderUnavailable(f"{what} {url}: HTTP {response.status_code}")
    if len(response.content) > MAX_DOCUMENT_BYTES:
        raise ProviderUnavailable(f"{what} {url}: larger than {MAX_DOCUMENT_BYTES} bytes")
    try:
        body = response.json()
    except ValueError:
        raise ProviderUnavailable(f"{what} {url}: not JSON") from None
    if not isinstance(body, dict):
        raise ProviderUnavailable(f"{what} {url}: not a JSON object")
    return body


def _metadata(doc: dict[str, Any], issuer: str, url: str) -> ProviderMetadata:
    if doc.get("issuer") != issuer:
        raise ProviderUnavailable(
            f"discovery document {url}: its issuer {doc.get('issuer')!r} is not the configured "
            f"TRACKVKF_OIDC_ISSUER {issuer!r} (they must be equal, character for character)")
    missing = [k for k in ("authorization_endpoint", "token_endpoint", "jwks_uri")
               if not isinstance(doc.get(k), str) or not doc[k].startswith(("https://", "http://"))]
    if missing:
        raise ProviderUnavailable(f"discovery document {url}: no {', '.join(missing)}")
    end = doc.get("end_session_endpoint")
    algs = doc.get("id_token_signing_alg_values_supported")
    return ProviderMetadata(
        issuer=issuer, authorization_endpoint=doc["authorization_endpoint"],
        token_endpoint=doc["token_endpoint"], jwks_uri=doc["jwks_uri"],
        end_session_endpoint=end if isinstance(end, str) and end.startswith(("https://", "http://")) else None,
        signing_algorithms=tuple(a for a in algs if isinstance(a, str)) if isinstance(algs, list) else (),
    )


class Provider:
    """One provider's metadata and keys, fetched on demand and kept (thread-safe).

    Parameters
    ----------
    config : OidcConfig
    clock : callable, optional
        Monotonic seconds (tests inject one).
    """

    def __init__(self, config: OidcConfig, clock: Any = time.monotonic) -> None:
        self.config = config
        self._clock = clock
        self._lock = threading.Lock()
        self._meta: tuple[float, ProviderMetadata] | None = None
        self._keys: tuple[float, KeySet] | None = None

    def client(self) -> httpx.Client:
        """An HTTP client for the provider (its timeout, no redirects followed)."""
        return httpx.Client(timeout=self.config.timeout_s, follow_redirects=False)

    def metadata(self) -> ProviderMetadata:
        """The discovery document (kept ``metadata_ttl_s``).

        Raises
        ------
        ProviderUnavailable
        """
        with self._lock:
            now = self._clock()
            if self._meta is not None and now - self._meta[0] < self.config.metadata_ttl_s:
                return self._meta[1]
        url = self.config.issuer.rstrip("/") + "/.well-known/openid-configuration"
        with self.client() as client:
            meta = _metadata(_get_json(client, url, "discovery document"), self.config.issuer, url)
        with self._lock:
            self._meta = (self._clock(), meta)
        return meta

    def keys(self, *, refresh: bool = False) -> KeySet:
        """The provider's public signing keys (kept ``metadata_ttl_s``; ``refresh`` fetches them
        again unless that was done less than :data:`KEY_REFRESH_MIN_S` ago).

        Raises
        ------
        ProviderUnavailable
        """
        with self._lock:
            now = self._clock()
            if self._keys is not None:
                age = now - self._keys[0]
                if age < self.config.metadata_ttl_s and (not refresh or age < KEY_REFRESH_MIN_S):
                    return self._keys[1]
        meta = self.metadata()
        with self.client() as client:
            doc = _get_json(client, meta.jwks_uri, "key set")
        try:
            keys = KeySet.import_key_set(doc)  # type: ignore[arg-type]
        except Exception as exc:  # noqa: BLE001 - whatever joserfc finds wrong with the document
            raise ProviderUnavailable(f"key set {meta.jwks_uri}: {exc}") from None
        with self._lock:
            self._keys = (self._clock(), keys)
        return keys


_PROVIDERS: dict[str, Provider] = {}
_PROVIDERS_LOCK = threading.Lock()


def provider_for(config: OidcConfig) -> Provider:
    """The process's :class:`Provider` of ``config`` (one per issuer, kept while its
    configuration stays the same)."""
    with _PROVIDERS_LOCK:
        provider = _PROVIDERS.get(config.issuer)
        if provider is None or provider.config != config:
            provider = _PROVIDERS[config.issuer] = Provider(config)
        return provider


def provider_of_settings(settings: Any) -> Provider | None:
    """The process's provider of the service settings; None when corporate sign-in is off."""
    config = OidcConfig.from_settings(settings)
    return provider_for(config) if config is not None else None


def forget_providers() -> None:
    """Drop every kept provider (their documents and keys are fetched again)."""
    with _PROVIDERS_LOCK:
        _PROVIDERS.clear()
