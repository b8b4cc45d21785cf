"""Data sets of the tests built once and kept on disk (the ``datasets`` fixture of tests/conftest.py).

A data set is whatever a build function makes in a directory of its own (a simulated run file, the
pipeline's results, a processed database with its run store) plus the value it returns (pickled next
to the files). :meth:`DatasetCache.get` builds it the first time a session asks for it and reads it
back every later time, in this session and in later ones, until its key changes. The key is

- the data set's **kind** and **spec** (the simulation's and the processing's parameters, as JSON),
- the build function's name and the **source of its module** (a test module whose fixture builds
  differently, or whose constants changed, makes another data set),
- the **code digest** (:func:`code_digest`): the pipeline's engine version, the processing settings'
  defaults, every source file of ``app/``, ``worker/``, ``migrations/`` and the tests' helper modules
  (``conftest.py``, ``support.py`` …, not the ``test_*.py`` modules), and the versions of Python,
  numpy, scipy, pandas and numba.

So a change to the numerics, the simulator, the schema or a helper invalidates every data set (the
cache of the previous digest is deleted when a session opens the new one); a change to a test module
alone does not. The value read back is exactly what the real build produced (the same pickled
objects, the same files): the cache saves the time, never the computation's checks.

Where it lives: ``.pytest_cache/d/trackvkf-datasets`` (``pytest --cache-clear`` empties it), or the
directory of ``TRACKVKF_TEST_DATASETS``; ``TRACKVKF_TEST_DATASETS=session`` (and ``-p
no:cacheprovider``) keeps it in the session's temporary directory: built once per session, then
gone. CI starts from a clean clone, so its first use of each data set pays once.

Builds are serialised per data set with a file lock, so two sessions (or test processes) on one
cache build each data set once; a build that fails leaves nothing behind.
"""

from __future__ import annotations

import fcntl
import hashlib
import inspect
import json
import os
import pickle
import platform
import shutil
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from functools import lru_cache
from pathlib import Path
from typing import Any, TypeVar

__all__ = ["DatasetCache", "code_digest", "DATASETS_ENV", "copy_dataset"]

T = TypeVar("T")

#: environment variable: the cache directory, or ``session`` for a per-session one
DATASETS_ENV = "TRACKVKF_TEST_DATASETS"
ROOT = Path(__file__).resolve().parent.parent
#: the source trees whose every change invalidates the cached data sets
_SOURCE_TREES = ("app", "worker", "migrations")
_VALUE = "value.pkl"


def _spec_json(spec: Mapping[str, Any]) -> str:
    return json.dumps(spec, sort_keys=True, separators=(",", ":"), default=repr)


@lru_cache(maxsize=1)
def code_digest() -> str:
    """sha256 (16 hex digits) of what the data sets depend on besides their specs (module docstring)."""
    import numba
    import numpy
    import pandas
    import scipy

    from app.analysis.settings import ProcessingSettings
    from app.pipeline import ENGINE_VERSION

    h = hashlib.sha256()
    for part in (ENGINE_VERSION, _spec_json(ProcessingSettings().to_dict()), platform.python_version(),
                 numpy.__version__, scipy.__version__, pandas.__version__, numba.__version__):
        h.update(part.encode() + b"\0")
    files = [p for tree in _SOURCE_TREES for p in (ROOT / tree).rglob("*.py")]
    files += [p for p in (ROOT / "tests").rglob("*.py") if not p.name.startswith("test_")]
    for path in sorted(files):
        h.update(str(path.relative_to(ROOT)).encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()[:16]


def _build_source(build: Callable[..., Any]) -> str:
    """The build function's name and its whole module's source (its constants and helpers count)."""
    name = f"{getattr(build, '__module__', '?')}.{getattr(build, '__qualname__', repr(build))}"
    module = inspect.getmodule(build)
    try:
        return name + "\n" + (inspect.getsource(module) if module is not None else inspect.getsource(build))
    except (OSError, TypeError):
        return name


@contextmanager
def _locked(path: Path) -> Iterator[None]:
    with open(path, "a+b") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


class DatasetCache:
    """Data sets built once per key under ``root`` (see the module docstring).

    Parameters
    ----------
    root : Path
        The cache directory; the data sets of the current :func:`code_digest` live in
        ``root/<digest>``, older digests' directories are removed on first use.
    """

    def __init__(self, root: Path) -> None:
        self.root = Path(root)
        self._dir: Path | None = None

    @property
    def directory(self) -> Path:
        """``root/<code digest>``, created (and the other digests' directories removed) on first use."""
        if self._dir is None:
            digest = code_digest()
            self.root.mkdir(parents=True, exist_ok=True)
            with _locked(self.root / ".lock"):
                for old in self.root.iterdir():
                    if old.is_dir() and old.name != digest:
                        shutil.rmtree(old, ignore_errors=True)
                (self.root / digest).mkdir(exist_ok=True)
            self._dir = self.root / digest
        return self._dir

    def key(self, kind: str, spec: Mapping[str, Any], build: Callable[[Path], Any]) -> str:
        """The data set's directory name: ``<kind>-<sha256 of spec and the build's source>``."""
        if not kind or not kind.replace("-", "").replace("_", "").isalnum():
            raise ValueError(f"kind must be a short name of letters, digits, - and _, got {kind!r}")
        blob = _spec_json({"kind": kind, "spec": dict(spec), "build": _build_source(build)})
        return f"{kind}-{hashlib.sha256(blob.encode()).hexdigest()[:16]}"

    def get(self, kind: str, spec: Mapping[str, Any], build: Callable[[Path], T]) -> T:
        """The value of data set ``kind``/``spec``: ``build(directory)`` once, then its pickled value.

        Parameters
        ----------
        kind : str
            A short name (also the directory's prefix).
        spec : mapping
            Everything that decides the data set (JSON-serialisable; objects are keyed by ``repr``).
        build : callable
            ``build(directory) -> value``: makes the data set's files in ``directory`` (which stays
            where it is: paths into it may be part of the value) and returns a picklable value.

        Returns
        -------
        The unpickled value (also on the first call, so a cold and a warm cache give the same).
        """
        name = self.key(kind, spec, build)
        where = self.directory / name
        with _locked(self.directory / f"{name}.lock"):
            done = where / _VALUE
            if not done.is_file():
                shutil.rmtree(where, ignore_errors=True)
                where.mkdir()
                try:
                    value = build(where)
                    tmp = where / f"{_VALUE}.tmp"
                    tmp.write_bytes(pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL))
                    tmp.replace(done)
                except BaseException:
                    shutil.rmtree(where, ignore_errors=True)
                    raise
            return pickle.loads(done.read_bytes())

    def path(self, kind: str, spec: Mapping[str, Any], build: Callable[[Path], Any]) -> Path:
        """The directory of data set ``kind``/``spec`` (built by :meth:`get` when missing)."""
        self.get(kind, spec, build)
        return self.directory / self.key(kind, spec, build)


def copy_dataset(source: Path, target: Path) -> Path:
    """A private, writable copy of a cached data set's files (for tests that change them)."""
    shutil.copytree(source, target, ignore=shutil.ignore_patterns(_VALUE, f"{_VALUE}.tmp"))
    return target


def cache_root(config: Any, session_tmp: Callable[[], Path]) -> Path:
    """Where :class:`DatasetCache` keeps the data sets for a pytest session (module docstring)."""
    env = os.environ.get(DATASETS_ENV, "").strip()
    if env and env != "session":
        return Path(env).expanduser()
    cache = getattr(config, "cache", None)
    if env == "session" or cache is None:
        return session_tmp()
    return Path(cache.mkdir("trackvkf-datasets"))
