"""The one table of run-file formats (app/io/formats.py): what the upload infers from a name, a declared
value or a content type, and what the recognition of a file from its bytes reads, come from it."""

from __future__ import annotations

from pathlib import Path

import pytest

from app.core.errors import ApiError
from app.io.detect import detect_format
from app.io.formats import (
    CONTENT_TYPE_FORMATS,
    EXTENSIONS,
    FORMATS,
    RECORDER_FORMATS,
    RUN_FORMATS,
    format_of_alias,
    format_of_name,
)
from app.io.sources import RECORDER_FORMATS as SOURCE_RECORDERS
from app.runs.upload import infer_format


def test_every_name_extension_and_content_type_names_one_format():
    assert FORMATS == ("hdf5", "csv", "parquet", "mdf4", "tdms")
    assert RECORDER_FORMATS == SOURCE_RECORDERS == ("mdf4", "tdms")
    for f in RUN_FORMATS:
        assert format_of_alias(f" {f.name.upper()} ") == f.name
        for alias in f.aliases:
            assert format_of_alias(alias) == f.name
        for ext in f.extensions:
            assert format_of_name(f"Run 7{ext.upper()}") == (f.name, ext)
            assert infer_format(None, f"x{ext}", "text/csv") == f.name  # the name before the content type
        for ct in f.content_types:
            assert infer_format(None, "upload.bin", ct) == f.name
    assert format_of_name("a.csv.gz") == ("csv", ".csv.gz")  # the longest ending
    assert format_of_name("a.gz") is None and format_of_name(None) is None
    assert format_of_alias("xlsx") is None
    assert set(EXTENSIONS.values()) <= set(FORMATS) and set(CONTENT_TYPE_FORMATS.values()) <= set(FORMATS)


def test_a_declared_unknown_format_is_refused_naming_the_table():
    with pytest.raises(ApiError) as err:
        infer_format("xlsx", "a.csv", None)
    assert err.value.status_code == 422 and err.value.field == "format"
    assert "hdf5, csv, parquet, mdf4, tdms" in err.value.message
    assert infer_format("PQ", "a.csv", None) == "parquet"


@pytest.mark.parametrize("fmt", [f for f in RUN_FORMATS if f.magic])
def test_detect_reads_the_tables_leading_bytes(tmp_path: Path, fmt):
    path = tmp_path / "run.bin"
    path.write_bytes(fmt.magic + b"\0" * 4096 + fmt.magic)  # Parquet: the magic at both ends
    assert detect_format(path)[0] == fmt.name
