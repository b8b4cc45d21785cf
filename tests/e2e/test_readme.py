"""The README's shell commands (and those of the guides it sends a reader to), run verbatim
against a service holding the demo, which they must leave as it was.

Blocks preceded by ``<!-- readme-test: run -->`` are run in one bash, in the order of
:data:`DOCS` and of each file (the README first: it starts the service), in
a fresh project directory (the repository's ``.venv`` linked in, the default ``./var``) whose
``./var`` holds a copy of the processed demo (tests/demo_db.py: three runs of line SIM track 1,
one of SIM-B, SIM's reference data; built once per session and shared, never processed again
here). A line whose comment says ``(runs until Ctrl-C)`` is started in the background (serve,
worker). The harness adds only what a reader sees anyway: ``curl`` fails on an HTTP error
(``--fail-with-body``: every request of the docs answers 2xx), and the first command that fails
fails the test, named; and it reads the demo's state (:data:`DEMO_STATE`: its runs, the
reference run of each line, the first run's stiffness index, places, sections, heat map, wheel
trend, reference data) once the service is up and again after the last command: the docs' examples
work on a line of their own (docs/api.md) and must not change any of it.

Port 8000, as written in the README: the script runs in a network namespace of its own
(``unshare -n``, root) so that it never meets another service on this machine; without one it
runs only when port 8000 is free.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import socket
import subprocess
from pathlib import Path

import pytest

pytestmark = pytest.mark.timeout(900)

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
#: the files whose marked blocks run, in this order
DOCS = (README, ROOT / "docs" / "api.md", ROOT / "docs" / "cli.md")
MARKER = "<!-- readme-test: run -->"
BACKGROUND = "(runs until Ctrl-C)"
#: the demo's state the docs must leave as it was: requests (``{first}``: the demo's first run);
#: ``condition/lines`` is compared on the demo's lines only
DEMO_STATE = (
    "/api/v1/runs?line_id=SIM&limit=100",
    "/api/v1/runs?line_id=SIM-B&limit=100",
    "/api/v1/condition/lines",
    "/api/v1/runs/{first}/profile?wheel=12&index=true&level=100",
    "/api/v1/runs/{first}/alignment",
    "/api/v1/condition/places?line_id=SIM&track=1&include_closed=true",
    "/api/v1/condition/sections?line_id=SIM&track=1",
    "/api/v1/condition/heatmap?line_id=SIM&track=1",
    "/api/v1/wheels/trend?vehicle_id=SIM-1",
    "/api/v1/reference/superstructure?line_id=SIM",
    "/api/v1/reference/maintenance?line_id=SIM",
)
#: the environment variable that hands the state reader its (admin) key
STATE_KEY = "README_TEST_STATE_KEY"


def readme_blocks(text: str) -> list[list[str]]:
    """The marked ```bash blocks, each as its commands (continuation lines joined)."""
    blocks = []
    lines = text.splitlines()
    for i, line in enumerate(lines):
        if line.strip() != MARKER:
            continue
        assert i + 1 < len(lines) and lines[i + 1].strip() == "```bash", f"README line {i + 1}: {MARKER} must precede a ```bash block"
        body = []
        for raw in lines[i + 2:]:
            if raw.strip() == "```":
                break
            body.append(raw)
        commands, current = [], ""
        for raw in body:
            current += raw
            if raw.endswith("\\"):
                current = current[:-1] + " "
                continue
            if current.strip():
                commands.append(current)
            current = ""
        blocks.append(commands)
    return blocks


def readme_script(blocks: list[list[str]], logs: Path, state: tuple[Path, list[str]] | None = None) -> str:
    """One bash script running the blocks; with ``state`` (a directory and request paths) the answers
    to those requests are written to ``before/<i>.json`` once the service is up and to
    ``after/<i>.json`` at the end (authorised with the key in :data:`STATE_KEY`)."""
    out = [
        "set -eEuo pipefail",
        "trap 'echo \"README command failed (exit $?): $BASH_COMMAND\" >&2' ERR",
        "trap 'kill $(jobs -p) 2>/dev/null || true' EXIT",
        "if ip link show lo >/dev/null 2>&1; then ip link set lo up 2>/dev/null || true; fi",
        "curl() { command curl --fail-with-body -sS \"$@\"; echo; }",
    ]
    if state is not None:
        directory, paths = state
        reads = " ".join(  # at once; each one's exit status checked
            f"command curl --fail-with-body -sS -H \"Authorization: Bearer ${STATE_KEY}\" "
            f"'http://127.0.0.1:8000{path}' >\"{directory}/$1/{i}.json\" & pids+=($!);" for i, path in enumerate(paths))
        out.append(f"__demo_state() {{ local pids=() pid; mkdir -p \"{directory}/$1\"; {reads} "
                   "for pid in \"${pids[@]}\"; do wait \"$pid\"; done; }")
    n = 0
    read_before = state is None
    for block in blocks:
        started = False
        for command in block:
            if BACKGROUND in command:
                n += 1
                out.append(f"{command.split('#')[0].strip()} >{logs / f'background-{n}.log'} 2>&1 &")
                started = True
            else:
                out.append(command)
        if started:
            out.append("for _ in $(seq 240); do command curl -s -o /dev/null http://127.0.0.1:8000/api/v1/health && break; sleep 0.5; done")
            if not read_before:
                out.append("__demo_state before")
                read_before = True
    if state is not None:
        out.append("__demo_state after")
    return "\n".join(out) + "\n"


def _isolation() -> list[str] | None:
    """``["unshare", "-n"]`` when a private network namespace can be made, else None."""
    if shutil.which("unshare") is None or shutil.which("ip") is None or os.geteuid() != 0:
        return None
    probe = subprocess.run(["unshare", "-n", "true"], capture_output=True)
    return ["unshare", "-n"] if probe.returncode == 0 else None


def _port_8000_free() -> bool:
    with socket.socket() as sock:
        try:
            sock.bind(("127.0.0.1", 8000))
        except OSError:
            return False
        return True


def all_blocks() -> list[list[str]]:
    """The marked blocks of :data:`DOCS`, in order."""
    return [block for path in DOCS for block in readme_blocks(path.read_text(encoding="utf-8"))]


def test_marked_blocks_exist_and_parse():
    blocks = all_blocks()
    assert readme_blocks(README.read_text(encoding="utf-8")), "the README starts the service in a marked block"
    assert len(blocks) >= 4
    text = "\n".join(c for b in blocks for c in b)
    assert "source .venv/bin/activate" in text and "trackvkf serve" in text
    assert ".venv/bin/trackvkf" not in text  # one way to run the command, as the README says
    for command in (c for b in blocks for c in b):
        if command.lstrip().startswith("curl") and "/api/v1/" in command and "/health" not in command:
            assert 'Authorization: Bearer $KEY' in command, command


def _demo_in(var: Path, demo) -> str:
    """Copy the processed demo into ``var`` where the README's commands find it (the default
    database and run store), without its webhook (no receiver here); an admin key for the state reads."""
    from app.db import webhooks
    from app.db.session import Database
    from tests.api.support import create_api_key
    from tests.demo_db import DB_FILE, RUN_STORE

    var.mkdir(parents=True)
    shutil.copy2(demo.directory / DB_FILE, var / "trackvkf.db")
    shutil.copytree(demo.directory / RUN_STORE, var / "runs")
    url = f"sqlite:///{var / 'trackvkf.db'}"
    db = Database(url)
    try:
        with db.write() as session:
            assert webhooks.delete_webhook(session, demo.webhook_id) is not None
    finally:
        db.dispose()
    return create_api_key(url, "admin", "readme-test state")


def _demo_state(directory: Path, paths: list[str]) -> dict[str, object]:
    """The answers read into ``directory`` (``condition/lines``: the demo's lines only)."""
    out: dict[str, object] = {}
    for i, path in enumerate(paths):
        body = json.loads((directory / f"{i}.json").read_text())
        if path.startswith("/api/v1/condition/lines"):
            body = [item for item in body["items"] if item["line_id"] in ("SIM", "SIM-B")]
        out[path] = body
    return out


def test_readme_commands_run_verbatim(tmp_path, processed_demo):
    isolation = _isolation()
    if isolation is None and not _port_8000_free():
        pytest.skip("port 8000 is in use and no private network namespace can be made (needs root and unshare)")
    project = tmp_path / "project"
    project.mkdir()
    (project / ".venv").symlink_to(ROOT / ".venv")
    key = _demo_in(project / "var", processed_demo)
    logs = tmp_path / "logs"
    logs.mkdir()
    paths = [p.format(first=processed_demo.run_ids[0]) for p in DEMO_STATE]
    script = tmp_path / "readme.sh"
    script.write_text(readme_script(all_blocks(), logs, state=(tmp_path / "state", paths)))
    env = {k: v for k, v in os.environ.items() if not k.startswith(("TRACKVKF_", "VIRTUAL_ENV"))}
    env["PATH"] = re.sub(r"[^:]*\.venv/bin:?", "", env.get("PATH", "")) or "/usr/bin:/bin"
    env[STATE_KEY] = key
    done = subprocess.run([*(isolation or []), "bash", str(script)], cwd=project, env=env,
                          capture_output=True, text=True, timeout=840)
    background = "\n".join(f"--- {p.name}\n{p.read_text()[-3000:]}" for p in sorted(logs.iterdir()))
    assert done.returncode == 0, f"{done.stderr[-4000:]}\n--- stdout\n{done.stdout[-3000:]}\n{background}"
    assert '"status":"done"' in done.stdout or "done" in done.stdout
    # what the README promised happened: the run, its reference data, the analyses, the CLI output
    assert '"slope"' in done.stdout and '"mass_kg"' in done.stdout and '"shift_confidence":1.0' in done.stdout
    assert (project / "var" / "cli-out" / "profiles.parquet").is_file()
    # the demo is as it was, and the docs' run is on its own line
    before, after = _demo_state(tmp_path / "state" / "before", paths), _demo_state(tmp_path / "state" / "after", paths)
    demo_runs = [r["id"] for path in paths[:2] for r in before[path]["items"]]
    assert sorted(demo_runs) == sorted(processed_demo.run_ids), demo_runs
    for path in paths:
        assert after[path] == before[path], f"the docs changed the demo: GET {path}"
    docs_run = json.loads((project / "var" / "docs-run.json").read_text())
    assert docs_run["line_id"] == "DOCS" and docs_run["id"] not in processed_demo.run_ids, docs_run
