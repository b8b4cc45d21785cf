/* Condition: an exception report of a line. The section classes along the line (A … E per 200 m,
 * the length per class now and a year before), the places (the work list: tier, extent, peak,
 * trend with its interval, time to the next tier, status, first seen, linked actions, assets) with
 * filters by tier and status, a place's history (observations over runs, events, status history,
 * maintenance in the runs' span) and its status workflow (engineers; viewers read it), then the
 * store's heat map of ln A, a segment's trend, the maintenance actions with their before/after
 * and (admins) the webhooks. Places and sections show the stiffness index ln(A/A_ref(class, v));
 * the heat map and a segment's trend the stored condition index ln A. Every number comes from
 * /api/v1/condition/… and /api/v1/assets. */
(function () {
  "use strict";
  const T = window.trackvkf;
  let lines = [], heat = null, trendData = null, effect = null, me = null, placeId = null, placeList = null;
  // answers can arrive out of order (a filter clicked twice, a place opened while another loads):
  // only the newest request of each view is drawn
  let placesSeq = 0, placeSeq = 0;
  const $ = (id) => document.getElementById(id);
  const TIER_COLORS = { watch: "#607d8b", alert: "#d49b00", intervention: "#e65100", immediate: "#c62828" };
  const CLASS_COLORS = { A: "#2e7d32", B: "#8bc34a", C: "#e6c619", D: "#fb8c00", E: "#c62828", "": "#cfd8dc" };
  const CLASS_MEANING = {
    A: "best fifth of healthy track", B: "typical healthy track", C: "the rest of healthy track",
    D: "beyond anything healthy measured", E: "reaches a place's alert limit", "": "not enough data",
  };

  function current() {
    const [line_id, track] = ($("cond-line").value || "\u0001").split("\u0001");
    return { line_id, track };
  }
  function indexLabel(name) { return name === "ln_amplitude" ? "Condition index ln(A / 1 m/s²) (ln units)" : `Index ${name} (ln units)`; }
  function pct(v, digits) { return v === null || v === undefined ? "–" : `${v > 0 ? "+" : ""}${T.fmt(v, digits ?? 1)}`; }
  function qs(params) {
    const u = new URLSearchParams();
    for (const [k, v] of Object.entries(params)) {
      if (Array.isArray(v)) v.forEach((x) => u.append(k, x));
      else if (v !== undefined && v !== null && v !== "") u.set(k, v);
    }
    return u.toString();
  }
  function tierBadge(t) { return `<span class="tier tier-${T.esc(t)}">${T.esc(t)}</span>`; }
  function canEdit() { return !!me && (me.role === "engineer" || me.role === "admin"); }
  function mapLink(runId, a, b) { return `/runs/${runId}?km_from=${(a - 0.05).toFixed(3)}&km_to=${(b + 0.05).toFixed(3)}`; }

  /* ---------------- section classes ---------------- */
  async function drawSections() {
    const el = $("cond-sections");
    const { line_id, track } = current();
    $("report-pdf").href = `${T.boot.api}/condition/report.pdf?${new URLSearchParams({ line_id, track })}`;
    const s = await T.api.get("/condition/sections", { line_id, track });
    $("sections-sub").textContent = `(per ${T.fmt(s.section_m, 0)} m, run of ${T.date(s.run_time)})`;
    $("sections-info").textContent = `class from the rms of the index over a section: A ≤ ${s.limits.map((x) => T.fmt(x, 2)).join(" < B ≤ ").replace(/ < B ≤ (\S+) < B ≤ (\S+) < B ≤ (\S+)$/, " < B ≤ $1 < C ≤ $2 < D ≤ $3 < E")}`;
    /* the railway's class scheme (TRACKVKF_PLACES_CLASS_SCHEME; default A … E): one trace per class */
    const groups = s.scheme.classes.concat([{ code: "", name: "no class", colour: CLASS_COLORS[""], of: [""] }]);
    const traces = groups.map((g) => {
      const part = s.sections.filter((x) => x.scheme_class === g.code);
      return {
        type: "bar", orientation: "v", name: g.name, x: part.map((x) => (x.km_from + x.km_to) / 2),
        y: part.map(() => 1), width: part.map((x) => (x.km_to - x.km_from) * 0.98), marker: { color: g.colour },
        customdata: part.map((x) => [x.km_from, x.km_to, x.level, x.spread, x.rms, Math.round(100 * x.fill), x.class || "–"]),
        hovertemplate: `${T.esc(g.name)} (class %{customdata[6]})<br>km %{customdata[0]:.2f}–%{customdata[1]:.2f}<br>rms %{customdata[4]:.3f}, level %{customdata[2]:.3f}, spread %{customdata[3]:.3f}<br>data %{customdata[5]} %<extra></extra>`,
      };
    }).filter((t) => t.x.length);
    if (!s.sections.length) { T.emptyState(el, "No section with data.", ""); return s; }
    await T.plot(el, traces, {
      barmode: "overlay", bargap: 0, showlegend: true,
      xaxis: T.axis("Track position (km)", { tickformat: ".1f", range: [s.sections[0].km_from, s.sections[s.sections.length - 1].km_to] }),
      yaxis: { visible: false, range: [0, 1], fixedrange: true },
      margin: { l: 20, r: 20, t: 30, b: 50 },
    }, {
      filename: `section-classes-${line_id}`,
      csv: () => ({ columns: ["km_from", "km_to", "class", "scheme_class", "level", "spread", "rms", "fill"],
                    rows: s.sections.map((x) => [x.km_from, x.km_to, x.class, x.scheme_class, x.level, x.spread, x.rms, x.fill]) }),
    });
    const old = s.length_by_scheme_class_year_ago;
    $("class-lengths-scheme").textContent = s.scheme.name;
    $("class-lengths-body").innerHTML = groups.map((g) => {
      const now = (s.length_by_scheme_class[g.code] || 0) / 1000, before = old ? (old[g.code] || 0) / 1000 : null;
      if (!g.code && !now && !before) return "";
      const meaning = g.of.map((c) => (c ? `${c}: ` : "") + CLASS_MEANING[c]).join("; ");
      return `<tr><td><span class="swatch" style="background:${g.colour}"></span> ${T.esc(g.name)}</td>
        <td class="num">${T.fmt(now, 2)}</td><td class="num">${before === null ? "–" : T.fmt(before, 2)}</td>
        <td class="num">${before === null ? "–" : pct(now - before, 2)}</td><td class="muted">${meaning}</td></tr>`;
    }).join("") + (old ? "" : `<tr><td colspan="5" class="muted">No run of this line a year or more before the newest: no change over the year yet.</td></tr>`);
    return s;
  }

  /* ---------------- places (work list) ---------------- */
  function checked(name) { return [...document.querySelectorAll(`#places-filter input[name='${name}']:checked`)].map((x) => x.value); }

  // a rate of the amplitude, per cent a year, from its ln rate (expm1: −1 ln unit a year is −63 %, never "−100 %")
  function ampRate(ln) { return 100 * Math.expm1(ln); }
  function trendText(p) {
    if (p.rate_per_year === null) return `<span class="muted">${T.esc(p.tendency || "–")}</span>`;
    // the rate is of the severity (direction · index, ln units a year); shown as the amplitude's change a year
    const d = p.direction === "soft" ? -1 : 1;
    const r = (v) => { const a = ampRate(d * v); return a > 999 ? "> +999 %" : `${pct(a, 0)} %`; };
    const arrow = { growing: "↗", shrinking: "↘", stable: "→" }[p.tendency] || "";
    const [lo, hi] = d > 0 ? [p.rate_low, p.rate_high] : [p.rate_high, p.rate_low];
    const iv = lo !== null && hi !== null ? ` <span class="muted">(${r(lo)} … ${r(hi)})</span>` : "";
    return `<span title="severity ${pct(p.rate_per_year, 2)} ln units a year">${arrow} ${T.esc(p.tendency)}: amplitude ${r(p.rate_per_year)} a year</span>${iv}`;
  }
  function limitText(p) {
    if (!p.next_tier) return `<span class="muted">top tier</span>`;
    if (p.days_to_next_tier === null) return `<span class="muted">no significant trend towards ${T.esc(p.next_tier)}</span>`;
    return `≈ ${T.fmt(p.days_to_next_tier, 0)} d to ${T.esc(p.next_tier)} <span class="muted">(${T.date(p.projected_date)})</span>`;
  }
  function peakText(p) {
    // the stated 1-sigma of the peak in per cent (delta method: 100 · sd · e^peak); none where not stated
    const sd = p.peak_sd === null || p.peak_sd === undefined ? "" :
      ` <span class="muted" title="stated 1-σ of the peak (roughness, noise)">± ${T.fmt(100 * p.peak_sd * Math.exp(p.peak), 0)} %</span>`;
    // stiffer / softer only where the place was read fast enough for the amplitude to rank stiffness (API: reading)
    const words = p.reading || (p.direction === "soft" ? "lower amplitude" : "higher amplitude");
    const speed = p.speed_kmh === null || p.speed_kmh === undefined ? "" : `, read at ${T.fmt(p.speed_kmh, 0)} km/h`;
    return `<span title="index ${T.fmt(p.peak, 3)} at km ${T.fmt(p.peak_km, 3)}${speed}">${pct(p.peak_percent, 0)} %${sd} ${p.direction === "soft" ? "▼" : "▲"} ${T.esc(words)}</span>`;
  }
  function confirmText(p) {
    // a new place: found by the newest run, on the list at once, confirmed (and alerted) by the next run
    return p.confirmed === false ? `<br><span class="badge unconfirmed" title="found by one run">new, to be confirmed by the next run</span>` : "";
  }
  function assetsText(p) {
    const list = (p.assets || []).map((a) => `${T.esc(a.type.replace(/_/g, " "))}${a.name ? ` <span class="muted">${T.esc(a.name)}</span>` : ""}`).join(", ");
    const muted = p.muted ? ` <span class="badge muted-badge" title="${T.esc(p.muted_reason || "")}">muted</span>` : "";
    return (list || `<span class="muted">–</span>`) + muted;
  }

  async function drawPlaces() {
    const body = $("places-body");
    const { line_id, track } = current();
    const params = { line_id, track, tier: checked("tier"), status: checked("status"),
                     include_closed: $("include-inactive").checked ? "true" : undefined };
    const q = qs(params);
    $("places-csv").href = `${T.boot.api}/condition/places.csv?${q}&limit=1000`;
    $("places-geojson").href = `${T.boot.api}/condition/places.geojson?${q}&limit=1000`;
    if (!params.tier.length || !params.status.length) {
      placesSeq++;
      placeList = { items: [], total: 0 };
      body.innerHTML = `<tr><td colspan="12" class="muted">Choose at least one tier and one status.</td></tr>`;
      $("places-info").textContent = "";
      return placeList;
    }
    const mine = ++placesSeq;
    const res = await T.api.get(`/condition/places?${q}&limit=200`);
    if (mine !== placesSeq) return res;  // a newer filter is on its way
    placeList = res;
    $("places-info").textContent = `${res.total} place${res.total === 1 ? "" : "s"}` + (res.total > res.items.length ? `, first ${res.items.length}` : "");
    if (!res.items.length) {
      body.innerHTML = `<tr><td colspan="12" class="muted">No place with these tiers and statuses.</td></tr>`;
      return res;
    }
    body.innerHTML = res.items.map((p, i) => `<tr data-place="${p.id}" class="${p.id === placeId ? "selected" : ""}${p.muted ? " is-muted" : ""}">
      <td class="num">${i + 1}</td><td>${tierBadge(p.tier)}${confirmText(p)}</td>
      <td title="place ${p.id}">${p.km_from.toFixed(3)}–${p.km_to.toFixed(3)}<br><span class="muted">${T.fmt(p.length_m, 0)} m</span></td>
      <td class="num nowrap">${peakText(p)}</td><td class="wrap">${trendText(p)}</td><td class="wrap">${limitText(p)}</td>
      <td><span class="status status-${T.esc(p.status)}">${T.esc(p.status.replace("_", " "))}</span></td>
      <td>${T.date(p.first_seen)}</td><td class="num" title="runs confirming">${p.runs_confirming}</td>
      <td class="wrap">${p.actions.length ? p.actions.map((a) => `${T.esc(a.kind)} ${T.date(a.date)}`).join(", ") : `<span class="muted">–</span>`}</td>
      <td class="wrap">${assetsText(p)}</td>
      <td><button class="btn small" type="button" data-act="history">History</button>
        <a class="btn small" href="${mapLink(p.last_run_id, p.km_from, p.km_to)}">Map</a></td></tr>`).join("");
    return res;
  }

  /* ---------------- a place's history ---------------- */
  async function drawPlace(id) {
    placeId = Number(id);
    for (const tr of document.querySelectorAll("#places-body tr[data-place]")) tr.classList.toggle("selected", Number(tr.dataset.place) === placeId);
    const mine = ++placeSeq;
    const p = await T.api.get(`/condition/places/${placeId}`);
    if (mine !== placeSeq) return p;  // another place (or a newer state of this one) is on its way
    $("place-title").innerHTML = `Place ${p.id}: km ${p.km_from.toFixed(3)}–${p.km_to.toFixed(3)} ${tierBadge(p.tier)}`;
    const link = $("place-map");
    link.href = mapLink(p.last_run_id, p.km_from, p.km_to);
    link.hidden = false;
    const kv = [
      ["Action", T.esc(p.action)], ["Peak", `${peakText(p)} <span class="muted">(index ${T.fmt(p.peak, 3)})</span>`],
      ["Evidence", T.esc(p.evidence.join(", ") || "–")], ["Wheels", T.esc(p.wheels.join(", ") || "–")],
      ["Trend per year (95 %)", trendText(p)], ["Time to next tier", limitText(p)],
      ["First seen / last confirmed", `${T.date(p.first_seen)} / ${T.date(p.last_confirmed)}`],
      ["Runs confirming", String(p.runs_confirming) + (p.active ? "" : " <span class='muted'>(not seen lately)</span>") + confirmText(p)],
      ["Status", `<span class="status status-${T.esc(p.status)}">${T.esc(p.status.replace("_", " "))}</span>` + (p.status_by ? ` <span class="muted">by ${T.esc(p.status_by)} ${T.date(p.status_at)}</span>` : "")],
      ["Assets", assetsText(p)], ["Method version", `<span class="muted">${T.esc(p.method_version || "–")}</span>`],
    ];
    $("place-kv").innerHTML = kv.map(([k, v]) => `<div><span>${k}</span><b>${v}</b></div>`).join("");
    await drawPlaceHistory(p);
    $("place-events-body").innerHTML = p.events.length ? p.events.map((e) => `<tr><td>${T.date(e.time)}</td><td>${T.esc(e.kind.replace("_", " "))}</td>
      <td>${e.run_id ?? "–"}</td><td>${e.old_tier && e.new_tier && e.old_tier !== e.new_tier ? `${tierBadge(e.old_tier)} → ${tierBadge(e.new_tier)}` : e.new_tier || e.old_tier ? tierBadge(e.new_tier || e.old_tier) : "–"}</td></tr>`).join("")
      : `<tr><td colspan="4" class="muted">No events.</td></tr>`;
    $("place-maint-body").innerHTML = p.maintenance.length ? p.maintenance.map((m) => `<tr><td>${T.date(m.date)}</td><td>${T.esc(m.kind || m.type)}</td>
      <td>${T.fmt(m.km_from, 3)}–${T.fmt(m.km_to, 3)}</td></tr>`).join("")
      : `<tr><td colspan="3" class="muted">No maintenance action over this place within its runs' span.</td></tr>`;
    $("place-status-body").innerHTML = p.status_history.length ? p.status_history.map((h) => `<tr><td>${T.datetime(h.at)}</td><td>${T.esc(h.by)}</td>
      <td>${T.esc(h.old.replace("_", " "))} → <b>${T.esc(h.new.replace("_", " "))}</b></td><td class="wrap">${T.esc(h.comment)}</td></tr>`).join("")
      : `<tr><td colspan="4" class="muted">Status ${T.esc(p.status)} since the place was found; no change yet.</td></tr>`;
    $("status-form").hidden = !canEdit();
    $("status-readonly").hidden = canEdit();
    $("status-new").value = p.status;
    return p;
  }

  async function drawPlaceHistory(p) {
    const el = $("place-history");
    const obs = p.observations;
    if (!obs.length) { T.emptyState(el, "No observation of this place.", ""); return; }
    const x = obs.map((o) => o.run_time);
    const traces = [
      { type: "scatter", mode: "lines+markers", name: "index at the place (ln units)", x, y: obs.map((o) => o.level),
        line: { color: "#1d2733", width: 2 }, marker: { size: 9, color: obs.map((o) => TIER_COLORS[o.tier] || "#999") },
        customdata: obs.map((o) => [o.run_id, o.tier, o.speed_kmh, o.km_from, o.km_to]),
        hovertemplate: "%{x|%Y-%m-%d} run %{customdata[0]}<br>index %{y:.3f} (%{customdata[1]})<br>km %{customdata[3]:.3f}–%{customdata[4]:.3f}, %{customdata[2]:.0f} km/h<extra></extra>" },
    ];
    const withChange = obs.filter((o) => o.change !== null);
    if (withChange.length) traces.push({ type: "scatter", mode: "markers", name: "change against its baseline", x: withChange.map((o) => o.run_time),
      y: withChange.map((o) => o.change), marker: { symbol: "diamond-open", size: 8, color: "#5d6b7a" },
      hovertemplate: "%{x|%Y-%m-%d}: change %{y:.3f}<extra></extra>" });
    const shapes = [], annotations = [];
    if (p.next_limit !== null && p.next_tier) {
      const lim = (p.direction === "soft" ? -1 : 1) * Math.abs(p.next_limit);
      shapes.push({ type: "line", xref: "paper", x0: 0, x1: 1, yref: "y", y0: lim, y1: lim, line: { color: TIER_COLORS[p.next_tier], width: 1.5, dash: "dot" } });
      annotations.push({ xref: "paper", x: 1, y: lim, yanchor: "bottom", xanchor: "right", showarrow: false, text: `${p.next_tier} limit`, font: { size: 11, color: TIER_COLORS[p.next_tier] } });
    }
    for (const m of p.maintenance) {
      shapes.push({ type: "line", xref: "x", yref: "paper", x0: m.date, x1: m.date, y0: 0, y1: 1, line: { color: "#2e7d32", width: 2, dash: "dash" } });
      annotations.push({ x: m.date, y: 1, xref: "x", yref: "paper", yanchor: "bottom", showarrow: false, text: T.esc(m.kind || m.type), font: { size: 11, color: "#2e7d32" } });
    }
    await T.plot(el, traces, {
      xaxis: T.dateAxis ? T.dateAxis("Run date", x, {}, 30) : T.axis("Run date", { type: "date" }),
      yaxis: T.axis("Stiffness index ln(A / A_ref) (ln units)", { zeroline: true }),
      shapes, annotations, margin: { l: 80, r: 30, t: 30, b: 55 },
    }, {
      filename: `place-${p.id}-history`,
      csv: () => ({ columns: ["run_id", "run_time", "speed_kmh", "level", "change", "tier", "km_from", "km_to", "method_version"],
                    rows: obs.map((o) => [o.run_id, o.run_time, o.speed_kmh, o.level, o.change, o.tier, o.km_from, o.km_to, o.method_version]) }),
    });
  }

  async function drawHeatmap() {
    const el = $("cond-heatmap");
    const { line_id, track } = current();
    heat = await T.api.get("/condition/heatmap", { line_id, track, wheel: $("cond-wheel").value });
    if (!heat.runs.length || !heat.km.length) { T.emptyState(el, "No runs of this line in the condition store.", ""); return; }
    const x = heat.km.map((k) => k + heat.segment_m / 2000);
    const y = heat.runs.map((r) => r.start_time);
    const fx = heat.flagged.map(([i, j]) => x[j]), fy = heat.flagged.map(([i]) => y[i]);
    await T.plot(el, [
      { type: "heatmap", x, y, z: heat.matrix, colorscale: "YlOrRd", reversescale: true, hoverongaps: false, name: "index",
        colorbar: { title: { text: "ln A", side: "right" }, thickness: 14 },
        hovertemplate: "%{y|%Y-%m-%d}<br>km %{x:.2f}<br>ln A %{z:.3f}<extra></extra>" },
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
      y: t.points.map((p) => { const r = p.wheels.find((q) => q.wheel === w); return r ? r.condition_index : null; }),
      hovertemplate: `${T.wheelLabel(w)} %{x|%Y-%m-%d}: %{y:.3f}<extra></extra>`,
    })).filter((tr) => tr.y.some((v) => v !== null));
    traces.push({ type: "scatter", mode: "lines+markers", name: "relative to its surroundings (right axis)", x, yaxis: "y2",
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
      xaxis: T.axis("Run date", { type: "date" }), yaxis: T.axis(indexLabel(heat ? heat.condition_index : "ln_amplitude")),
      yaxis2: T.axis("Relative to the surroundings (log units)", { overlaying: "y", side: "right", showgrid: false }),
      shapes, annotations, margin: { l: 80, r: 80, t: 30, b: 55 },
    }, {
      filename: `condition-trend-km${t.segment_km[0].toFixed(3)}`,
      csv: () => {
        const rows = [];
        for (const p of t.points) for (const w of p.wheels) rows.push([p.run_id, p.start_time, t.segment_km[0], t.segment_km[1], w.wheel, w.condition_index, p.relative, w.amp_mean, w.speed_kmh, w.change_z, p.flagged ? 1 : 0]);
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
      <td class="num">${a.n_runs_before} / ${a.n_runs_after}</td><td class="num">${pct(a.recovery_pct)}${a.rail_surface ? `<br><span class="muted" title="the rail surface's response across the work; the support's change is read against the new surface's own baseline">rail surface ${pct(a.rail_surface_change_pct)}</span>` : ""}</td>
      <td class="num" title="${a.slope_after_per_year === null ? "" : `${pct(a.slope_after_per_year, 2)} ln units a year`}">${a.slope_after_per_year === null ? "–" : pct(ampRate(a.slope_after_per_year))}</td>
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
      { type: "scatter", mode: "markers", name: "per run", x: e.series.map((p) => p.start_time), y: e.series.map((p) => p.condition_index),
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
    await drawSections();
    const res = await drawPlaces();
    const top = res.items[0];
    if (top && !(placeList.items.some((p) => p.id === placeId))) placeId = top.id;
    if (placeId) await drawPlace(placeId);
    else T.emptyState("place-history", "No place on this line.", "<p>Places appear once two runs find the same exceedance (at once at the intervention tier).</p>");
    await drawHeatmap();
    if (!$("cond-trend-km").value) {
      $("cond-trend-km").value = top ? top.peak_km.toFixed(3) : ((line.km_min + line.km_max) / 2).toFixed(3);
      $("cond-trend-seg").value = top ? "10" : String(T.boot.overview_segment_m);
    }
    await drawTrend();
    await drawActions();
  }

  const fail = (what) => (e) => T.banner(`${what}: ${e.detail || e.message}`);
  $("cond-controls").addEventListener("submit", (ev) => { ev.preventDefault(); show().catch(fail("Could not load the condition")); });
  $("cond-line").addEventListener("change", () => { $("cond-trend-km").value = ""; placeId = null; });
  $("places-filter").addEventListener("change", () => drawPlaces().catch(fail("Places")));
  $("cond-wheel").addEventListener("change", () => drawHeatmap().catch(fail("Heat map")));
  $("cond-trend-show").addEventListener("click", () => drawTrend().catch(fail("Trend")));
  $("places-body").addEventListener("click", (ev) => {
    const btn = ev.target.closest("button[data-act='history']");
    if (!btn) return;
    const row = btn.closest("tr");
    drawPlace(row.dataset.place).then((p) => {
      $("cond-trend-km").value = p.peak_km.toFixed(3);
      $("cond-trend-seg").value = "10";
      $("place-card").scrollIntoView({ behavior: "smooth", block: "start" });
      return drawTrend();
    }).catch(fail("Place"));
  });
  $("status-form").addEventListener("submit", async (ev) => {
    ev.preventDefault();
    const comment = $("status-comment").value.trim();
    if (!comment) { T.banner("A status change needs a comment: what was decided and why."); $("status-comment").focus(); return; }
    try {
      await T.api.patch(`/condition/places/${placeId}/status`, { status: $("status-new").value, comment });
      $("status-comment").value = "";
      T.banner(`Place ${placeId}: status set to ${$("status-new").value.replace("_", " ")}.`, "ok");
      await drawPlaces();
      await drawPlace(placeId);
    } catch (e) { T.banner(`Status not changed (HTTP ${e.status}): ${e.detail}`); }
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
      me = await T.api.get("/auth/me").catch(() => null);
      lines = (await T.api.get("/condition/lines")).items;
      if (!lines.length) {
        for (const id of ["cond-sections", "place-history", "cond-heatmap", "cond-trend", "cond-effect"]) T.emptyState(id, "No runs in the condition store yet.",
          "<p>Processed runs with a line id appear here: <code>./scripts/demo.sh</code> processes a short history of a line.</p>");
        $("places-body").innerHTML = `<tr><td colspan="12" class="muted">No places yet.</td></tr>`;
      } else {
        const best = lines.reduce((a, b) => (b.n_runs > a.n_runs ? b : a));
        $("cond-line").innerHTML = lines.map((l) => `<option value="${T.esc(l.line_id)}\u0001${T.esc(l.track)}">line ${T.esc(l.line_id)} / track ${T.esc(l.track)} (${l.n_runs} runs)</option>`).join("");
        $("cond-line").value = `${best.line_id}\u0001${best.track}`;
        const want = T.param("place");
        if (want) placeId = Number(want);
        await show();
      }
      await drawWebhooks();
    } catch (e) {
      T.banner(`Could not load the condition page: ${e.detail || e.message}`);
    }
    T.ready();
  })();
})();
