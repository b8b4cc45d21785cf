"""Debian packages the tests install for themselves (PostgreSQL, Chromium), one installer at a time.

On a fresh machine several test processes (pytest-xdist) ask for their package at once: apt-get holds
its lists and dpkg locks and refuses a second apt-get ("Could not get lock /var/lib/apt/lists/lock").
:func:`apt_install` takes an exclusive lock on a file beside them first (``fcntl.flock``: released
when the process ends, whatever happens), rechecks under it whether another process has installed what
is asked meanwhile, and gives apt-get a wait on dpkg's own lock for an installer outside the tests.
"""

from __future__ import annotations

import fcntl
import os
import shutil
import subprocess
from collections.abc import Callable, Sequence
from pathlib import Path

#: the file the test processes' installers lock (one machine, any checkout)
LOCK_FILE = Path("/tmp/trackvkf-apt.lock")
#: how long an apt-get waits for dpkg's lock held by another installer, s
DPKG_LOCK_WAIT_S = 600


class AptUnavailable(RuntimeError):
    """The packages are missing and cannot be installed here (not root, no apt-get, or apt-get failed)."""


def apt_install(packages: Sequence[str], *, installed: Callable[[], bool], timeout_s: float = 900) -> None:
    """Install Debian ``packages`` with apt-get unless ``installed()`` says they are there.

    Parameters
    ----------
    packages : sequence of str
        Debian package names.
    installed : callable
        Whether what the caller needs is present (checked before and again under the lock).
    timeout_s : float
        Limit of each apt-get command, s.

    Raises
    ------
    AptUnavailable
        With the reason (the apt-get's own output where it failed).
    """
    if not packages:
        raise ValueError("packages: name at least one")
    if installed():
        return
    if os.geteuid() != 0 or shutil.which("apt-get") is None:
        raise AptUnavailable(f"{' '.join(packages)} missing and apt-get unusable here (needs root and apt-get)")
    env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
    wait = ["-o", f"DPkg::Lock::Timeout={DPKG_LOCK_WAIT_S}"]
    with open(LOCK_FILE, "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # blocks while another test process installs
        if installed():
            return
        for cmd in (["apt-get", *wait, "update", "-qq"],
                    ["apt-get", *wait, "install", "-y", "-qq", "--no-install-recommends", *packages]):
            done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout_s)
            if done.returncode != 0:
                raise AptUnavailable(f"{' '.join(cmd)} failed:\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}")
    if not installed():
        raise AptUnavailable(f"apt-get installed {' '.join(packages)} but what they provide is still missing")
