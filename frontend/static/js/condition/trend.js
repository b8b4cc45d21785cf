/* Condition page: one segment's trend over the line's runs — per wheel the quantity the heat map
 * shows (stiffness index by /analytics/segment-trend, or the stored ln A), the segment relative to
 * its surroundings (±1 km) on the right axis with the store's flagged changes, the maintenance
 * actions over it marked. */
(function () {
  "use strict";
  const C = window.trackvkfCondition;
  const { T, $, state } = C;

  /* Per wheel [{start_time, value}] of the stiffness index (one request per wheel of the runs). */
  async function indexByWheel(line_id, track, km, segment_m) {
    const out = {};
    await Promise.all(T.WHEELS.map(async (w) => {
      const res = await T.api.get("/analytics/segment-trend", { line_id, track, km, wheel: w, segment_m, align: false, value: "index" });
      out[w] = new Map(res.points.filter((p) => p.index !== null && p.index !== undefined).map((p) => [p.run_id, p.index]));
    }));
    return out;
  }

  async function drawTrend(view = C.view()) {
    const el = $("cond-trend");
    const km = parseFloat($("cond-trend-km").value);
    if (!view.live()) return null;  // a draw for a line no longer chosen writes nothing
    const { line_id, track } = view;
    if (!Number.isFinite(km)) { T.emptyState(el, T._("Choose a segment."), `<p>${T._("Click a cell of the heat map or a work list row.")}</p>`); return; }
    const segment_m = $("cond-trend-seg").value;
    const index = C.showIndex();
    const t = await T.api.get("/condition/trend", { line_id, track, km, segment_m });
    const byWheel = index ? await indexByWheel(line_id, track, km, t.segment_m) : null;
    if (!view.live()) return;  // another line was chosen meanwhile
    state.trend = t;
    $("cond-trend-title").textContent = T._("Trend of segment km {from}–{to} ({m} m)",
      { from: T.fmt(t.segment_km[0], 3), to: T.fmt(t.segment_km[1], 3), m: t.segment_m });
    if (!t.points.length) { T.emptyState(el, T._("No run covers this segment."), ""); return; }
    const x = t.points.map((p) => p.start_time);
    const valueOf = (p, w) => {
      if (index) return byWheel[w].has(p.run_id) ? byWheel[w].get(p.run_id) : null;
      const r = p.wheels.find((q) => q.wheel === w);
      return r ? r.condition_index : null;
    };
    const traces = T.WHEELS.map((w) => ({
      type: "scatter", mode: "lines", name: T.wheelLabel(w), x, line: { color: T.wheelColor(w), width: 1 }, opacity: 0.55,
      y: t.points.map((p) => valueOf(p, w)),
      hovertemplate: `${T.wheelLabel(w)} %{x|${T.DATE_FMT}}: %{y:.3f}<extra></extra>`,
    })).filter((tr) => tr.y.some((v) => v !== null));
    const relative = T._("relative to its surroundings (right axis)");
    traces.push({ type: "scatter", mode: "lines+markers", name: relative, x, yaxis: "y2",
      y: t.points.map((p) => p.relative), line: { color: "#1d2733", width: 2 }, marker: { size: 4 },
      hovertemplate: `%{x|${T.DATE_FMT}}: %{y:.3f} ${T.esc(T._("relative"))}<extra></extra>` });
    const flagged = t.points.filter((p) => p.flagged);
    if (flagged.length) traces.push({ type: "scatter", mode: "markers", name: T._("flagged change"), x: flagged.map((p) => p.start_time), yaxis: "y2",
      y: flagged.map((p) => p.relative), marker: { symbol: "x", size: 10, color: "#c62828" } });
    const shapes = t.maintenance.map((m) => ({ type: "line", xref: "x", yref: "paper", x0: m.date, x1: m.date, y0: 0, y1: 1,
      line: { color: "#2e7d32", width: 2, dash: "dash" } }));
    const annotations = t.maintenance.map((m) => ({ x: m.date, y: 1, xref: "x", yref: "paper", yanchor: "bottom", showarrow: false,
      text: T.esc(T.label("maintenance type", m.type)), font: { size: 11, color: "#2e7d32" } }));
    await T.plot(el, traces, {
      xaxis: T.axis(T._("Run date"), { type: "date" }),
      yaxis: T.axis(index ? T._("Stiffness index ln(A / A_ref) (ln units)") : T._("Condition index ln(A / 1 m/s²) (ln units)")),
      yaxis2: T.axis(T._("Relative to the surroundings (ln units)"), { overlaying: "y", side: "right", showgrid: false }),
      shapes, annotations, margin: { l: 80, r: 80, t: 30, b: 55 },
    }, {
      filename: `condition-trend-km${t.segment_km[0].toFixed(3)}`,
      csv: () => {
        const rows = [];
        for (const p of t.points) for (const w of p.wheels) {
          rows.push([p.run_id, p.start_time, t.segment_km[0], t.segment_km[1], w.wheel, valueOf(p, w.wheel), p.relative, w.amp_mean, w.speed_kmh, w.change_z, p.flagged ? 1 : 0]);
        }
        return { columns: ["run_id", "start_time", "km_from", "km_to", "wheel", index ? "stiffness_index" : "ln_a", "relative_mean", "amp_mean_mps2", "speed_kmh", "change_z", "flagged"], rows };
      },
    });
  }

  $("cond-trend-show").addEventListener("click", () => drawTrend().catch(C.fail(T._("Trend"))));

  C.drawTrend = drawTrend;
})();
