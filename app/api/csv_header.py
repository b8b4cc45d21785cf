"""The ``header`` parameter of the CSV exports: the API's field names (``fields``, the default: what a
data system reads) or each column's label and unit in the request's language (``labels``: what a
person opening the file in a spreadsheet reads; :mod:`app.core.csv_labels`)."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Query, Request

from app.api.language import request_language
from app.core.csv_labels import check_header

__all__ = ["CsvLanguage"]


def _csv_language(
    request: Request,
    header: Annotated[str | None, Query(max_length=40, description="fields (default): the API's field names; "
                                                                   "labels: each column's label and unit in the "
                                                                   "user's language")] = None,
) -> str | None:
    """The language of the header's labels, or None for the field names; 422 naming ``header`` for
    anything but ``fields`` or ``labels``."""
    return request_language(request).code if check_header(header) == "labels" else None


#: A CSV route's parameter: the language to write the header's labels in, None for the field names.
CsvLanguage = Annotated[str | None, Depends(_csv_language)]
