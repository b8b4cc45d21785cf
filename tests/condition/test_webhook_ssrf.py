"""Issue 24 defect 3: webhook SSRF and delivery.

An admin could register loopback, link-local, private and numeric-form targets and the worker
posted there; the delivery log echoed the target's answer and told refused from open ports;
the timeout was per read (a trickling receiver held the only loop for a minute); a 200 MB
answer was read whole; CRLF, port 99999 and spaces were accepted, a password in the URL was
echoed, and a secret could not be rotated. Against real sockets on loopback (the tests
allow-list 127.0.0.1/32 where a receiver must be reached) and the API over its ASGI client.
"""

from __future__ import annotations

import resource
import socket
import threading
import time

import pytest

from app.alerts import transport
from app.core.signing import SIGNATURE_HEADER, verify
from app.core.url_policy import (
    AddressPolicy,
    RefusedAddress,
    UrlError,
    check_url,
    parse_networks,
    resolve,
)
from app.db import webhooks
from app.db.session import Database
from tests.condition.test_webhooks import Receiver
from worker.deliveries import DeliveryLoop, deliver_due

LOCAL = "127.0.0.1/32"

REFUSED = [
    "127.0.0.1", "127.255.0.9", "::1", "0.0.0.0", "::", "169.254.169.254", "fe80::1", "10.0.0.1", "172.16.5.4",
    "192.168.1.1", "100.64.0.1", "fc00::1", "fd12:3456::1", "224.0.0.1", "239.255.255.250", "ff02::1",
    "240.0.0.1", "255.255.255.255", "198.18.0.1", "192.0.2.1", "2001:db8::1", "192.0.0.8", "fec0::1",
    "::ffff:127.0.0.1", "::ffff:169.254.169.254", "::ffff:10.0.0.1", "::127.0.0.1", "64:ff9b::7f00:1",
    "64:ff9b::a00:1", "2002:7f00:1::1", "2002:a9fe:a9fe::1",
]
PUBLIC = ["8.8.8.8", "1.1.1.1", "93.184.216.34", "2606:4700::1111", "2a00:1450:4001:80b::200e"]


@pytest.mark.parametrize("address", REFUSED)
def test_non_public_addresses_are_refused(address):
    with pytest.raises(RefusedAddress):
        AddressPolicy().check(address)


@pytest.mark.parametrize("address", PUBLIC)
def test_public_addresses_pass(address):
    assert str(AddressPolicy().check(address)) == address


def test_the_allow_list_admits_exactly_its_networks():
    policy = AddressPolicy(parse_networks("127.0.0.1/32, 10.20.0.0/16"))
    assert str(policy.check("127.0.0.1")) == "127.0.0.1" and str(policy.check("10.20.3.4")) == "10.20.3.4"
    for address in ("127.0.0.2", "10.21.0.1", "::1", "169.254.169.254"):
        with pytest.raises(RefusedAddress):
            policy.check(address)
    with pytest.raises(ValueError, match="'10.0.0.300/8'"):
        parse_networks("10.0.0.300/8")


@pytest.mark.parametrize("url", [
    "http://127.1/", "http://2130706433/", "http://0x7f000001/", "http://0x7f.0.0.1/", "http://0177.0.0.1/",
    "http://017700000001/", "http://10.1/", "http://a b.example.org/", "http://example.org/a b",
    "http://example.org/\r\nX-Injected: 1", "http://example.org/\nX: 1", "http://example.org/\tx", "http://example.org:99999/",
    "http://example.org:0/", "http://example.org:-1/", "http://example.org:8o/", "http://user:pw@example.org/",
    "http://user@example.org/", "http://example.org/#frag", "http://[fe80::1%25eth0]/", "http://[::1/",
    "http://exämple.org/", "http://example.org/\x00", "http://-bad-.example.org/", "http:/example.org/",
    "http://example.org\\@evil.org/", "ftp://example.org/", "http://", "http://" + "a" * 2001,
])
def test_malformed_urls_are_refused(url):
    with pytest.raises(UrlError):
        check_url(url)


@pytest.mark.parametrize("url", [
    "https://hooks.example.org/a/b?c=d", "http://example.org:8080", "HTTPS://Example.ORG/x", "http://8.8.8.8/",
    "http://[2606:4700::1111]:8443/hook", "https://xn--exmple-cua.org/",
])
def test_well_formed_urls_pass(url):
    assert check_url(url) == url


def test_a_host_is_refused_when_any_of_its_addresses_is():
    public_and_private = lambda host, port: ["8.8.8.8", "10.0.0.5"]  # noqa: E731
    with pytest.raises(RefusedAddress, match="10.0.0.5"):
        resolve("https://hooks.example.org/", AddressPolicy(), public_and_private)
    with pytest.raises(RefusedAddress, match="does not resolve"):
        resolve("https://nowhere.invalid/", AddressPolicy(), lambda h, p: (_ for _ in ()).throw(OSError("nx")))


# --- the API -------------------------------------------------------------------------------------
@pytest.fixture
def strict(make_client):
    """An admin client with the default policy (no allow-list)."""
    return make_client(webhook_timeout_s=1.5, webhook_retry_base_s=0.2)


@pytest.fixture(scope="module")
def strict_api(tmp_path_factory):
    """One admin client with the default policy for the module's refusals: a refused target stores
    nothing, so each check starts from (and asserts) an empty list of webhooks."""
    from tests.condition.history_support import history_service

    with history_service(tmp_path_factory.mktemp("ssrf-api"), webhook_timeout_s=1.5,
                         webhook_retry_base_s=0.2) as client:
        yield client


@pytest.fixture
def admin(make_client):
    """An admin client whose policy allows the loopback receivers of the tests."""
    return make_client(webhook_timeout_s=1.5, webhook_retry_base_s=0.2, webhook_max_attempts=3,
                       webhook_allowed_networks=LOCAL, webhook_secret_grace_s=1.5)


@pytest.mark.parametrize("url", [
    "http://127.0.0.1:8000/hook", "http://localhost:8000/hook", "http://[::1]:8000/", "http://2130706433/",
    "http://169.254.169.254/latest/meta-data/", "http://10.0.0.1/", "http://192.168.0.10:9000/x",
    "http://[::ffff:127.0.0.1]/", "http://0.0.0.0:8000/", "http://127.0.0.1:8000/a\r\nHost: x",
    "http://127.0.0.1:99999/", "http://user:s3cret@127.0.0.1/", "http://127.0.0.1/a b",
])
def test_the_api_refuses_ssrf_targets_with_422_naming_url(strict_api, url):
    r = strict_api.post("/api/v1/webhooks", json={"url": url})
    assert r.status_code == 422, (url, r.text)
    assert r.json()["field"] == "url"
    assert "s3cret" not in r.text
    assert strict_api.get("/api/v1/webhooks").json()["items"] == []


def test_patching_to_a_private_target_is_refused(admin):
    hook = admin.post("/api/v1/webhooks", json={"url": "http://127.0.0.1:9/hook"}).json()
    r = admin.patch(f"/api/v1/webhooks/{hook['id']}", json={"url": "http://169.254.169.254/"})
    assert r.status_code == 422 and r.json()["field"] == "url"
    assert admin.get("/api/v1/webhooks").json()["items"][0]["url"] == "http://127.0.0.1:9/hook"


def test_credentials_are_never_echoed(admin):
    r = admin.post("/api/v1/webhooks", json={"url": "http://u:pw-1234567@127.0.0.1:9/x"})
    assert r.status_code == 422 and "pw-1234567" not in r.text
    hook = admin.post("/api/v1/webhooks", json={"url": "http://127.0.0.1:9/x?token=tok-98765&team=a"}).json()
    assert hook["url"] == "http://127.0.0.1:9/x?token=***&team=a"
    assert admin.get("/api/v1/webhooks").json()["items"][0]["url"] == hook["url"]
    assert admin.patch(f"/api/v1/webhooks/{hook['id']}", json={"secret": "whsec_rotated-secret-0001"}).status_code == 200
    audit = admin.get("/api/v1/audit", params={"limit": 50}).text
    for secret in ("tok-98765", "whsec_rotated-secret-0001", hook["secret"]):
        assert secret not in audit and secret not in admin.get("/api/v1/webhooks").text


# --- delivery ------------------------------------------------------------------------------------
class RawServer:
    """A TCP server on loopback answering every connection with ``handle(conn)`` in a thread."""

    def __init__(self, handle) -> None:
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(16)
        self.port = self.sock.getsockname()[1]
        self.handle = handle
        self.connections = 0
        self.requests: list[bytes] = []
        self._stop = False
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self) -> None:
        while not self._stop:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            self.connections += 1
            threading.Thread(target=self._run, args=(conn,), daemon=True).start()

    def _run(self, conn: socket.socket) -> None:
        try:
            conn.settimeout(10)
            data = b""
            while b"\r\n\r\n" not in data:
                data += conn.recv(65536)
            head, _, body = data.partition(b"\r\n\r\n")
            length = next((int(line.split(b":")[1]) for line in head.split(b"\r\n")
                           if line.lower().startswith(b"content-length")), 0)
            while len(body) < length:
                body += conn.recv(65536)
            self.requests.append(head + b"\r\n\r\n" + body)
            self.handle(conn)
        except OSError:
            pass
        finally:
            conn.close()

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}/hook"

    def close(self) -> None:
        self._stop = True
        self.sock.close()


def _trickle(conn: socket.socket) -> None:
    conn.sendall(b"HTTP/1.1 200 OK\r\n")
    for _ in range(120):  # a header byte every 0.5 s: a minute if waited for
        conn.sendall(b"X")
        time.sleep(0.5)


def _huge(conn: socket.socket) -> None:
    conn.sendall(b"HTTP/1.1 200 OK\r\nContent-Length: 209715200\r\n\r\n")
    block = b"\0" * (1 << 20)
    for _ in range(200):
        conn.sendall(block)


def _chatty_500(conn: socket.socket) -> None:
    body = b"internal: db password=hunter2 at 10.0.0.7"
    conn.sendall(b"HTTP/1.1 500 Oops\r\nContent-Length: %d\r\n\r\n%s" % (len(body), body))


def _not_http(conn: socket.socket) -> None:
    conn.sendall(b"SSH-2.0-OpenSSH_9.6\r\n")


@pytest.fixture
def servers():
    made = []

    def make(handle):
        s = RawServer(handle)
        made.append(s)
        return s

    yield make
    for s in made:
        s.close()


def _hook(admin, url: str) -> dict:
    r = admin.post("/api/v1/webhooks", json={"url": url})
    assert r.status_code == 201, r.text
    return r.json()


def _ping(admin, hook: dict) -> None:
    assert admin.post(f"/api/v1/webhooks/{hook['id']}/test").status_code == 202


def _log(admin, hook: dict) -> dict:
    (item,) = admin.get("/api/v1/webhooks/deliveries", params={"webhook_id": hook["id"]}).json()["items"]
    return item


def test_a_trickling_receiver_is_cut_at_the_total_timeout(admin, servers):
    slow = servers(_trickle)
    hook = _hook(admin, slow.url)
    _ping(admin, hook)
    db = Database(admin.settings.database_url)
    try:
        t0 = time.monotonic()
        assert deliver_due(db, admin.settings) == 1
        took = time.monotonic() - t0
    finally:
        db.dispose()
    assert took < admin.settings.webhook_timeout_s + 1.0, took  # not 60 s
    item = _log(admin, hook)
    assert item["status"] == "pending" and item["last_status_code"] is None
    assert item["last_error"].startswith("no answer")


def test_a_huge_answer_is_not_read(admin, servers):
    big = servers(_huge)
    hook = _hook(admin, big.url)
    _ping(admin, hook)
    db = Database(admin.settings.database_url)
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    try:
        t0 = time.monotonic()
        assert deliver_due(db, admin.settings) == 1
        took = time.monotonic() - t0
    finally:
        db.dispose()
    grown_mb = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss0) / 1024
    assert took < 1.5 and grown_mb < 50, (took, grown_mb)
    item = _log(admin, hook)
    assert item["status"] == "delivered" and item["last_status_code"] == 200


def test_the_log_keeps_no_answer_text_and_cannot_tell_closed_from_open_ports(admin, servers):
    chatty, banner = servers(_chatty_500), servers(_not_http)
    with socket.socket() as s:  # a port with nothing listening
        s.bind(("127.0.0.1", 0))
        closed_port = s.getsockname()[1]
    hooks = [_hook(admin, chatty.url), _hook(admin, banner.url),
             _hook(admin, f"http://127.0.0.1:{closed_port}/hook")]
    for hook in hooks:
        _ping(admin, hook)
    db = Database(admin.settings.database_url)
    try:
        assert deliver_due(db, admin.settings) == 3
    finally:
        db.dispose()
    text = admin.get("/api/v1/webhooks/deliveries").text
    assert "hunter2" not in text and "Oops" not in text and "SSH" not in text
    chatty_item, banner_item, closed_item = (_log(admin, h) for h in hooks)
    assert (chatty_item["last_status_code"], chatty_item["last_error"]) == (500, "HTTP 500")
    assert banner_item["last_error"] == closed_item["last_error"]  # open non-HTTP port == closed port
    assert banner_item["last_status_code"] is closed_item["last_status_code"] is None
    assert banner_item["last_attempt_at"] and closed_item["last_attempt_at"]


def test_redirects_are_not_followed(admin, servers):
    target = Receiver()
    target.start()
    try:
        def redirect(conn):
            conn.sendall(b"HTTP/1.1 307 Temporary Redirect\r\nLocation: %s\r\nContent-Length: 0\r\n\r\n"
                         % target.url.encode())

        hook = _hook(admin, servers(redirect).url)
        _ping(admin, hook)
        db = Database(admin.settings.database_url)
        try:
            assert deliver_due(db, admin.settings) == 1
        finally:
            db.dispose()
        assert _log(admin, hook)["last_error"] == "HTTP 307" and target.requests == []
    finally:
        target.stop()


def test_dns_rebinding_is_refused_at_delivery_and_the_checked_address_is_the_one_connected(admin, servers):
    """A host that resolved to a public address when registered and resolves to a private one at
    delivery is refused (nothing sent); an allowed answer is connected to as resolved (pinned),
    with the URL's host in the Host header."""
    db = Database(admin.settings.database_url)
    ok = servers(lambda conn: conn.sendall(b"HTTP/1.1 204 No Content\r\n\r\n"))
    try:
        with db.write() as s:
            rebind = webhooks.create_webhook(s, "http://rebind.example.test:9/hook").id
            pinned = webhooks.create_webhook(s, f"http://pinned.example.test:{ok.port}/hook").id
            webhooks.enqueue(s, webhooks.EVENT_PING, {"event": "ping"})
        calls = []

        def resolver(host, port):
            calls.append(host)
            return ["169.254.169.254"] if host.startswith("rebind") else ["127.0.0.1"]

        assert deliver_due(db, admin.settings, resolver=resolver) == 2
    finally:
        db.dispose()
    assert sorted(calls) == ["pinned.example.test", "rebind.example.test"]  # once each: pinned
    by_hook = {d["webhook_id"]: d for d in admin.get("/api/v1/webhooks/deliveries").json()["items"]}
    assert by_hook[rebind]["last_error"].startswith("refused") and by_hook[rebind]["status"] == "pending"
    assert by_hook[pinned]["status"] == "delivered"
    (request,) = ok.requests
    assert f"Host: pinned.example.test:{ok.port}".encode() in request


def test_the_policy_applies_at_delivery_without_an_allow_list(strict, servers):
    ok = servers(lambda conn: conn.sendall(b"HTTP/1.1 204 No Content\r\n\r\n"))
    db = Database(strict.settings.database_url)
    try:
        with db.write() as s:  # as if registered before this version
            webhooks.create_webhook(s, ok.url)
            webhooks.enqueue(s, webhooks.EVENT_PING, {"event": "ping"})
        assert deliver_due(db, strict.settings) == 1
    finally:
        db.dispose()
    assert ok.connections == 0
    (item,) = strict.get("/api/v1/webhooks/deliveries").json()["items"]
    assert item["last_error"].startswith("refused")


def test_one_slow_receiver_does_not_hold_the_others(admin, servers):
    slow, fast = servers(_trickle), Receiver()
    fast.start()
    try:
        slow_hook, fast_hook = _hook(admin, slow.url), _hook(admin, fast.url)
        _ping(admin, slow_hook)
        db = Database(admin.settings.database_url)
        loop = DeliveryLoop(admin.settings, db)
        loop.start()
        try:
            deadline = time.monotonic() + 10
            while slow.connections == 0 and time.monotonic() < deadline:
                time.sleep(0.02)
            assert slow.connections == 1  # the slow one is in flight now
            t0 = time.monotonic()
            _ping(admin, fast_hook)
            while not fast.requests and time.monotonic() < deadline:
                time.sleep(0.02)
            fast_s = time.monotonic() - t0
        finally:
            loop.stop(timeout=5)
            db.dispose()
        assert fast.requests and fast_s < admin.settings.webhook_timeout_s, fast_s
    finally:
        fast.stop()


def test_a_rotated_secret_signs_beside_the_old_one_for_the_grace_period(admin, clock):
    receiver = Receiver()
    receiver.start()
    try:
        hook = _hook(admin, receiver.url)
        old = hook["secret"]
        new = "whsec_the-new-secret-0123456789"
        r = admin.patch(f"/api/v1/webhooks/{hook['id']}", json={"secret": new})
        assert r.status_code == 200 and "secret" not in r.json()
        assert r.json()["secret_rotated_at"] and r.json()["previous_secret_valid_until"]
        db = Database(admin.settings.database_url)
        try:
            _ping(admin, hook)
            assert deliver_due(db, admin.settings) == 1
            clock.advance(admin.settings.webhook_secret_grace_s + 0.2)
            _ping(admin, hook)
            assert deliver_due(db, admin.settings) == 1
        finally:
            db.dispose()
        (h1, b1), (h2, b2) = receiver.requests
        assert h1[SIGNATURE_HEADER].count("v1=") == 2
        assert verify(new, h1[SIGNATURE_HEADER], b1) and verify(old, h1[SIGNATURE_HEADER], b1)
        assert h2[SIGNATURE_HEADER].count("v1=") == 1
        assert verify(new, h2[SIGNATURE_HEADER], b2) and not verify(old, h2[SIGNATURE_HEADER], b2)
        assert admin.get("/api/v1/webhooks").json()["items"][0]["previous_secret_valid_until"] is None
    finally:
        receiver.stop()


def test_the_transport_validates_its_arguments():
    with pytest.raises(ValueError, match="timeout_s"):
        transport.post("http://8.8.8.8/", b"", {}, policy=AddressPolicy(), timeout_s=0, max_answer_bytes=1)
    with pytest.raises(ValueError, match="max_answer_bytes"):
        transport.post("http://8.8.8.8/", b"", {}, policy=AddressPolicy(), timeout_s=1, max_answer_bytes=-1)


def test_a_backlog_of_one_webhook_does_not_keep_the_others_waiting(admin, clock):
    db = Database(admin.settings.database_url)
    try:
        with db.write() as s:
            backlog = webhooks.create_webhook(s, "http://127.0.0.1:9/a").id
            other = webhooks.create_webhook(s, "http://127.0.0.1:9/b").id
            for _ in range(30):
                webhooks.enqueue(s, webhooks.EVENT_PING, {"event": "ping"}, webhook_ids=[backlog])
            clock.advance(0.01)
            (late,) = webhooks.enqueue(s, webhooks.EVENT_PING, {"event": "ping"}, webhook_ids=[other])
        claimed = webhooks.claim_due(db, limit=2, one_per_webhook=True)
        assert sorted(c.webhook_id for c in claimed) == [backlog, other]
        assert late in {c.id for c in claimed}
        assert webhooks.claim_due(db, limit=2, one_per_webhook=True, busy_webhooks=[backlog, other]) == []
        assert len(webhooks.claim_due(db, limit=5)) == 5  # without the rule: the oldest five
    finally:
        db.dispose()
