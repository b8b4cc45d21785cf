/* Line view: heat map runs × km (/analytics/segments: the runs aligned and averaged per
 * segment by the server), overlaid profiles with the line's assets marked, trend of one segment
 * across run dates (/analytics/segment-trend). The stiffness index first (value=index), the raw
 * amplitude one click away. Runs run down the heat map oldest first, as on the Condition page. */
(function () {
  "use strict";
  const T = window.trackvkf;
  let runs = [], seg = null, profiles = [];
  const SEG_M = T.boot.segment_m; // the server's default segment of /analytics/segments

  const lineKey = T.lineKey;
  function runLabel(r) { return T._("{date} · run {run}", { date: T.date(r.start_time), run: r.run_id }); }
  function value() { return document.getElementById("line-value").value; }
  function isIndex() { return value() === "index"; }
  /* The quantity's name with its unit, and the same for a hover label. */
  function quantity() {
    return isIndex() ? { title: T._("Stiffness index ln(A / A_ref) (ln units)"), short: T._("stiffness index"), unit: T._("ln units"), digits: 3 }
      : { title: T._("Sleeper-passage amplitude (m/s²)"), short: T._("amplitude"), unit: "m/s²", digits: 3 };
  }

  async function drawHeatmap() {
    const el = document.getElementById("heatmap-plot");
    const q = quantity();
    document.getElementById("heatmap-title").textContent = isIndex()
      ? T._("Stiffness index per {m} m segment: runs × km", { m: T.fmt(SEG_M, 0) })
      : T._("Sleeper-passage amplitude per {m} m segment: runs × km", { m: T.fmt(SEG_M, 0) });
    if (!seg || !seg.runs.length || !seg.km.length) {
      T.emptyState(el, T._("No processed runs on this line and track."), `<p>${T._("Upload runs on the Runs page.")}</p>`);
      return;
    }
    const x = seg.km.map((k) => k + seg.segment_m / 2000);
    await T.plot(el, [{
      type: "heatmap", x, y: seg.runs.map(runLabel), z: seg.matrix, colorscale: isIndex() ? "RdBu" : "YlOrRd",
      reversescale: !isIndex(), zmid: isIndex() ? 0 : undefined, hoverongaps: false,
      colorbar: { title: { text: q.title, side: "right" }, thickness: 14 },
      hovertemplate: `%{y}<br>km %{x:.3f}<br>${q.short} %{z:.3f} ${isIndex() ? "" : "m/s²"}<extra></extra>`,
    }], {
      xaxis: T.axis(T._("Track position, segment centre (km)"), { tickformat: ".3f" }),
      // oldest run at the top, as the Condition page's heat map
      yaxis: T.axis(T._("Run (start date)"), { type: "category", autorange: "reversed" }),
      margin: { l: 150, r: 30, t: 20, b: 60 },
    }, {
      filename: "line-heatmap",
      csv: () => {
        const rows = [];
        seg.runs.forEach((r, i) => seg.km.forEach((k, j) => rows.push([r.run_id, r.start_time, k, k + seg.segment_m / 1000, seg.matrix[i][j]])));
        return { columns: ["run_id", "start_time", "km_from", "km_to", isIndex() ? "stiffness_index" : "sleeper_amp_mean_mps2"], rows };
      },
    });
    if (el.dataset.clickBound) return;
    el.dataset.clickBound = "1";
    el.on("plotly_click", (ev) => {
      const p = ev.points && ev.points[0];
      if (!p) return;
      document.getElementById("trend-km").value = (p.x - seg.segment_m / 2000).toFixed(3);
      drawTrend();
    });
  }

  async function drawProfiles(doneRuns, wheel) {
    const el = document.getElementById("profiles-plot");
    const index = isIndex();
    const col = index ? "stiffness_index_mean" : "sleeper_amp_mean";
    profiles = await Promise.all(doneRuns.map(async (r) => {
      try {
        const params = { wheel, level: 10, max_points: 3000, columns: "sleeper_amp" };
        if (index) params.index = true;
        return { run: r, rows: (await T.api.profile(`/runs/${r.id}/profile`, params)).rows };
      } catch (e) { return { run: r, rows: [] }; }
    }));
    profiles = profiles.filter((p) => p.rows.length);
    if (!profiles.length) { T.emptyState(el, T._("No profiles."), ""); return; }
    const n = profiles.length;
    const traces = profiles.map((p, i) => {
      const t = n > 1 ? i / (n - 1) : 1;
      const color = `rgb(${Math.round(60 + 170 * t)}, ${Math.round(110 - 60 * t)}, ${Math.round(190 - 150 * t)})`;
      return {
        type: "scatter", mode: "lines", name: T._("{date} (run {run})", { date: T.date(p.run.start_time), run: p.run.id }), line: { color, width: 1.4 },
        x: p.rows.map((r) => (r.km_from + r.km_to) / 2), y: p.rows.map((r) => r[col] ?? null),
        hovertemplate: `${T.esc(T._("run {run}", { run: p.run.id }))} ${T.date(p.run.start_time)}<br>km %{x:.3f}<br>%{y:.3f} ${index ? "" : "m/s²"}<extra></extra>`,
      };
    });
    // the line's known discontinuities (assets): a dotted line at each, labelled with its type
    const first = profiles[0].run;
    const assets = ((await T.api.optional("/assets", { line_id: first.line_id, track: first.track })) || { items: [] }).items;
    const shapes = assets.map((a) => ({ type: "line", xref: "x", yref: "paper", x0: a.km, x1: a.km, y0: 0, y1: 1,
      line: { color: "rgba(55,71,79,0.7)", width: 1, dash: "dot" } }));
    const annotations = assets.length <= 40 ? assets.map((a) => ({ x: a.km, y: 0.99, xref: "x", yref: "paper", yanchor: "top",
      showarrow: false, text: `◆ ${T.esc(T.label("asset type", a.type))}`, font: { size: 10, color: "#37474f" }, bgcolor: "rgba(255,255,255,0.75)",
      hovertext: `${T.esc(T.label("asset type", a.type))}${a.name ? " " + T.esc(a.name) : ""} · km ${T.fmt(a.km, 3)}` })) : [];
    await T.plot(el, traces, {
      shapes, annotations,
      xaxis: T.axis(T._("Track position (km)"), { tickformat: ".3f" }),
      yaxis: index ? T.axis(T._("{wheel}: stiffness index (ln units)", { wheel: T.wheelLabel(wheel) }), { zeroline: true })
        : T.axis(T._("{wheel}: amplitude (m/s²)", { wheel: T.wheelLabel(wheel) }), { rangemode: "tozero" }),
      legend: { orientation: "v", x: 1.01, y: 1, xanchor: "left" },
      margin: { l: 75, r: 20, t: 20, b: 60 },
    }, {
      filename: `line-profiles-${wheel}`,
      csv: () => {
        const rows = [];
        for (const p of profiles) for (const r of p.rows) rows.push([p.run.id, p.run.start_time, wheel, r.km_from, r.km_to, r[col], r.sleeper_amp_max, (r.speed_mean_mean ?? NaN) * 3.6]);
        return { columns: ["run_id", "start_time", "wheel", "km_from", "km_to", index ? "stiffness_index_mean" : "sleeper_amp_mean_mps2", "sleeper_amp_max_mps2", "speed_kmh"], rows };
      },
    });
  }

  async function drawTrend() {
    const el = document.getElementById("trend-plot");
    const km = parseFloat(document.getElementById("trend-km").value);
    const wheel = document.getElementById("wheel").value;
    const { line_id, track } = T.lineOf("line-track");
    const index = isIndex();
    if (!seg || !Number.isFinite(km)) { T.emptyState(el, T._("Choose a segment."), `<p>${T._("Click a cell of the heat map or enter a km.")}</p>`); return; }
    const res = await T.api.get("/analytics/segment-trend", { line_id, track, km, wheel, segment_m: seg.segment_m, value: value() });
    const key = index ? "index" : "amplitude";
    const points = res.points.filter((p) => p[key] !== null && p[key] !== undefined);
    const k0 = Math.floor(km * 1000 / seg.segment_m) * seg.segment_m / 1000;
    document.getElementById("trend-title").textContent = T._("Trend of segment km {from}–{to} across run dates",
      { from: T.fmt(k0, 3), to: T.fmt(k0 + seg.segment_m / 1000, 3) });
    if (!points.length) { T.emptyState(el, T._("No runs cover this segment."), ""); return; }
    await T.plot(el, [{
      type: "scatter", mode: T.trendMode(points.map((p) => p.start_time)), name: T.wheelLabel(wheel), x: points.map((p) => p.start_time), y: points.map((p) => p[key]),
      customdata: points.map((p) => p.run_id), line: { color: T.wheelColor(wheel), width: 2 }, marker: { size: 9 },
      hovertemplate: `%{x|${T.DATE_FMT}}<br>%{y:.3f} ${index ? "" : "m/s²"}<br>${T.esc(T._("run {run}", { run: "%{customdata}" }))}<extra></extra>`,
    }], {
      xaxis: T.dateAxis(T._("Run start (date)"), points.map((p) => p.start_time)),
      yaxis: index ? T.axis(T._("Stiffness index (ln units)"), { zeroline: true }) : T.axis(T._("Amplitude (m/s²)"), { rangemode: "tozero" }),
      margin: { l: 75, r: 20, t: 20, b: 55 }, showlegend: true,
    }, {
      filename: `segment-trend-km${k0.toFixed(3)}`,
      csv: () => ({ columns: ["run_id", "start_time", "km_from", "wheel", index ? "stiffness_index" : "amplitude_mps2"], rows: points.map((p) => [p.run_id, p.start_time, k0, wheel, p[key]]) }),
    });
  }

  async function show() {
    T.banner(null);
    const key = document.getElementById("line-track").value;
    const wheel = document.getElementById("wheel").value;
    const { line_id, track } = T.lineOf("line-track");
    T.rememberLine({ line_id, track });
    const doneRuns = runs.filter((r) => lineKey(r) === key && r.latest_job && r.latest_job.status === "done")
      .sort((a, b) => String(a.start_time).localeCompare(String(b.start_time)));
    seg = null;
    try { seg = await T.api.get("/analytics/segments", { line_id, track, wheel, segment_m: SEG_M, align: true, value: value() }); }
    catch (e) { T.banner(T._("Segments not available (HTTP {status}): {detail}", { status: e.status, detail: e.detail })); }
    document.getElementById("line-info").textContent =
      T.ngettext("{n} processed run", "{n} processed runs", doneRuns.length) + " · " + T._("runs aligned by the analytics service");
    document.getElementById("line-quantity").textContent = isIndex()
      ? T._("Stiffness index ln(A / A_ref(class, v)): the amplitude against the typical track of its superstructure class at the speed it was passed (0 = typical, +0.10 = an amplitude 10.5 % higher). The raw amplitude also moves with speed.")
      : T._("Raw sleeper-passage amplitude A (m/s²): it moves with speed as well as with the track; the stiffness index takes the speed out.");
    const trendKm = document.getElementById("trend-km");
    if (!trendKm.value && seg && seg.km.length) trendKm.value = seg.km[Math.floor(seg.km.length / 2)].toFixed(3);
    await drawHeatmap();
    await drawProfiles(doneRuns, wheel);
    await drawTrend();
  }

  const fail = (e) => T.banner(T._("Could not load the line view: {detail}", { detail: e.detail || e.message }));
  document.getElementById("line-controls").addEventListener("submit", (ev) => { ev.preventDefault(); show().catch(fail); });
  document.getElementById("line-value").addEventListener("change", () => show().catch(fail));

  (async () => {
    try {
      runs = await T.allRuns();
      const keys = T.fillLinePicker("line-track", runs);
      document.getElementById("wheel").innerHTML = T.WHEELS.map((w) => `<option value="${w}">${T.wheelLabel(w)}</option>`).join("");
      document.getElementById("wheel").value = "12";
      if (T.param("value") === "amplitude") document.getElementById("line-value").value = "amplitude";
      if (!keys.length) {
        for (const id of ["heatmap-plot", "profiles-plot", "trend-plot"]) T.emptyState(id, T._("No runs yet."), `<p>${T._("Upload runs on the Runs page.")}</p>`);
      } else {
        await show();
      }
    } catch (e) {
      fail(e);
    }
    T.ready();
  })();
})();
