/* Condition page: the line's runs × segments heat map — the stiffness index per segment (by
 * /analytics/segments, value=index) first, the stored condition index ln A (/condition/heatmap)
 * one click away — with the store's flagged changes and the line's rail findings (a dotted line
 * each) marked on both. Runs run down the map oldest first, as on the Line view. A click on a cell shows its segment's trend. */
(function () {
  "use strict";
  const C = window.trackvkfCondition;
  const { T, $, state } = C;

  function showIndex() { return $("cond-value").value === "index"; }

  /* The rows, columns and values to draw: {runs: [{run_id, start_time}], km (segment starts),
   * segment_m, matrix, flagged: [[run_id, km]]}. */
  async function load(line_id, track, wheel) {
    const heat = await T.api.get("/condition/heatmap", { line_id, track, wheel });
    const flagged = heat.flagged.map(([i, j]) => [heat.runs[i].run_id, heat.km[j]]);
    if (!showIndex()) return { ...heat, flagged, value: "ln_a" };
    const seg = await T.api.get("/analytics/segments", { line_id, track, wheel, segment_m: heat.segment_m, align: false, value: "index" });
    return { runs: seg.runs, km: seg.km, segment_m: seg.segment_m, matrix: seg.matrix, flagged, value: "index" };
  }

  async function drawHeatmap(view = C.view()) {
    const el = $("cond-heatmap");
    if (!view.live()) return null;  // a draw for a line no longer chosen writes nothing
    const { line_id, track } = view;
    const index = showIndex();
    const heat = await load(line_id, track, $("cond-wheel").value);
    if (!view.live()) return;  // another line was chosen meanwhile
    state.heat = heat;
    $("cond-heatmap-title").textContent = index
      ? T._("Stiffness index per {m} m × run", { m: T.fmt(heat.segment_m, 0) })
      : T._("Condition index ln A per {m} m × run", { m: T.fmt(heat.segment_m, 0) });
    if (!heat.runs.length || !heat.km.length) { T.emptyState(el, T._("No runs of this line in the condition store."), ""); return; }
    const x = heat.km.map((k) => k + heat.segment_m / 2000);
    const y = heat.runs.map((r) => r.start_time);
    const when = new Map(heat.runs.map((r) => [r.run_id, r.start_time]));
    const marks = heat.flagged.filter(([run]) => when.has(run));
    const name = index ? T._("stiffness index") : "ln A";
    // the line's rail findings (welds, joints; condition/rails.js drew them for this view): a dotted line each
    const rails = state.rails && state.rails.key === view.key ? state.rails.items : [];
    const shapes = rails.map((f) => ({ type: "line", xref: "x", yref: "paper", x0: f.km, x1: f.km, y0: 0, y1: 1,
                                       line: { color: "rgba(29,39,51,0.55)", width: 1, dash: "dot" } }));
    await T.plot(el, [
      { type: "heatmap", x, y, z: heat.matrix, colorscale: index ? "RdBu" : "YlOrRd", reversescale: !index, zmid: index ? 0 : undefined,
        hoverongaps: false, name,
        colorbar: { title: { text: index ? T._("stiffness index (ln units)") : T._("ln A (ln units)"), side: "right" }, thickness: 14 },
        hovertemplate: `%{y|${T.DATE_FMT}}<br>km %{x:.2f}<br>${T.esc(name)} %{z:.3f}<extra></extra>` },
      { type: "scatter", mode: "markers", x: marks.map(([, k]) => k + heat.segment_m / 2000), y: marks.map(([run]) => when.get(run)),
        name: T._("flagged change"), marker: { symbol: "x-thin", size: 7, color: "#1d2733", line: { width: 1.5, color: "#1d2733" } },
        hovertemplate: `${T.esc(T._("flagged change"))}<br>%{y|${T.DATE_FMT}} km %{x:.2f}<extra></extra>` },
    ], {
      xaxis: T.axis(T._("Track position, segment centre (km)"), { tickformat: ".1f" }),
      // oldest run at the top, as the Line view's heat map
      yaxis: T.axis(T._("Run (date)"), { type: "date", autorange: "reversed" }),
      margin: { l: 90, r: 30, t: 20, b: 60 }, showlegend: false, shapes,
    }, {
      filename: `condition-heatmap-${line_id}`,
      csv: () => {
        const rows = [];
        const flaggedAt = new Set(marks.map(([run, k]) => `${run}:${k.toFixed(4)}`));
        heat.runs.forEach((r, i) => heat.km.forEach((k, j) => rows.push([r.run_id, r.start_time, k, k + heat.segment_m / 1000, heat.matrix[i][j],
          flaggedAt.has(`${r.run_id}:${k.toFixed(4)}`) ? 1 : 0])));
        return { columns: ["run_id", "start_time", "km_from", "km_to", index ? "stiffness_index" : "ln_a", "flagged"], rows };
      },
    });
    if (!el.dataset.clickBound) {
      el.dataset.clickBound = "1";
      el.on("plotly_click", (ev) => {
        const p = ev.points && ev.points[0];
        if (!p || !state.heat) return;
        $("cond-trend-km").value = (p.x - state.heat.segment_m / 2000 + 0.0005).toFixed(3);
        $("cond-trend-seg").value = String(C.RULES.overviewSegmentM);
        C.drawTrend().catch(C.fail(T._("Trend")));
      });
    }
  }

  $("cond-wheel").addEventListener("change", () => drawHeatmap().catch(C.fail(T._("Heat map"))));
  $("cond-value").addEventListener("change", () => Promise.all([drawHeatmap(), C.drawTrend()]).catch(C.fail(T._("Heat map"))));

  C.showIndex = showIndex;
  C.drawHeatmap = drawHeatmap;
})();
