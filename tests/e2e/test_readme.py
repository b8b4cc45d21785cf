"""The README's shell commands (and those of the guides it sends a reader to), run verbatim
against a throw-away service.

Blocks preceded by ``<!-- readme-test: run -->`` are run in one bash, in the order of
:data:`DOCS` and of each file (the README first: it starts the service), in
a fresh project directory (the repository's ``.venv`` linked in, the default ``./var``). A line
whose comment says ``(runs until Ctrl-C)`` is started in the background (serve, worker). The
harness adds only what a reader sees anyway: ``curl`` fails on an HTTP error
(``--fail-with-body``), and the first command that fails fails the test, named.

Port 8000, as written in the README: the script runs in a network namespace of its own
(``unshare -n``, root) so that it never meets another service on this machine; without one it
runs only when port 8000 is free.
"""

from __future__ import annotations

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


def readme_script(blocks: list[list[str]], logs: Path) -> str:
    """One bash script running the blocks."""
    out = [
        "set -eEuo pipefail",
        "trap 'echo \"README command failed (exit $?): $BASH_COMMAND\" >&2' ERR",
        "trap 'kill $(jobs -p) 2>/dev/null || true' EXIT",
        "if ip link show lo >/dev/null 2>&1; then ip link set lo up 2>/dev/null || true; fi",
        "curl() { command curl --fail-with-body -sS \"$@\"; echo; }",
    ]
    n = 0
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


def test_readme_commands_run_verbatim(tmp_path):
    isolation = _isolation()
    if isolation is None and not _port_8000_free():
        pytest.skip("port 8000 is in use and no private network namespace can be made (needs root and unshare)")
    project = tmp_path / "project"
    project.mkdir()
    (project / ".venv").symlink_to(ROOT / ".venv")
    logs = tmp_path / "logs"
    logs.mkdir()
    script = tmp_path / "readme.sh"
    script.write_text(readme_script(all_blocks(), logs))
    env = {k: v for k, v in os.environ.items() if not k.startswith(("TRACKVKF_", "VIRTUAL_ENV"))}
    env["PATH"] = re.sub(r"[^:]*\.venv/bin:?", "", env.get("PATH", "")) or "/usr/bin:/bin"
    done = subprocess.run([*(isolation or []), "bash", str(script)], cwd=project, env=env,
                          capture_output=True, text=True, timeout=840)
    background = "\n".join(f"--- {p.name}\n{p.read_text()[-3000:]}" for p in sorted(logs.iterdir()))
    assert done.returncode == 0, f"{done.stderr[-4000:]}\n--- stdout\n{done.stdout[-3000:]}\n{background}"
    assert '"status":"done"' in done.stdout or "done" in done.stdout
    # what the README promised happened: the run, its reference data, the analyses, the CLI output
    assert '"slope"' in done.stdout and '"mass_kg"' in done.stdout and '"shift_confidence":1.0' in done.stdout
    assert (project / "var" / "cli-out" / "profiles.parquet").is_file()
