"""Which URLs a webhook may have, and which addresses the workers may send to (SSRF policy).

A webhook is configured by an admin, but its requests leave from the worker
hosts, inside the operator's network: without a policy the service becomes a
proxy into it (cloud metadata at 169.254.169.254, databases on loopback,
admin consoles on 10.x). Two checks, one rule:

* :func:`check_url` — the URL's syntax, strictly: ``http``/``https`` only, a
  host, ASCII without spaces or control characters (no CR/LF header
  injection), a port in 1–65535, no user name or password (credentials would
  be echoed by the API and logs: the receiver authenticates the request by its
  signature instead), no fragment, and an IP address only in its canonical
  form (``127.1``, ``2130706433``, ``0x7f.0.0.1`` or ``0177.0.0.1`` are
  refused outright: resolvers read them as 127.0.0.1).
* :meth:`AddressPolicy.check` — every address the host resolves to must be a
  public unicast address: loopback, link-local, private (RFC 1918, ULA),
  shared (100.64/10), multicast, unspecified, reserved, documentation and
  benchmarking ranges are refused, and so is an IPv6 address embedding such an
  IPv4 one (IPv4-mapped ``::ffff:…``, IPv4-compatible, 6to4, Teredo, NAT64).
  :func:`resolve` applies it when a webhook is registered or changed (422) and
  again at every delivery (:mod:`app.alerts.transport`), where the address
  checked is the one connected to, so a DNS answer that changes in between
  (DNS rebinding) gains nothing.

On-premises receivers on private addresses are allowed by an explicit
allow-list of networks (``TRACKVKF_WEBHOOK_ALLOWED_NETWORKS``, CIDR, comma
separated; empty by default): an address inside one of them is accepted
whatever its kind.
"""

from __future__ import annotations

import ipaddress
import re
import socket
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from urllib.parse import SplitResult, parse_qsl, urlencode, urlsplit, urlunsplit

from app.core.i18n import N_, _

__all__ = [
    "MAX_URL_CHARS",
    "UrlError",
    "RefusedAddress",
    "AddressPolicy",
    "parse_networks",
    "check_url",
    "resolve",
    "redact_url",
    "Resolver",
]

MAX_URL_CHARS = 2000

IPAddress = ipaddress.IPv4Address | ipaddress.IPv6Address
IPNetwork = ipaddress.IPv4Network | ipaddress.IPv6Network
#: ``resolver(host, port)`` → the addresses of ``host`` (default: :func:`socket.getaddrinfo`)
Resolver = Callable[[str, int], Sequence[str]]

#: refused although Python's ``is_global`` may say otherwise (IETF protocol assignments, 6to4 relays)
_DENIED = tuple(ipaddress.ip_network(n) for n in ("192.0.0.0/24", "192.88.99.0/24", "0.0.0.0/8", "fec0::/10"))
#: NAT64 prefixes: the last 32 bits are an IPv4 address
_NAT64 = tuple(ipaddress.ip_network(n) for n in ("64:ff9b::/96", "64:ff9b:1::/48"))
_LABEL = re.compile(r"^(?!-)[A-Za-z0-9-]{1,63}(?<!-)$")
_NUMERIC_LABEL = re.compile(r"^(0x[0-9a-f]*|[0-9]+)$", re.IGNORECASE)
_SECRET_QUERY_KEYS = re.compile(r"(token|key|secret|pass|pwd|auth|sig|code|credential)", re.IGNORECASE)


class UrlError(ValueError):
    """The URL is not acceptable (the message says why; the API answers 422 naming ``url``)."""


class RefusedAddress(UrlError):
    """The host resolves to an address the policy refuses (or does not resolve)."""


def parse_networks(text: str | Iterable[str] | None) -> tuple[IPNetwork, ...]:
    """Networks of an allow-list: CIDR strings, comma separated (``"10.1.0.0/16, 127.0.0.1/32"``).

    Raises
    ------
    ValueError
        Naming the entry that is not a network.
    """
    if text is None:
        return ()
    items = text.split(",") if isinstance(text, str) else list(text)
    out = []
    for item in (str(i).strip() for i in items):
        if not item:
            continue
        try:
            out.append(ipaddress.ip_network(item, strict=False))
        except ValueError:
            raise ValueError(f"webhook_allowed_networks: {item!r} is not an IP network (CIDR)") from None
    return tuple(out)


def _embedded_ipv4(ip: ipaddress.IPv6Address) -> list[ipaddress.IPv4Address]:
    out = []
    if ip.ipv4_mapped is not None:
        out.append(ip.ipv4_mapped)
    if ip.sixtofour is not None:
        out.append(ip.sixtofour)
    if ip.teredo is not None:
        out.extend(ip.teredo)
    if any(ip in net for net in _NAT64) or int(ip) >> 32 == 0:  # NAT64, IPv4-compatible ::a.b.c.d
        out.append(ipaddress.IPv4Address(int(ip) & 0xFFFFFFFF))
    return out


#: why an address is not public: the words of each kind (``"a loopback address"``)
_NOT_PUBLIC: dict[str, str] = {
    "loopback": N_("a loopback address"), "unspecified": N_("an unspecified address"),
    "link_local": N_("a link-local address"), "multicast": N_("a multicast address"),
    "private": N_("a private address"), "reserved": N_("a reserved address"),
}


def _why_not_public(ip: IPAddress) -> str | None:
    """Why ``ip`` is not a public unicast address, in words (``"a private address"``; None: it is)."""
    for name in ("loopback", "unspecified", "link_local", "multicast", "private", "reserved"):
        if getattr(ip, f"is_{name}"):
            return _(_NOT_PUBLIC[name])
    if isinstance(ip, ipaddress.IPv6Address) and ip.is_site_local:
        return _("a site-local address")
    if any(ip in net for net in _DENIED if net.version == ip.version):
        return _(_NOT_PUBLIC["reserved"])
    if not ip.is_global:
        return _("a non-global address")
    if isinstance(ip, ipaddress.IPv6Address):
        for inner in _embedded_ipv4(ip):
            why = _why_not_public(inner)
            if why is not None:
                return _("an address embedding {inner} ({why})", inner=inner, why=why)
    return None


@dataclass(frozen=True)
class AddressPolicy:
    """Which addresses webhook requests may go to.

    Parameters
    ----------
    allowed_networks : tuple of ip_network
        Networks accepted whatever their kind (on-premises receivers); empty by default.
    """

    allowed_networks: tuple[IPNetwork, ...] = ()

    @classmethod
    def from_settings(cls, settings) -> AddressPolicy:
        """The policy of the service settings (``webhook_allowed_networks``)."""
        return cls(parse_networks(settings.webhook_allowed_networks))

    def check(self, address: str | IPAddress) -> IPAddress:
        """The address, if requests may go to it.

        Raises
        ------
        RefusedAddress
            Saying which kind of address it is.
        """
        try:
            ip = ipaddress.ip_address(address.split("%", 1)[0] if isinstance(address, str) else address)
        except ValueError:
            raise RefusedAddress(_("{address!r} is not an IP address", address=address)) from None
        if any(ip in net for net in self.allowed_networks if net.version == ip.version):
            return ip
        why = _why_not_public(ip)
        if why is not None:
            raise RefusedAddress(
                _("resolves to {ip}, {why}: webhooks may only reach public addresses (on-premises receivers: TRACKVKF_WEBHOOK_ALLOWED_NETWORKS)", ip=ip, why=why))
        return ip


def _check_host(host: str) -> None:
    """Hostname syntax (LDH labels) or a canonical IP literal; refuses numeric forms resolvers accept."""
    if host.startswith("["):
        inner = host[1:-1] if host.endswith("]") else ""
        if "%" in inner:
            raise UrlError(_("an IPv6 zone (%…) is not accepted"))
        try:
            ipaddress.IPv6Address(inner)
        except ValueError:
            raise UrlError(_("host {host!r} is not an IPv6 address", host=host)) from None
        return
    try:
        ipaddress.IPv4Address(host)
        return
    except ValueError:
        pass
    name = host[:-1] if host.endswith(".") else host
    if not name or len(name) > 253:
        raise UrlError(_("the host name is empty or longer than 253 characters"))
    labels = name.split(".")
    if not all(_LABEL.match(label) for label in labels):
        raise UrlError(_("host {host!r} is not a valid host name (letters, digits, hyphens; IDN in punycode)", host=host))
    if _NUMERIC_LABEL.match(labels[-1]):
        raise UrlError(_("host {host!r} is a numeric address in a non-canonical form: write it as a.b.c.d", host=host))


def _netloc_host(parts: SplitResult) -> str:
    """The host part of the netloc as written (brackets kept), after userinfo was refused."""
    netloc = parts.netloc
    if netloc.startswith("["):
        end = netloc.find("]")
        return netloc[: end + 1] if end >= 0 else netloc
    return netloc.rsplit(":", 1)[0] if ":" in netloc else netloc


def check_url(url: str) -> str:
    """The URL (surrounding whitespace removed), if its syntax is acceptable for a webhook.

    Raises
    ------
    UrlError
        Saying what is wrong (scheme, host, port, credentials, characters, length).
    """
    if not isinstance(url, str):
        raise UrlError(_("must be a string"))
    value = url.strip()
    if len(value) > MAX_URL_CHARS:
        raise UrlError(_("at most {n} characters", n=MAX_URL_CHARS))
    if not value:
        raise UrlError(_("is empty"))
    bad = next((c for c in value if ord(c) <= 0x20 or ord(c) >= 0x7F or c in '\\"<>^`{|}'), None)
    if bad is not None:
        raise UrlError(_('contains {bad!r} (spaces, control characters, non-ASCII and {{|}}\\^"<>` are not accepted: percent-encode them)', bad=bad))
    try:
        parts = urlsplit(value)
        parts.port  # noqa: B018 - raises for a port out of range
    except ValueError as exc:
        raise UrlError(_("is not a valid URL ({error})", error=exc)) from None
    if parts.scheme.lower() not in ("http", "https"):
        raise UrlError(_("must be an http:// or https:// URL, got {value!r}", value=value[:80]))
    if not value.lower().startswith(f"{parts.scheme.lower()}://"):
        raise UrlError(_("must start with http:// or https://"))
    if "@" in parts.netloc:
        raise UrlError(_("credentials in the URL (user:password@) are not accepted: they would be shown in the webhook list and the audit log; the receiver checks the request's signature instead"))
    if parts.fragment or "#" in value:
        raise UrlError(_("a fragment (#…) is not accepted"))
    host = _netloc_host(parts)
    if not host or not parts.hostname:
        raise UrlError(_("has no host"))
    _check_host(host)
    port_text = parts.netloc[len(host):]
    if port_text:
        if not re.fullmatch(r":[0-9]{1,5}", port_text):
            raise UrlError(_("port {port_text!r} is not a number in 1–65535", port_text=port_text[1:]))
        if not 1 <= int(port_text[1:]) <= 65535:
            raise UrlError(_("port {port_text} is not in 1–65535", port_text=port_text[1:]))
    return value


def _default_resolver(host: str, port: int) -> list[str]:
    infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, proto=socket.IPPROTO_TCP)
    return [info[4][0] for info in infos]


def resolve(url: str, policy: AddressPolicy, resolver: Resolver | None = None) -> list[IPAddress]:
    """The addresses of the URL's host, every one allowed by ``policy`` (in the resolver's order).

    Parameters
    ----------
    url : str
        A URL accepted by :func:`check_url`.
    policy : AddressPolicy
    resolver : callable, optional
        ``resolver(host, port)`` → addresses (default: the system resolver).

    Raises
    ------
    RefusedAddress
        When the host does not resolve, or when any of its addresses is refused
        (one refused address refuses the host: a resolver may answer either).
    """
    parts = urlsplit(check_url(url))
    host = parts.hostname or ""
    port = parts.port or (443 if parts.scheme.lower() == "https" else 80)
    try:
        addresses = list((resolver or _default_resolver)(host, port))
    except (OSError, UnicodeError) as exc:
        raise RefusedAddress(_("host {host!r} does not resolve ({kind})", host=host, kind=type(exc).__name__)) from None
    if not addresses:
        raise RefusedAddress(_("host {host!r} does not resolve", host=host))
    out: list[IPAddress] = []
    for address in addresses:
        ip = policy.check(address)
        if ip not in out:
            out.append(ip)
    return out


def redact_url(url: str) -> str:
    """The URL as shown in lists and logs: a password (user:password@, left by an older version)
    and the values of query parameters named like credentials (token, key, secret, ...) masked."""
    try:
        parts = urlsplit(url)
        netloc = parts.netloc
        if "@" in netloc:
            netloc = "***@" + netloc.rsplit("@", 1)[1]
        query = parts.query
        if query:
            pairs = parse_qsl(query, keep_blank_values=True)
            query = urlencode([(k, "***" if _SECRET_QUERY_KEYS.search(k) else v) for k, v in pairs], safe="*")
        return urlunsplit((parts.scheme, netloc, parts.path, query, ""))
    except ValueError:
        return "(unparseable URL)"
