"""The run-file layer's error texts reach a reader in their language, with the field or channel named.

A sample of one rejection per module of app/io (the recorder formats, geometry, plausibility,
canonical, ingest, positioning, run file, reference, limits, metadata, channel map), each made
from a bad input, read in German and in French or Italian; two cross the parse child (the
isolation of uploads). Plus a static check: no message of ``RunFileError`` (or of a helper that
makes one, or a validator's ``ValueError``) in app/io is an English literal the catalogues never
see, so a new one cannot slip in.
"""

from __future__ import annotations

import ast
import io
import json
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import pytest

from app.core.i18n import Msg
from app.io import IngestLimits, RunFileError, ingest
from app.io.canonical import write_run_hdf5
from app.io.channel_map import parse_channel_map
from app.io.detect import resolve_format
from app.io.geometry import parse_geojson
from app.io.isolation import ParseBudget, parse_geojson_bounded, read_reference_bounded
from app.io.metadata import parse_metadata
from app.io.plausibility import check_sample_rate
from app.io.reference import read_reference
from app.io.runfile import open_run
from tests.io.conftest import base_meta, kinematic_arrays

ROOT = Path(__file__).resolve().parents[2]
N = 4000
META = base_meta(sample_rate_hz=2000)
BUDGET = ParseBudget(seconds=60.0, memory_bytes=4 << 30)


def _csv(tmp: Path, data: dict, name: str = "r.csv") -> Path:
    pd.DataFrame(data).to_csv(tmp / name, index=False)
    return tmp / name


def _good() -> dict:
    a = kinematic_arrays(N)
    return {"Z11": a["Z11"], "speed": a["speed"], "position": a["position"]}


def _ingest(tmp: Path, src: Path, meta: dict | None = META, fmt: str | None = None, **kw) -> None:
    ingest(src, fmt, meta, tmp / "out.h5", **kw)


def _feature(**props) -> dict:
    return {"type": "Feature", "properties": {"line_id": "L1", "track": "1", **props},
            "geometry": {"type": "LineString", "coordinates": [[7.0, 46.0], [7.001, 46.0], [7.002, 46.0]]}}


def _not_a_run_file(tmp: Path) -> None:
    with h5py.File(tmp / "x.h5", "w") as h5:
        h5["Z11"] = np.zeros(10)
    open_run(tmp / "x.h5")


def _parquet_cut(tmp: Path) -> None:
    buf = io.BytesIO()
    pd.DataFrame(_good()).to_parquet(buf)
    (tmp / "r.parquet").write_bytes(buf.getvalue()[:-40] + b"PAR1")
    _ingest(tmp, tmp / "r.parquet")


def _hdf5_text_channel(tmp: Path) -> None:
    with h5py.File(tmp / "r.h5", "w") as h5:
        for k, v in _good().items():
            h5[k] = v
        h5["Z42"] = np.array([b"x"] * N)
    _ingest(tmp, tmp / "r.h5")


#: id, make the rejection (tmp → raises), field, {language: words of the translation}
Case = tuple[str, Callable[[Path], object], str, dict[str, str]]
CASES: list[Case] = [
    ("detect", lambda t: resolve_format(_csv(t, _good()), "hdf5"), "format",
     {"de": "Format 'hdf5' angegeben, aber die Datei hat keine HDF5-Signatur",
      "fr": "format 'hdf5' déclaré mais le fichier n'a pas de signature HDF5"}),
    ("csv", lambda t: _ingest(t, _csv(t, {**_good(), "Z11": ["1.5"] * (N - 1) + ["abc"]})), "Z11",
     {"de": "falscher dtype: nicht numerischer Wert 'abc' in Datenzeile 4000",
      "it": "dtype errato: valore non numerico 'abc' nella riga di dati 4000"}),
    ("hdf5", _hdf5_text_channel, "Z42",
     {"de": "falscher dtype |S1: Kanäle müssen numerisch sein", "fr": "dtype |S1 incorrect : les canaux doivent"}),
    ("parquet", _parquet_cut, "file",
     {"de": "Bytes passt nicht in die Datei (abgeschnitten?)", "it": "non sta nel file (troncato?)"}),
    ("ingest-empty", lambda t: _ingest(t, (t / "r.csv").write_bytes(b"") or t / "r.csv"), "file",
     {"de": "Datei ist leer", "fr": "le fichier est vide"}),
    ("plausibility-channels", lambda t: _ingest(t, _csv(t, {"Z11": _good()["Z11"]})), "speed",
     {"de": "fehlender Kanal: speed oder position ist erforderlich",
      "it": "canale mancante: è richiesto speed o position"}),
    ("plausibility-rate", lambda t: check_sample_rate(3.0, IngestLimits()), "sample_rate_hz",
     {"de": "ungültige Abtastrate 3 Hz; zulässig", "fr": "fréquence d'échantillonnage non valide 3 Hz"}),
    ("plausibility-speed", lambda t: _ingest(t, _csv(t, {**_good(), "speed": _good()["speed"] * 3.6 + 100})), "speed",
     {"de": "speed muss in m/s angegeben sein (nicht km/h)", "fr": "speed doit être donnée en m/s (pas en km/h)"}),
    ("positioning", lambda t: _ingest(t, _csv(t, _good()), base_meta(sample_rate_hz=2000, position_kind="line_km")),
     "km_start",
     {"de": "bei position_kind line_km nicht anzugeben: der km kommt aus dem Positionskanal",
      "fr": "à ne pas indiquer avec position_kind line_km : le km provient du canal de position"}),
    ("metadata-validator", lambda t: parse_metadata(base_meta(wheel_diameters={"11": 3.0})), "wheel_diameters",
     {"de": "Durchmesser von Rad 11 muss in (0.3, 1.5) m liegen, erhalten: 3.0",
      "it": "il diametro della ruota 11 deve essere in (0.3, 1.5) m, ricevuto: 3.0"}),
    ("metadata-missing", lambda t: parse_metadata({k: v for k, v in base_meta().items() if k != "line_id"}),
     "line_id", {"de": "Pflichtfeld fehlt", "fr": "champ obligatoire manquant"}),
    ("channel-map", lambda t: parse_channel_map({"channels": {"Z11": "A", "z11": "B"}}), "channel_map.channels",
     {"de": "Kanal Z11 doppelt angegeben", "it": "canale Z11 indicato due volte"}),
    ("canonical", lambda t: write_run_hdf5(t / "c.h5", {"Z11": np.zeros(10)}, -1.0, base_meta()), "sample_rate_hz",
     {"de": "Abtastrate muss > 0 Hz sein, erhalten: -1.0",
      "fr": "la fréquence d'échantillonnage doit être > 0 Hz, reçu : -1.0"}),
    ("runfile", _not_a_run_file, "format",
     {"de": "keine trackvkf-Messfahrtdatei (kein trackvkf_format_version)",
      "it": "non è un file di corsa trackvkf (manca trackvkf_format_version)"}),
    ("limits", lambda t: IngestLimits().check_decoded(10**12, 1000, Msg("the MDF data")), "file",
     {"de": "die MDF-Daten ergeben entpackt 1000000000000 Bytes",
      "fr": "les données MDF se décodent en 1000000000000 octets"}),
    ("geometry", lambda t: parse_geojson({"type": "FeatureCollection", "features": [_feature()]}), "features[0]",
     {"de": "(Strecke L1 Gleis 1) hat keine km-Stationen: properties.km angeben",
      "fr": "(ligne L1 voie 1) n'a pas de stations kilométriques : indiquez properties.km"}),
    ("reference", lambda t: read_reference(b"line_id,track,km_from,km_to,type,date\nL1,1,1.0,1.2,tamping,2024-31-12\n",
                                           "maintenance", "csv"), "row 1, column date",
     {"de": "'2024-31-12' ist kein ISO-Datum (JJJJ-MM-TT)", "it": "'2024-31-12' non è una data ISO (aaaa-mm-gg)"}),
]


@pytest.mark.parametrize(("make", "field", "words"), [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_a_rejection_reads_in_the_users_language(tmp_path: Path, make, field, words) -> None:
    """The message is kept for translation: German and French or Italian, the field unchanged and
    named in the answer's detail (``<field>: <message>``), never the English text."""
    with pytest.raises(RunFileError) as exc:
        make(tmp_path)
    err = exc.value
    assert err.field == field, str(err)
    assert isinstance(err.message, Msg), f"not marked for translation: {err.message!r}"
    for lang, text in words.items():
        shown = err.message.in_language(lang)
        assert text in shown, (lang, shown)
        assert shown != str(err.message), (lang, shown)


def test_rejections_cross_the_parse_child_translatable() -> None:
    """An upload is parsed in a child process: its error comes back with the message to translate,
    and the name of the file's kind in the user's language too."""
    with pytest.raises(RunFileError) as exc:
        read_reference_bounded(b"line_id,track,km_from,km_to,type\nL1,1,1.5,1.2,tamping\n", "superstructure",
                               "csv", None, budget=BUDGET)
    assert exc.value.field == "row 1, column km_to"
    assert exc.value.message.in_language("de") == "1.2 liegt unter km_from 1.5"
    assert exc.value.message.in_language("fr") == "1.2 est inférieur à km_from 1.5"
    with pytest.raises(RunFileError) as exc:
        parse_geojson_bounded(json.dumps({"type": "FeatureCollection", "features": []}).encode(), budget=BUDGET)
    assert exc.value.field == "file" and exc.value.message.in_language("it") == "nessuna feature"


def test_ingest_warnings_are_marked_for_translation(tmp_path: Path) -> None:
    """The ingest report's warnings (shown on the run's page) are kept for translation too."""
    summary = ingest(_csv(tmp_path, _good()), None, {k: v for k, v in META.items()}, tmp_path / "out.h5")
    axles = [w for w in summary.warnings if w.startswith("axle_positions: not given")]
    assert axles and isinstance(axles[0], Msg)
    assert axles[0].in_language("de").startswith("axle_positions: nicht angegeben; die Standardanordnung")


# -- static: every message of the run-file layer goes through the catalogues ---------------------

#: calls whose argument at this index is a message a client reads
_MESSAGE_ARG = {"RunFileError": 1, "ParseBudgetExceeded": 1, "_fail": -1, "ValueError": 0}
_MARKERS = {"_", "ngettext", "Msg"}


def _name(func: ast.expr) -> str | None:
    return func.id if isinstance(func, ast.Name) else func.attr if isinstance(func, ast.Attribute) else None


def _is_text(node: ast.expr) -> bool:
    """An English literal: a string, an f-string, or text joined with ``+`` / chosen with ``if``."""
    if isinstance(node, ast.Constant):
        return isinstance(node.value, str)
    if isinstance(node, ast.JoinedStr):
        return True
    if isinstance(node, ast.BinOp):
        return _is_text(node.left) or _is_text(node.right)
    if isinstance(node, ast.IfExp):
        return _is_text(node.body) or _is_text(node.orelse)
    return False


def _validators(tree: ast.Module) -> set[int]:
    """The ids of the functions pydantic calls (``@field_validator``/``@model_validator``)."""
    return {id(f) for f in ast.walk(tree) if isinstance(f, ast.FunctionDef)
            and any(_name(d.func if isinstance(d, ast.Call) else d) in ("field_validator", "model_validator")
                    for d in f.decorator_list)}


def unmarked_messages(root: Path) -> list[str]:
    """``file:line: text`` of each error message (or ingest warning) of ``root`` that is not marked."""
    found = []
    for path in sorted(root.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        validators = _validators(tree)
        in_validator = {id(n) for f in ast.walk(tree) if id(f) in validators for n in ast.walk(f)}
        for node in ast.walk(tree):
            if not isinstance(node, ast.Call):
                continue
            name = _name(node.func)
            if name == "append" and isinstance(node.func, ast.Attribute) and _name(node.func.value) == "warnings":
                index = 0
            elif name in _MESSAGE_ARG and (name != "ValueError" or id(node) in in_validator):
                index = _MESSAGE_ARG[name]
            else:
                continue
            if not node.args or (index >= 0 and len(node.args) <= index):
                continue
            message = node.args[index]
            if _is_text(message):
                found.append(f"{path.relative_to(root.parents[1])}:{node.lineno}: {ast.unparse(message)[:100]}")
    return found


def test_every_error_message_of_the_run_file_layer_is_marked() -> None:
    """An English literal as the message of a RunFileError, of a helper making one (``_fail``), of
    a pydantic validator's ValueError or as an ingest warning fails here: mark it with ``_()``."""
    assert unmarked_messages(ROOT / "app" / "io") == []


def test_the_scan_finds_an_unmarked_message(tmp_path: Path) -> None:
    """The scan itself: literals, f-strings and joined text are found, marked messages are not."""
    pkg = tmp_path / "app" / "io"
    pkg.mkdir(parents=True)
    (pkg / "m.py").write_text(
        "from pydantic import field_validator\n"
        "def f(x, warnings):\n"
        "    raise RunFileError('file', f'bad {x}')\n"
        "def g():\n"
        "    raise RunFileError('file', 'bad ' + 'file')\n"
        "def h(x):\n"
        "    raise RunFileError('file', _('bad {x}', x=x))\n"
        "def k(warnings):\n"
        "    warnings.append('a warning')\n"
        "    raise _fail(1, 'col', 'is empty')\n"
        "class M:\n"
        "    @field_validator('a')\n"
        "    def v(cls, a):\n"
        "        raise ValueError('must be positive')\n"
        "def internal():\n"
        "    raise ValueError('a programming error')\n",
        encoding="utf-8",
    )
    found = unmarked_messages(pkg)
    assert [f.split(":")[1] for f in found] == ["3", "5", "9", "10", "14"], found


# -- over HTTP: an upload's rejection and its warnings in the reader's language ------------------

@pytest.fixture(scope="module")
def service(tmp_path_factory):
    from fastapi.testclient import TestClient

    from app.main import create_app
    from tests.api.support import auth_headers, create_api_key, make_settings, migrate_database

    settings = make_settings(tmp_path_factory.mktemp("error_languages"))
    migrate_database(settings.database_url)
    key = create_api_key(settings.database_url, "engineer")
    with TestClient(create_app(settings), follow_redirects=False) as client:
        yield client, auth_headers(key)


def _upload(client, headers: dict, path: Path, metadata: dict):
    with path.open("rb") as fh:
        return client.post("/api/v1/runs", files={"file": (path.name, fh, "text/csv")},
                           data={"metadata": json.dumps(metadata)}, headers=headers)


def test_an_upload_is_refused_in_the_users_language(service, tmp_path: Path) -> None:
    """The 422 of a bad file, parsed in the parse child, answers in the request's language; the field
    (the channel) and the part before the colon stay as they are."""
    client, auth = service
    bad = _csv(tmp_path, {**_good(), "speed": _good()["speed"] * 3.6 + 100})
    r = _upload(client, auth | {"Accept-Language": "de-CH,de;q=0.9"}, bad, META)
    assert r.status_code == 422 and r.json()["field"] == "speed", r.text
    assert r.json()["detail"].startswith("speed: Geschwindigkeit "), r.text
    assert "speed muss in m/s angegeben sein (nicht km/h)" in r.json()["detail"]
    r = _upload(client, auth | {"Accept-Language": "it"}, bad, META)
    assert r.status_code == 422 and "speed deve essere indicata in m/s (non km/h)" in r.json()["detail"], r.text


def test_the_ingest_warnings_are_answered_in_the_readers_language(service, tmp_path: Path) -> None:
    """The warnings kept with a run (the default axle layout used) are stored as messages: the run's
    detail and the run list answer them in the reader's language, English by default."""
    client, auth = service
    r = _upload(client, auth, _csv(tmp_path, _good()), META)
    assert r.status_code == 201, r.text
    run_id = r.json()["id"]
    english = r.json()["warnings"]
    assert any(w.startswith("axle_positions: not given; the default layout was used") for w in english), english
    german = client.get(f"/api/v1/runs/{run_id}", headers=auth | {"Accept-Language": "de"}).json()["warnings"]
    assert len(german) == len(english)
    assert any(w.startswith("axle_positions: nicht angegeben; die Standardanordnung wurde verwendet") for w in german)
    listed = client.get("/api/v1/runs", headers=auth | {"Accept-Language": "fr"}).json()["items"]
    french = next(item for item in listed if item["id"] == run_id)["warnings"]
    assert any(w.startswith("axle_positions : non indiqué ; la disposition par défaut") for w in french), french


def test_a_full_disk_reads_in_the_users_language(tmp_path: Path) -> None:
    """The 507 of an upload the disk cannot hold says what did not fit in the reader's language
    (no errno, no server path)."""
    from app.core.diskspace import DiskFullError, require_free
    from app.core.i18n import _
    from app.runs.upload import refusal

    with pytest.raises(DiskFullError) as exc:
        require_free(tmp_path, 10**18, 0, _("the upload"))
    error, outcome, answer = refusal(exc.value)
    assert outcome == "rejected" and answer is error and error.status_code == 507 and error.field == "storage"
    assert error.message.startswith("not enough free space for the upload: "), error.message
    assert str(tmp_path) not in error.message and "Errno" not in error.message
    german = error.message_in("de")
    assert german.startswith("nicht genug freier Speicher für den Upload: "), german
    assert german.endswith("; das Hochgeladene wurde nicht behalten, schaffen Sie Platz und versuchen Sie es erneut")
