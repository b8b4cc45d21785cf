"""The printed list's rates: the amplitude's change a year as the page shows it (issue 33's real line,
seed 4: a place's trend over 3 runs 45 days apart had a 95 % interval of −38.6 … +34.9 ln units a year,
printed as a number of 19 digits)."""

from __future__ import annotations

import math

import pytest

from app.places.report.render import (
    AMPLITUDE_PERCENT_SHOWN,
    ENGLISH,
    Speech,
    _environment,
    amplitude_percent_text,
)

#: the report's own filter: a rate in ln units a year as the amplitude's change a year, per cent
amplitude_percent = _environment(ENGLISH).filters["amp_rate"]


def test_a_rate_in_ln_units_is_the_amplitudes_change_in_per_cent():
    assert amplitude_percent(-1.0) == pytest.approx(-63.212, abs=1e-3)  # never "−100 %"
    assert amplitude_percent(0.0) == 0.0
    assert amplitude_percent(math.log(2.0)) == pytest.approx(100.0)
    assert amplitude_percent(None) is None and amplitude_percent(math.nan) is None
    assert amplitude_percent(800.0) == math.inf  # math.expm1 overflows: the report must not fail on it


def test_the_printed_number_stops_where_the_page_does():
    assert amplitude_percent_text(ENGLISH, amplitude_percent(34.9)) == "> +999"
    assert amplitude_percent_text(ENGLISH, math.inf) == "> +999"
    assert amplitude_percent_text(ENGLISH, AMPLITUDE_PERCENT_SHOWN) == "+999"
    assert amplitude_percent_text(ENGLISH, amplitude_percent(-38.6)) == "-100"
    assert amplitude_percent_text(ENGLISH, amplitude_percent(-1.84)) == "-84"
    assert amplitude_percent_text(ENGLISH, amplitude_percent(1.84)) == "+530"
    assert amplitude_percent_text(ENGLISH, None) == "–"


def test_the_printed_number_speaks_the_locale():
    de = Speech(lang="de", tag="de-CH")
    assert amplitude_percent_text(de, 1234.0) == "> +999"
    assert amplitude_percent_text(de, -12.4) == "-12"
