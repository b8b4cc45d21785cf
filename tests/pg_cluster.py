"""A throw-away PostgreSQL cluster for tests and benchmarks (no Docker).

:class:`PgCluster` finds the Debian server binaries (``/usr/lib/postgresql/*/bin``),
installs the ``postgresql`` package with ``apt-get`` when they are missing and
the process runs as root, initialises a cluster in a fresh temporary
directory, starts it on ``127.0.0.1`` on a free port (Unix socket in the same
directory, no TCP on other interfaces) and removes everything on
:meth:`PgCluster.destroy`. PostgreSQL refuses to run as root: as root the
server runs as the ``postgres`` system user (created by the package) or, if
absent, a ``trackvkf-pg`` user created for the purpose.

Command line (used by ``scripts/postgres.sh``)::

    python -m tests.pg_cluster start DIR   # prints the SQLAlchemy URL
    python -m tests.pg_cluster stop DIR
"""

from __future__ import annotations

import glob
import os
import pwd
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

__all__ = ["PgCluster", "PgUnavailable", "find_bindir", "ensure_installed"]

DB_NAME = "trackvkf"
DB_USER = "trackvkf"
DB_PASSWORD = "trackvkf"


class PgUnavailable(RuntimeError):
    """The PostgreSQL server cannot be found or installed here (message says why)."""


def find_bindir() -> Path | None:
    """Directory of the newest installed server binaries, or None."""
    dirs = sorted(
        (Path(p) for p in glob.glob("/usr/lib/postgresql/*/bin") if Path(p, "initdb").is_file()),
        key=lambda p: int(p.parent.name) if p.parent.name.isdigit() else 0,
    )
    return dirs[-1] if dirs else None


def ensure_installed() -> Path:
    """Server binaries' directory; installs Debian ``postgresql`` with apt-get if needed.

    Raises
    ------
    PgUnavailable
        If the binaries are missing and cannot be installed (not root, no apt-get,
        or the installation failed).
    """
    from tests.system_packages import AptUnavailable, apt_install

    try:
        apt_install(["postgresql"], installed=lambda: find_bindir() is not None)
    except AptUnavailable as exc:
        raise PgUnavailable(str(exc)) from None
    bindir = find_bindir()
    assert bindir is not None  # apt_install checked it
    return bindir


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def _server_user() -> str | None:
    """User the server runs as: None (ourselves) unless we are root."""
    if os.geteuid() != 0:
        return None
    for name in ("postgres", "trackvkf-pg"):
        try:
            pwd.getpwnam(name)
            return name
        except KeyError:
            continue
    subprocess.run(["useradd", "--system", "--no-create-home", "trackvkf-pg"], check=True)
    return "trackvkf-pg"


class PgCluster:
    """A PostgreSQL cluster in a temporary directory on 127.0.0.1.

    Parameters
    ----------
    base_dir : Path, optional
        Directory to create the cluster in (default: a new ``/tmp`` directory,
        removed by :meth:`destroy`).
    port : int, optional
        TCP port on 127.0.0.1 (default: a free one).
    """

    def __init__(self, base_dir: Path | None = None, port: int | None = None) -> None:
        self.bindir = ensure_installed()
        self.user = _server_user()
        self._own_dir = base_dir is None
        self.base = Path(base_dir or tempfile.mkdtemp(prefix="trackvkf-pg-"))
        self.base.mkdir(parents=True, exist_ok=True)
        self.data = self.base / "data"
        self.port = port or _free_port()
        self.log = self.base / "server.log"

    # --- helpers -------------------------------------------------------------
    def _run(self, *args: str, check: bool = True, timeout: float = 120) -> subprocess.CompletedProcess:
        cmd = [str(self.bindir / args[0]), *args[1:]]
        if self.user is not None:
            cmd = ["runuser", "-u", self.user, "--", *cmd]
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=self.base)
        if check and proc.returncode != 0:
            raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode}):\n{proc.stdout}\n{proc.stderr}")
        return proc

    @property
    def url(self) -> str:
        """SQLAlchemy URL (psycopg 3 driver) of the test database."""
        return f"postgresql+psycopg://{DB_USER}:{DB_PASSWORD}@127.0.0.1:{self.port}/{DB_NAME}"

    # --- life cycle ----------------------------------------------------------
    def init(self) -> PgCluster:
        """Initialise the cluster, start it and create the role and database."""
        os.chmod(self.base, 0o755)
        if self.user is not None:
            shutil.chown(self.base, self.user)
        pwfile = self.base / "pw"
        pwfile.write_text(DB_PASSWORD + "\n")
        if self.user is not None:
            shutil.chown(pwfile, self.user)
        self._run("initdb", "-D", str(self.data), "-U", DB_USER, "--pwfile", str(pwfile),
                  "-A", "scram-sha-256", "-E", "UTF8", "--no-sync")
        pwfile.unlink()
        with open(self.data / "postgresql.conf", "a") as fh:
            fh.write(
                "\n# trackvkf test cluster\n"
                "listen_addresses = '127.0.0.1'\n"
                f"port = {self.port}\n"
                f"unix_socket_directories = '{self.base}'\n"
                "fsync = off\nsynchronous_commit = off\nfull_page_writes = off\n"
                "max_connections = 200\n"
            )
        self.start()
        env = dict(os.environ, PGPASSWORD=DB_PASSWORD)
        subprocess.run(
            [str(self.bindir / "createdb"), "-h", "127.0.0.1", "-p", str(self.port), "-U", DB_USER, DB_NAME],
            check=True, env=env, capture_output=True, timeout=60,
        )
        return self

    def create_database(self) -> str:
        """Create a new empty database in the cluster; returns its SQLAlchemy URL."""
        self._n_databases = getattr(self, "_n_databases", 0) + 1
        name = f"db_{os.getpid()}_{self._n_databases}"
        env = dict(os.environ, PGPASSWORD=DB_PASSWORD)
        subprocess.run(
            [str(self.bindir / "createdb"), "-h", "127.0.0.1", "-p", str(self.port), "-U", DB_USER, name],
            check=True, env=env, capture_output=True, timeout=60,
        )
        return self.url.rsplit("/", 1)[0] + "/" + name

    def start(self) -> None:
        """Start the server and wait until it accepts connections."""
        self._run("pg_ctl", "-D", str(self.data), "-l", str(self.log), "-w", "-t", "60", "start")

    def stop(self, mode: str = "fast") -> None:
        """Stop the server (``fast`` disconnects clients; ``immediate`` is a crash)."""
        self._run("pg_ctl", "-D", str(self.data), "-m", mode, "-w", "-t", "60", "stop", check=False)

    def restart(self, down_s: float = 0.0) -> None:
        """Stop the server (fast), stay down ``down_s`` seconds, start it again."""
        self.stop("fast")
        time.sleep(down_s)
        self.start()

    def destroy(self) -> None:
        """Stop the server and remove the cluster directory."""
        if self.data.is_dir():
            self.stop("immediate")
        if self._own_dir:
            shutil.rmtree(self.base, ignore_errors=True)


def main(argv: list[str]) -> int:
    """``start DIR`` (prints the URL) / ``stop DIR`` / ``url DIR``."""
    if len(argv) != 2 or argv[0] not in ("start", "stop", "url"):
        print("usage: python -m tests.pg_cluster start|stop|url DIR", file=sys.stderr)
        return 2
    base = Path(argv[1]).resolve()
    port_file = base / "port"
    if argv[0] == "start":
        if (base / "data").is_dir():
            cluster = PgCluster(base, int(port_file.read_text()))
            cluster.start()
        else:
            cluster = PgCluster(base)
            cluster.init()
            port_file.write_text(str(cluster.port))
        print(cluster.url)
        return 0
    if not port_file.is_file():
        print(f"no cluster in {base}", file=sys.stderr)
        return 1
    cluster = PgCluster(base, int(port_file.read_text()))
    if argv[0] == "stop":
        cluster.stop()
    else:
        print(cluster.url)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
