/* Condition: per line the heat map of the condition index (100 m × run date, flagged cells
 * marked), the work list ranked by priority (links to the stiffness map at that km), the trend
 * of a chosen segment with maintenance actions marked, the before/after view of an action, and
 * (admins) the webhooks with their delivery log. Every number comes from /api/v1/condition/…
 * (the segment condition store), never from the 25 cm rows. */
(function () {
  "use strict";
  const T = window.trackvkf;
  let lines = [], heat = null, trendData = null, effect = null;
  const $ = (id) => document.getElementById(id);

  function current() {
    const [line_id, track] = ($("cond-line").value || "\u0001").split("\u0001");
    return { line_id, track };
  }
  function kmRange() { return { km_from: $("cond-km-from").value, km_to: $("cond-km-to").value }; }
  function indexLabel(name) { return name === "ln_amplitude" ? "Index ln(A / 1 m/s²) (log units)" : `Index ${name} (log units)`; }
  function pct(v, digits) { return v === null || v === undefined ? "–" : `${v > 0 ? "+" : ""}${T.fmt(v, digits ?? 1)}`; }
  function qs(params) {
    const u = new URLSearchParams();
    for (const [k, v] of Object.entries(params)) if (v !== undefined && v !== null && v !== "") u.set(k, v);
    return u.toString();
  }

  async function drawHeatmap() {
    const el = $("cond-heatmap");
    const { line_id, track } = current();
    heat = await T.api.get("/condition/heatmap", { line_id, track, wheel: $("cond-wheel").value, ...kmRange() });
    if (!heat.runs.length || !heat.km.length) { T.emptyState(el, "No runs of this line in the condition store.", ""); return; }
    const x = heat.km.map((k) => k + heat.segment_m / 2000);
    const y = heat.runs.map((r) => r.start_time);
    const fx = heat.flagged.map(([i, j]) => x[j]), fy = heat.flagged.map(([i]) => y[i]);
    await T.plot(el, [
      { type: "heatmap", x, y, z: heat.matrix, colorscale: "YlOrRd", reversescale: true, hoverongaps: false, name: "index",
        colorbar: { title: { text: "Index", side: "right" }, thickness: 14 },
        hovertemplate: "%{y|%Y-%m-%d}<br>km %{x:.2f}<br>index %{z:.3f}<extra></extra>" },
      { type: "scatter", mode: "markers", x: fx, y: fy, name: "flagged", marker: { symbol: "x-thin", size: 7, color: "#1d2733", line: { width: 1.5, color: "#1d2733" } },
        hovertemplate: "flagged<br>%{y|%Y-%m-%d} km %{x:.2f}<extra></extra>" },
    ], {
      xaxis: T.axis("Track position, segment centre (km)", { tickformat: ".1f" }),
      yaxis: T.axis("Run (date)", { type: "date" }),
      margin: { l: 90, r: 30, t: 20, b: 60 }, showlegend: false,
    }, {
      filename: `condition-heatmap-${line_id}`,
      csv: () => {
        const rows = [];
        heat.runs.forEach((r, i) => heat.km.forEach((k, j) => rows.push([r.run_id, r.start_time, k, k + heat.segment_m / 1000, heat.matrix[i][j],
          heat.flagged.some(([a, b]) => a === i && b === j) ? 1 : 0])));
        return { columns: ["run_id", "start_time", "km_from", "km_to", "index", "flagged"], rows };
      },
    });
    if (!el.dataset.clickBound) {
      el.dataset.clickBound = "1";
      el.on("plotly_click", (ev) => {
        const p = ev.points && ev.points[0];
        if (!p) return;
        $("cond-trend-km").value = (p.x - heat.segment_m / 2000 + 0.0005).toFixed(3);
        $("cond-trend-seg").value = String(T.boot.overview_segment_m);
        drawTrend();
      });
    }
  }

  async function drawWorklist() {
    const body = $("worklist-body");
    const { line_id, track } = current();
    const params = { line_id, track, segment_m: $("cond-seg").value, class: $("cond-class").value || undefined, ...kmRange() };
    const wl = await T.api.get("/condition/hotspots", { ...params, limit: 50 });
    const q = qs({ ...params, limit: 10000 });
    $("worklist-csv").href = `${T.boot.api}/condition/hotspots.csv?${q}`;
    $("worklist-geojson").href = `${T.boot.api}/condition/hotspots.geojson?${q}`;
    $("worklist-info").textContent = `${wl.total} segment${wl.total === 1 ? "" : "s"} beyond a threshold` + (wl.total > wl.items.length ? `, first ${wl.items.length}` : "");
    if (!wl.items.length) { body.innerHTML = `<tr><td colspan="11" class="muted">Nothing beyond the thresholds in the newest run.</td></tr>`; return wl; }
    body.innerHTML = wl.items.map((h) => `<tr data-km="${h.km_from}" data-seg="${h.segment_m}">
      <td class="num">${h.rank}</td><td>${h.km_from.toFixed(3)}–${h.km_to.toFixed(3)}</td><td>${T.esc(h.superstructure || "–")}</td>
      <td class="num"><b>${T.fmt(h.priority, 2)}</b></td><td>${T.esc(h.reasons.join(", "))}</td>
      <td>${h.direction === "up" ? "▲ up" : "▼ down"}</td><td class="num">${T.fmt(h.anomaly_z, 1)}</td>
      <td class="num">${pct(h.change_pct)}</td><td class="num">${pct(h.rate_pct_per_year)}</td>
      <td class="num">${h.wheels_agreeing}/${h.n_wheels}</td>
      <td><button class="btn small" type="button" data-act="trend">Trend</button>
        ${h.map_url ? `<a class="btn small" href="${T.esc(h.map_url)}">Stiffness map</a>` : ""}</td></tr>`).join("");
    return wl;
  }

  async function drawTrend() {
    const el = $("cond-trend");
    const km = parseFloat($("cond-trend-km").value);
    const { line_id, track } = current();
    if (!Number.isFinite(km)) { T.emptyState(el, "Choose a segment.", "<p>Click a cell of the heat map or a work list row.</p>"); return; }
    trendData = await T.api.get("/condition/trend", { line_id, track, km, segment_m: $("cond-trend-seg").value });
    const t = trendData;
    $("cond-trend-title").textContent = `Trend of segment km ${t.segment_km[0].toFixed(3)}–${t.segment_km[1].toFixed(3)} (${t.segment_m} m)`;
    if (!t.points.length) { T.emptyState(el, "No run covers this segment.", ""); return; }
    const x = t.points.map((p) => p.start_time);
    const traces = T.WHEELS.map((w) => ({
      type: "scatter", mode: "lines", name: T.wheelLabel(w), x, line: { color: T.wheelColor(w), width: 1 }, opacity: 0.55,
      y: t.points.map((p) => { const r = p.wheels.find((q) => q.wheel === w); return r ? r.index : null; }),
      hovertemplate: `${T.wheelLabel(w)} %{x|%Y-%m-%d}: %{y:.3f}<extra></extra>`,
    })).filter((tr) => tr.y.some((v) => v !== null));
    traces.push({ type: "scatter", mode: "lines+markers", name: "relative to the surrounding ±1 km (right axis)", x, yaxis: "y2",
      y: t.points.map((p) => p.relative), line: { color: "#1d2733", width: 2 }, marker: { size: 4 },
      hovertemplate: "%{x|%Y-%m-%d}: %{y:.3f} relative<extra></extra>" });
    const flagged = t.points.filter((p) => p.flagged);
    if (flagged.length) traces.push({ type: "scatter", mode: "markers", name: "flagged", x: flagged.map((p) => p.start_time), yaxis: "y2",
      y: flagged.map((p) => p.relative), marker: { symbol: "x", size: 10, color: "#c62828" } });
    const shapes = t.maintenance.map((m) => ({ type: "line", xref: "x", yref: "paper", x0: m.date, x1: m.date, y0: 0, y1: 1,
      line: { color: "#2e7d32", width: 2, dash: "dash" } }));
    const annotations = t.maintenance.map((m) => ({ x: m.date, y: 1, xref: "x", yref: "paper", yanchor: "bottom", showarrow: false,
      text: m.type, font: { size: 11, color: "#2e7d32" } }));
    await T.plot(el, traces, {
      xaxis: T.axis("Run date", { type: "date" }), yaxis: T.axis(indexLabel(heat ? heat.index : "ln_amplitude")),
      yaxis2: T.axis("Relative to the surroundings (log units)", { overlaying: "y", side: "right", showgrid: false }),
      shapes, annotations, margin: { l: 80, r: 80, t: 30, b: 55 },
    }, {
      filename: `condition-trend-km${t.segment_km[0].toFixed(3)}`,
      csv: () => {
        const rows = [];
        for (const p of t.points) for (const w of p.wheels) rows.push([p.run_id, p.start_time, t.segment_km[0], t.segment_km[1], w.wheel, w.index, p.relative, w.amp_mean, w.speed_kmh, w.change_z, p.flagged ? 1 : 0]);
        return { columns: ["run_id", "start_time", "km_from", "km_to", "wheel", "index", "relative_mean", "amp_mean_mps2", "speed_kmh", "change_z", "flagged"], rows };
      },
    });
  }

  async function drawActions() {
    const body = $("actions-body");
    const { line_id, track } = current();
    const res = await T.api.get("/condition/maintenance-effect", { line_id, track });
    if (!res.items.length) {
      body.innerHTML = `<tr><td colspan="7" class="muted">No maintenance actions imported for this line (<code>POST /api/v1/reference/maintenance</code>).</td></tr>`;
      T.emptyState("cond-effect", "No maintenance action.", "");
      return;
    }
    // an action no run of the line passed over (before or after) has no before/after view
    const covered = (a) => a.n_runs > 0;
    body.innerHTML = res.items.map((a) => `<tr ${covered(a) ? `data-action="${a.action_id}" style="cursor:pointer"` : `class="muted" title="no run of this line covers it"`}>
      <td>${T.esc(a.date)}</td><td>${T.esc(a.type)}</td><td>${a.km_from.toFixed(3)}–${a.km_to.toFixed(3)}</td>
      <td class="num">${a.n_runs_before} / ${a.n_runs_after}</td><td class="num">${pct(a.recovery_pct)}</td>
      <td class="num">${a.slope_after_per_year === null ? "–" : pct(100 * a.slope_after_per_year)}</td>
      <td class="num">${a.lasted_days_observed !== null ? T.fmt(a.lasted_days_observed, 0) : a.lasted_days_projected !== null ? "≈ " + T.fmt(a.lasted_days_projected, 0) : "–"}</td></tr>`).join("");
    const best = res.items.find((a) => a.recovery !== null) || res.items.find(covered);
    if (!best) {
      $("effect-title").textContent = "Before / after";
      T.emptyState("cond-effect", "No run of this line covers its maintenance actions yet.",
        "<p>The before/after view needs runs over the action's km range.</p>");
      return;
    }
    await drawEffect(best.action_id);
  }

  async function drawEffect(actionId) {
    const el = $("cond-effect");
    effect = await T.api.get(`/condition/maintenance-effect/${actionId}`);
    const e = effect;
    $("effect-title").textContent = `Before / after: ${e.type} on ${e.date}, km ${e.km_from.toFixed(3)}–${e.km_to.toFixed(3)}`;
    const xs = e.profile_km.map((k) => k + 0.005);
    const traces = [
      { type: "scatter", mode: "lines", name: `before (${e.n_runs_before} runs)`, x: xs, y: e.profile_before, line: { color: "#c62828", width: 2 } },
      { type: "scatter", mode: "lines", name: `after (${e.n_runs_after} runs)`, x: xs, y: e.profile_after, line: { color: "#1565c0", width: 2 } },
      { type: "scatter", mode: "markers", name: "per run", x: e.series.map((p) => p.start_time), y: e.series.map((p) => p.index),
        xaxis: "x2", yaxis: "y2", marker: { size: 4, color: "#5d6b7a" } },
    ];
    await T.plot(el, traces, {
      xaxis: T.axis("Track position (km)", { domain: [0, 0.52], tickformat: ".2f" }),
      yaxis: T.axis("Index relative to the surroundings (log units)"),
      xaxis2: T.axis("Run date", { domain: [0.62, 1], type: "date", anchor: "y2" }),
      yaxis2: T.axis("Over the extent (log units)", { anchor: "x2" }),
      shapes: [
        { type: "rect", xref: "x", yref: "paper", x0: e.km_from, x1: e.km_to, y0: 0, y1: 1, fillcolor: "rgba(46,125,50,0.10)", line: { width: 0 } },
        { type: "line", xref: "x2", yref: "paper", x0: e.date, x1: e.date, y0: 0, y1: 1, line: { color: "#2e7d32", width: 2, dash: "dash" } },
      ],
      margin: { l: 80, r: 20, t: 30, b: 55 },
    }, {
      filename: `maintenance-effect-${e.action_id}`,
      csv: () => ({ columns: ["km_from", "index_before", "index_after"], rows: e.profile_km.map((k, i) => [k, e.profile_before[i], e.profile_after[i]]) }),
    });
  }

  async function drawWebhooks() {
    const me = await T.api.get("/auth/me").catch(() => null);
    if (!me || me.role !== "admin") return;
    $("webhooks-card").hidden = false;
    const [hooks, log] = await Promise.all([T.api.get("/webhooks"), T.api.get("/webhooks/deliveries", { limit: 20 })]);
    $("webhooks-body").innerHTML = hooks.items.length ? hooks.items.map((h) => `<tr data-hook="${h.id}"><td>${h.id}</td><td>${T.esc(h.url)}</td>
      <td>${T.esc(h.description || "")}</td><td>${h.active ? "yes" : "no"}</td><td class="num">${h.pending}</td><td class="num">${h.failed}</td>
      <td><button class="btn small" type="button" data-act="ping">Test</button> <button class="btn small danger" type="button" data-act="delete">Delete</button></td></tr>`).join("")
      : `<tr><td colspan="7" class="muted">No webhook yet: alerts of new flags go nowhere.</td></tr>`;
    $("deliveries-body").innerHTML = log.items.length ? log.items.map((d) => `<tr><td>${d.id}</td><td>${d.webhook_id}</td><td>${T.esc(d.event)}</td>
      <td>${d.run_id ?? "–"}</td><td>${T.esc(d.status)}</td><td class="num">${d.attempts}</td>
      <td>${d.last_status_code ? "HTTP " + d.last_status_code : T.esc((d.last_error || "–").slice(0, 60))}</td><td>${T.datetime(d.created_at)}</td></tr>`).join("")
      : `<tr><td colspan="8" class="muted">No deliveries yet.</td></tr>`;
  }

  async function show() {
    T.banner(null);
    const { line_id } = current();
    const line = lines.find((l) => `${l.line_id}\u0001${l.track}` === $("cond-line").value);
    $("cond-info").textContent = line ? `${line.n_runs} runs, ${T.date(line.first_run)} – ${T.date(line.last_run)}, km ${T.fmt(line.km_min, 2)}–${T.fmt(line.km_max, 2)}` : "";
    if (!line_id) return;
    await drawHeatmap();
    const wl = await drawWorklist();
    if (!$("cond-trend-km").value) {
      const top = wl && wl.items[0];
      $("cond-trend-km").value = top ? (top.km_from + 0.0005).toFixed(3) : ((line.km_min + line.km_max) / 2).toFixed(3);
      $("cond-trend-seg").value = top ? String(top.segment_m) : String(T.boot.overview_segment_m);
    }
    await drawTrend();
    await drawActions();
  }

  async function loadClasses() {
    const { line_id, track } = current();
    const sel = $("cond-class");
    const res = await T.api.optional("/reference/superstructure", { line_id, track }).catch(() => null);
    const types = [...new Set(((res && res.items) || []).map((s) => s.type))].sort();
    sel.innerHTML = `<option value="">all classes</option>` + types.map((t) => `<option value="${T.esc(t)}">${T.esc(t)}</option>`).join("");
  }

  $("cond-controls").addEventListener("submit", (ev) => { ev.preventDefault(); show().catch((e) => T.banner(`Could not load the condition: ${e.detail || e.message}`)); });
  $("cond-line").addEventListener("change", async () => { $("cond-trend-km").value = ""; await loadClasses(); });
  $("cond-trend-show").addEventListener("click", () => drawTrend().catch((e) => T.banner(`Trend: ${e.detail || e.message}`)));
  $("worklist-body").addEventListener("click", (ev) => {
    const btn = ev.target.closest("button[data-act='trend']");
    if (!btn) return;
    const row = btn.closest("tr");
    $("cond-trend-km").value = (parseFloat(row.dataset.km) + 0.0005).toFixed(3);
    $("cond-trend-seg").value = row.dataset.seg;
    drawTrend().catch((e) => T.banner(`Trend: ${e.detail || e.message}`));
  });
  $("actions-body").addEventListener("click", (ev) => {
    const row = ev.target.closest("tr[data-action]");
    if (row) drawEffect(row.dataset.action).catch((e) => T.banner(`Maintenance effect: ${e.detail || e.message}`));
  });
  $("webhook-form").addEventListener("submit", async (ev) => {
    ev.preventDefault();
    try {
      const h = await T.api.post("/webhooks", { url: $("webhook-url").value, description: $("webhook-desc").value || null });
      $("webhook-secret").textContent = `Signing secret of webhook ${h.id} (shown once): ${h.secret}`;
      $("webhook-url").value = "";
      await drawWebhooks();
    } catch (e) { T.banner(`Webhook not added (HTTP ${e.status}): ${e.detail}`); }
  });
  $("webhooks-body").addEventListener("click", async (ev) => {
    const btn = ev.target.closest("button[data-act]");
    if (!btn) return;
    const id = btn.closest("tr").dataset.hook;
    try {
      if (btn.dataset.act === "delete") await T.api.del(`/webhooks/${id}`);
      else await T.api.post(`/webhooks/${id}/test`);
      await drawWebhooks();
    } catch (e) { T.banner(`Webhook ${id}: ${e.detail || e.message}`); }
  });

  (async () => {
    try {
      $("cond-wheel").innerHTML += T.WHEELS.map((w) => `<option value="${w}">${T.wheelLabel(w)}</option>`).join("");
      lines = (await T.api.get("/condition/lines")).items;
      if (!lines.length) {
        for (const id of ["cond-heatmap", "cond-trend", "cond-effect"]) T.emptyState(id, "No runs in the condition store yet.",
          "<p>Processed runs with a line id appear here; <code>trackvkf simulate-fleet</code> writes a year of generated runs.</p>");
      } else {
        const best = lines.reduce((a, b) => (b.n_runs > a.n_runs ? b : a));
        $("cond-line").innerHTML = lines.map((l) => `<option value="${T.esc(l.line_id)}\u0001${T.esc(l.track)}">line ${T.esc(l.line_id)} / track ${T.esc(l.track)} (${l.n_runs} runs)</option>`).join("");
        $("cond-line").value = `${best.line_id}\u0001${best.track}`;
        await loadClasses();
        await show();
      }
      await drawWebhooks();
    } catch (e) {
      T.banner(`Could not load the condition page: ${e.detail || e.message}`);
    }
    T.ready();
  })();
})();
