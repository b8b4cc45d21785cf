"""The report's plots as static SVG, drawn on the server (no browser, no network): a place's
history over time, where a place is along its line, where it is on the map, the section classes
along the line. Plain SVG text (escaped), sized in px, that WeasyPrint embeds as vector images.
"""

from __future__ import annotations

import datetime as dt
import math
from collections.abc import Callable, Sequence
from html import escape

import numpy as np

__all__ = ["history_plot", "line_strip", "mini_map"]

_FONT = 'font-family="DejaVu Sans, sans-serif" font-size="10"'
_AXIS = "#444"
_GRID = "#ddd"
#: a place's matched passes (open circles) and their fitted trend (dashed), as the Condition page draws them
_PASS = "#3f6ea5"
_TREND = "#b5651d"


def _svg(width: int, height: int, body: list[str], label: str) -> str:
    return (f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
            f'viewBox="0 0 {width} {height}" role="img" aria-label="{escape(label)}">' + "".join(body) + "</svg>")


def _ticks(lo: float, hi: float, n: int = 5) -> list[float]:
    """Round tick values covering [lo, hi]."""
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi <= lo:
        return [lo]
    step = 10 ** math.floor(math.log10((hi - lo) / n))
    for m in (1, 2, 5, 10):
        if (hi - lo) / (m * step) <= n:
            step *= m
            break
    start = math.ceil(lo / step) * step
    return [start + i * step for i in range(int((hi - start) / step + 1e-9) + 1)]


def _fmt(v: float) -> str:
    return f"{v:.2f}".rstrip("0").rstrip(".") if abs(v) < 100 else f"{v:.0f}"


def _iso_month(d: dt.date) -> str:
    return d.strftime("%Y-%m")


#: a tick's number as text (the report passes its locale's; default: plain, up to 2 decimals)
Number = Callable[[float], str]
#: a month tick (the first of the month) as text
Month = Callable[[dt.date], str]


def history_plot(times: Sequence[dt.datetime], values: Sequence[float], sds: Sequence[float | None], *,
                 limits: Sequence[tuple[float, str, str]] = (), markers: Sequence[tuple[dt.date, str]] = (),
                 passes: Sequence[tuple[dt.datetime, float]] = (),
                 trend: tuple[tuple[dt.datetime, float], tuple[dt.datetime, float]] | None = None,
                 y_label: str, width: int = 520, height: int = 220, label: str = "history",
                 number: Number = _fmt, month: Month = _iso_month) -> str:
    """Values over time with ±1σ bars, horizontal limits ``(value, label, colour)`` and vertical
    markers ``(date, label)`` (maintenance); ``passes`` ``(time, value)`` as open circles (a place's matched
    passes) and ``trend`` ``((time, value), (time, value))`` as a dashed line (their fitted trend); ticks
    written by ``number`` and ``month``."""
    left, right, top, bottom = 52, 12, 12, 34
    pw, ph = width - left - right, height - top - bottom
    t = np.array([x.timestamp() for x in times], dtype=float)
    v = np.array(values, dtype=float)
    s = np.array([np.nan if x is None else x for x in sds], dtype=float)
    extra = [*passes, *(trend or ())]
    et = np.array([x.timestamp() for x, _ in extra], dtype=float)
    ev = np.array([y for _, y in extra], dtype=float)
    mt = [dt.datetime.combine(d, dt.time(12), tzinfo=dt.UTC).timestamp() for d, _ in markers]
    t_all = np.concatenate([t, et, mt])
    t0, t1 = (float(t_all.min()), float(t_all.max())) if t_all.size else (0.0, 1.0)
    if t1 - t0 < 86400:
        t0, t1 = t0 - 86400 * 15, t1 + 86400 * 15
    pad_t = 0.04 * (t1 - t0)
    t0, t1 = t0 - pad_t, t1 + pad_t
    lo_v = np.nanmin(np.concatenate([v - np.nan_to_num(s), ev, [x for x, _, _ in limits], [0.0]])) if v.size else 0.0
    hi_v = np.nanmax(np.concatenate([v + np.nan_to_num(s), ev, [x for x, _, _ in limits], [0.0]])) if v.size else 1.0
    pad_v = 0.08 * (hi_v - lo_v or 1.0)
    lo_v, hi_v = lo_v - pad_v, hi_v + pad_v

    def x_of(tt: float) -> float:
        return left + pw * (tt - t0) / (t1 - t0)

    def y_of(vv: float) -> float:
        return top + ph * (1 - (vv - lo_v) / (hi_v - lo_v))

    body = [f'<rect x="{left}" y="{top}" width="{pw}" height="{ph}" fill="white" stroke="{_AXIS}"/>']
    for yv in _ticks(lo_v, hi_v):
        y = y_of(yv)
        body.append(f'<line x1="{left}" y1="{y:.1f}" x2="{left + pw}" y2="{y:.1f}" stroke="{_GRID}"/>'
                    f'<text x="{left - 4}" y="{y + 3:.1f}" text-anchor="end" {_FONT}>{escape(number(yv))}</text>')
    months = _month_ticks(t0, t1, month)
    for tt, text in months:
        x = x_of(tt)
        body.append(f'<line x1="{x:.1f}" y1="{top + ph}" x2="{x:.1f}" y2="{top + ph + 4}" stroke="{_AXIS}"/>'
                    f'<text x="{x:.1f}" y="{top + ph + 15}" text-anchor="middle" {_FONT}>{escape(text)}</text>')
    for value, text, colour in limits:
        y = y_of(value)
        body.append(f'<line x1="{left}" y1="{y:.1f}" x2="{left + pw}" y2="{y:.1f}" stroke="{colour}" '
                    f'stroke-dasharray="5 3"/><text x="{left + pw - 3}" y="{y - 3:.1f}" text-anchor="end" '
                    f'fill="{colour}" {_FONT}>{escape(text)}</text>')
    for (_, text), tt in zip(markers, mt, strict=True):
        x = x_of(tt)
        body.append(f'<line x1="{x:.1f}" y1="{top}" x2="{x:.1f}" y2="{top + ph}" stroke="#6a1b9a"/>'
                    f'<text x="{x + 3:.1f}" y="{top + 10}" fill="#6a1b9a" {_FONT}>{escape(text)}</text>')
    ok = np.isfinite(v)
    pts = [(x_of(a), y_of(b)) for a, b in zip(t[ok], v[ok], strict=True)]
    for a, b, sd in zip(t[ok], v[ok], s[ok], strict=True):
        if math.isfinite(sd) and sd > 0:
            x = x_of(a)
            body.append(f'<line x1="{x:.1f}" y1="{y_of(b - sd):.1f}" x2="{x:.1f}" y2="{y_of(b + sd):.1f}" '
                        f'stroke="#1f77b4" stroke-width="1"/>')
    if len(pts) > 1:
        body.append('<polyline fill="none" stroke="#1f77b4" stroke-width="1.5" points="'
                    + " ".join(f"{x:.1f},{y:.1f}" for x, y in pts) + '"/>')
    body.extend(f'<circle cx="{x:.1f}" cy="{y:.1f}" r="2.6" fill="#1f77b4"/>' for x, y in pts)
    body.extend(f'<circle cx="{x_of(a.timestamp()):.1f}" cy="{y_of(b):.1f}" r="2.8" fill="none" stroke="{_PASS}" '
                f'stroke-width="1.2"/>' for a, b in passes if math.isfinite(b))
    if trend is not None:
        (ta, va), (tb, vb) = trend
        body.append(f'<line x1="{x_of(ta.timestamp()):.1f}" y1="{y_of(va):.1f}" x2="{x_of(tb.timestamp()):.1f}" '
                    f'y2="{y_of(vb):.1f}" stroke="{_TREND}" stroke-width="1.5" stroke-dasharray="6 3"/>')
    body.append(f'<text x="12" y="{top + ph / 2:.1f}" transform="rotate(-90 12 {top + ph / 2:.1f})" '
                f'text-anchor="middle" {_FONT}>{escape(y_label)}</text>')
    return _svg(width, height, body, label)


def _month_ticks(t0: float, t1: float, month: Month) -> list[tuple[float, str]]:
    a = dt.datetime.fromtimestamp(t0, dt.UTC)
    b = dt.datetime.fromtimestamp(t1, dt.UTC)
    months = (b.year - a.year) * 12 + b.month - a.month + 1
    step = max(1, math.ceil(months / 7))
    out, y, m = [], a.year, a.month
    while True:
        m += 1
        if m > 12:
            y, m = y + 1, 1
        tick = dt.datetime(y, m, 1, tzinfo=dt.UTC)
        if tick.timestamp() > t1:
            return out
        if (m - 1) % step == 0:
            out.append((tick.timestamp(), month(tick.date())))


def line_strip(km_range: tuple[float, float], spans: Sequence[tuple[float, float, str]], *,
               highlight: tuple[float, float] | None = None, width: int = 520, height: int = 46,
               label: str = "along the line", number: Number = _fmt) -> str:
    """The line from ``km_range[0]`` to ``[1]`` with coloured ``spans`` ``(km_from, km_to, colour)``
    and a highlighted extent (a place), km ticks below (written by ``number``)."""
    left, right, top = 10, 10, 6
    pw, bar = width - left - right, 16
    a, b = km_range
    b = b if b > a else a + 1.0

    def x_of(km: float) -> float:
        return left + pw * (km - a) / (b - a)

    body = [f'<rect x="{left}" y="{top}" width="{pw}" height="{bar}" fill="#eceff1" stroke="{_AXIS}"/>']
    body.extend(f'<rect x="{x_of(k0):.1f}" y="{top}" width="{max(x_of(k1) - x_of(k0), 0.6):.1f}" '
                f'height="{bar}" fill="{escape(c)}"/>' for k0, k1, c in spans)
    if highlight is not None:
        h0, h1 = x_of(highlight[0]), x_of(highlight[1])
        mid = (h0 + h1) / 2
        body.append(f'<rect x="{min(h0, mid - 2):.1f}" y="{top - 3}" width="{max(h1 - h0, 4):.1f}" '
                    f'height="{bar + 6}" fill="none" stroke="#000" stroke-width="2"/>')
    for km in _ticks(a, b, 8):
        x = x_of(km)
        body.append(f'<line x1="{x:.1f}" y1="{top + bar}" x2="{x:.1f}" y2="{top + bar + 4}" stroke="{_AXIS}"/>'
                    f'<text x="{x:.1f}" y="{top + bar + 15}" text-anchor="middle" {_FONT}>{escape(number(km))}</text>')
    return _svg(width, height, body, label)


def mini_map(x: np.ndarray, y: np.ndarray, mark_x: np.ndarray, mark_y: np.ndarray, *, width: int = 240,
             height: int = 180, label: str = "map", number: Number = _fmt) -> str:
    """The line's geometry (local metric coordinates, m) with a marked stretch, north up, to scale,
    with a scale bar (its length written by ``number``)."""
    pad = 12
    x0, x1, y0, y1 = float(np.min(x)), float(np.max(x)), float(np.min(y)), float(np.max(y))
    span = max(x1 - x0, y1 - y0, 1.0)
    k = min((width - 2 * pad) / span, (height - 2 * pad - 14) / span)

    def pt(a: float, b: float) -> str:
        return f"{pad + (a - x0) * k:.1f},{height - pad - 14 - (b - y0) * k:.1f}"

    body = [f'<rect x="0.5" y="0.5" width="{width - 1}" height="{height - 1}" fill="#f7f9fa" stroke="{_GRID}"/>',
            '<polyline fill="none" stroke="#607d8b" stroke-width="2" points="'
            + " ".join(pt(a, b) for a, b in zip(x, y, strict=True)) + '"/>',
            '<polyline fill="none" stroke="#c62828" stroke-width="5" points="'
            + " ".join(pt(a, b) for a, b in zip(mark_x, mark_y, strict=True)) + '"/>']
    mid = len(mark_x) // 2
    body.append(f'<circle cx="{pt(mark_x[mid], mark_y[mid]).split(",")[0]}" cy="{pt(mark_x[mid], mark_y[mid]).split(",")[1]}" '
                'r="6" fill="none" stroke="#c62828" stroke-width="1.5"/>')
    bar_m = 10 ** math.floor(math.log10(span / 3))
    body.append(f'<line x1="{pad}" y1="{height - 8}" x2="{pad + bar_m * k:.1f}" y2="{height - 8}" stroke="{_AXIS}" '
                f'stroke-width="2"/><text x="{pad + bar_m * k + 4:.1f}" y="{height - 5}" {_FONT}>'
                f'{escape(number(bar_m / 1000)) + " km" if bar_m >= 1000 else escape(number(bar_m)) + " m"}</text>'
                f'<text x="{width - pad}" y="{pad + 8}" text-anchor="end" {_FONT}>N ↑</text>')
    return _svg(width, height, body, label)
