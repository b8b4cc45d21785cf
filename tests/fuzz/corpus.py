"""The fuzz corpora: valid base files written here, their mutants, and the oracle.

Oracle, per mutant (recorder and run files):

* never an exception other than :class:`RunFileError` (a 5xx), a hang past
  the per-file limit or a crash;
* refused (4xx naming its field), or accepted with exactly the data of its
  base file, or — only when every changed byte is a value byte
  (:mod:`tests.fuzz.mutations`) — accepted with other data.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

from tests.fuzz import mutations as mu
from tests.fuzz.harness import Outcome, ingest_digest, run_corpus
from tests.io import recorder_bytes as rb
from tests.io.conftest import base_meta

__all__ = ["PER_FILE_S", "FORMATS", "Result", "run"]

#: Time limit per file, s (a valid small file ingests in well under 0.5 s).
PER_FILE_S = 10.0
FORMATS = ("mdf4", "tdms", "hdf5", "geojson")
SEED = 24


@dataclass
class Result:
    mutants: list[mu.Mutant]
    outcomes: list[tuple[mu.Mutant, Outcome]]
    base_digests: dict[str, str]
    seconds: float

    def failures(self) -> list[tuple[mu.Mutant, Outcome, str]]:
        out = []
        for m, o in self.outcomes:
            base = self.base_digests[m.name.split("/")[0]]
            if o.kind in ("hang", "crash", "error"):
                out.append((m, o, o.kind))
            elif o.kind == "refused" and not o.detail.split(":")[0].strip():
                out.append((m, o, "refused without a field"))
            elif o.kind == "accepted" and o.detail != base and not m.value_only:
                out.append((m, o, "accepted with other data after a structural change"))
        return out


def _recorder_digest(src: Path) -> str:
    return ingest_digest(src, src.with_suffix(".out.h5"), base_meta(), channel_map=rb.CHANNEL_MAP)


#: HDF5 is parsed by libhdf5 (C): a flipped byte can keep it busy for long (measured: > 10 s
#: reading an attribute). Only the watchdog bounds that: an HDF5 mutant that hangs or crashes
#: in-process is parsed again through the production path, a child process with this budget,
#: which must refuse it (4xx).
HDF5_BUDGET_S = 3.0
#: In-process time limit per HDF5 file before it is handed to the watchdog, s.
HDF5_IN_PROCESS_S = 2.0


def _run_digest(src: Path) -> str:
    return ingest_digest(src, src.with_suffix(".out.h5"), base_meta())


def _run_digest_bounded(src: Path) -> str:
    from app.io.isolation import ParseBudget, ingest_bounded

    budget = ParseBudget(HDF5_BUDGET_S, 2 << 30)
    return ingest_digest(src, src.with_suffix(".out.h5"), base_meta(),
                         ingest_fn=lambda *a, **k: ingest_bounded(*a, budget=budget, **k))


def _run_bounded_corpus(parse: Callable[[Path], str], files: list[Path]) -> list[Outcome]:
    """Each file through the production watchdog (a child process per file), from here."""
    from app.io.errors import RunFileError
    from app.io.isolation import ParseBudgetExceeded

    out = []
    for path in files:
        t0 = time.perf_counter()
        try:
            kind, detail = "accepted", parse(path)
        except ParseBudgetExceeded as exc:
            kind, detail = "refused", f"{exc.field}: {exc.message} [watchdog]"
        except RunFileError as exc:
            kind, detail = "refused", f"{exc.field}: {exc.message}"
        except Exception as exc:  # noqa: BLE001 - reported by the oracle
            kind, detail = "error", repr(exc)
        out.append(Outcome(kind, detail, time.perf_counter() - t0))
    return out


def _mdf4(tmp: Path, rng: np.random.Generator) -> Iterator[tuple[str, bytes, Iterator[mu.Mutant]]]:
    for tag, kwargs in (("mdf4-plain", {}), ("mdf4-deflate-dl", {"compression": 1, "fragment": 4096}),
                        ("mdf4-transposed", {"compression": 2}), ("mdf4-rich", {"rich": True})):
        base = rb.write_mdf4(tmp / f"{tag}.mf4", **kwargs).read_bytes()
        yield tag, base, mu.mdf4_mutants(tag, base, rng)


def _tdms(tmp: Path, rng: np.random.Generator) -> Iterator[tuple[str, bytes, Iterator[mu.Mutant]]]:
    for tag, segments in (("tdms-2seg", 2), ("tdms-8seg", 8)):
        base = rb.write_tdms(tmp / f"{tag}.tdms", segments=segments).read_bytes()
        yield tag, base, mu.tdms_mutants(tag, base, rng)


def _hdf5(tmp: Path, rng: np.random.Generator) -> Iterator[tuple[str, bytes, Iterator[mu.Mutant]]]:
    import h5py

    s = rb.signals()
    meta = json.dumps(base_meta()).encode()
    speed = np.interp(s["t"], s["t2"], s["v_train"] / 3.6)
    for tag, kwargs in (("hdf5-contiguous", {}), ("hdf5-gzip", {"chunks": (1000,), "compression": "gzip"})):
        path = tmp / f"{tag}.h5"
        with h5py.File(path, "w") as h5:
            for name, x in (("Z11", s["AccZ_1R"] * 9.80665), ("Z12", s["AccZ_1L"]), ("speed", speed)):
                h5.create_dataset(name, data=np.asarray(x, np.float32), **kwargs)
                h5[name].attrs["units"] = "m/s^2" if name != "speed" else "m/s"
            h5.attrs["sample_rate_hz"] = rb.FS
        raw: list[tuple[int, int]] = []
        with h5py.File(path, "r") as h5:
            for name in ("Z11", "Z12", "speed"):
                ds = h5[name]
                if ds.chunks is None:
                    raw.append((int(ds.id.get_offset()), int(ds.id.get_storage_size())))
                else:
                    for k in range(ds.id.get_num_chunks()):
                        info = ds.id.get_chunk_info(k)
                        raw.append((int(info.byte_offset), int(info.size)))
        base = path.read_bytes()
        texts = [b"m/s^2", b"m/s", np.float64(rb.FS).tobytes(), meta]
        values = mu.hdf5_values(base, raw, texts)
        yield tag, base, mu.hdf5_mutants(tag, base, values, rng)


def _geojson(tmp: Path, rng: np.random.Generator) -> Iterator[tuple[str, bytes, Iterator[mu.Mutant]]]:
    muts = list(mu.geojson_mutants(rng))
    base = muts[0][1]
    # any accepted geometry is fine if it is sound (checked by the digest): "value-only"
    yield "geojson", base, (mu.Mutant(name, data, True) for name, data in muts[1:])


def _geojson_digest(src: Path) -> str:
    """Parse a GeoJSON file; an accepted geometry must be sound (else an AssertionError: "error")."""
    import hashlib

    from app.io.geometry import KM_LENGTH_TOLERANCE, parse_geojson

    lines = parse_geojson(src.read_bytes())
    h = hashlib.sha256()
    assert lines, "no geometry"
    for g in lines:
        assert g.line_id.strip() and "\x00" not in g.line_id and "\x00" not in g.track
        assert g.lon.shape == g.lat.shape == g.km.shape and g.km.size >= 2
        assert np.isfinite(g.lon).all() and np.isfinite(g.lat).all() and np.isfinite(g.km).all()
        assert (np.abs(g.lon) <= 180).all() and (np.abs(g.lat) <= 90).all()
        dk = np.diff(g.km)
        assert (dk > 0).all() or (dk < 0).all()
        span = abs(float(g.km[-1] - g.km[0])) * 1000
        assert abs(span - g.length_m) <= KM_LENGTH_TOLERANCE * g.length_m * 1.001
        for a in (g.lon, g.lat, g.km):
            h.update(a.tobytes())
    return h.hexdigest()


_BUILDERS: dict[str, tuple[Callable, Callable[[Path], str], str]] = {
    "mdf4": (_mdf4, _recorder_digest, ".mf4"),
    "tdms": (_tdms, _recorder_digest, ".tdms"),
    "hdf5": (_hdf5, _run_digest, ".h5"),
    "geojson": (_geojson, _geojson_digest, ".geojson"),
}


def build(fmt: str, tmp: Path) -> tuple[list[mu.Mutant], dict[str, str], list[Path], Callable[[Path], str]]:
    """Write the base files and mutants of ``fmt`` under ``tmp``."""
    builder, digest, suffix = _BUILDERS[fmt]
    rng = np.random.default_rng(SEED)
    mutants: list[mu.Mutant] = []
    bases: dict[str, str] = {}
    for tag, base, muts in builder(tmp, rng):
        base_path = tmp / f"{tag}.base{suffix}"
        base_path.write_bytes(base)
        bases[tag] = digest(base_path)
        mutants.extend(muts)
    files = []
    for k, m in enumerate(mutants):
        path = tmp / f"m{k:04d}{suffix}"
        path.write_bytes(m.data)
        files.append(path)
    return mutants, bases, files, digest


def run(fmt: str, tmp: Path, per_file_s: float = PER_FILE_S) -> Result:
    """Build and parse the corpus of ``fmt``; see :class:`Result` for the oracle."""
    mutants, bases, files, digest = build(fmt, tmp)
    t0 = time.perf_counter()
    if fmt == "hdf5":
        outcomes = run_corpus(partial(digest), files, min(per_file_s, HDF5_IN_PROCESS_S))
        for k, o in enumerate(outcomes):
            if o.kind in ("hang", "crash"):
                outcomes[k] = _run_bounded_corpus(_run_digest_bounded, [files[k]])[0]
    else:
        outcomes = run_corpus(partial(digest), files, per_file_s)
    return Result(mutants, list(zip(mutants, outcomes, strict=True)), bases, time.perf_counter() - t0)
