/* Stiffness map of one run: the stiffness index ln(A / A_ref(class, v)) along km for the four
 * wheels (raw sleeper-passage amplitude one click away, and with it the step estimate: its levels
 * between change points, one named trace per wheel), decimated on the server per zoom level,
 * speed on a second axis, the reference curves it used stated under the plot, superstructure
 * sections and maintenance actions shaded when the reference data exist, known discontinuities
 * (assets: switches, bridges, joints, ...) marked with their type. */
(function () {
  "use strict";
  const T = window.trackvkf;
  const runId = T.boot.run_id;
  const el = document.getElementById("stiffness-plot");
  // superstructure shading: the colour follows the type's name (not the order in which types
  // appear in the visible range), so a type keeps its colour when zooming and across runs
  const SECTION_COLORS = ["rgba(31,95,168,0.10)", "rgba(224,123,0,0.12)", "rgba(46,139,87,0.11)", "rgba(142,68,173,0.10)",
    "rgba(0,131,143,0.11)", "rgba(176,137,0,0.13)", "rgba(93,64,55,0.10)", "rgba(120,144,156,0.14)"];
  const MAINT_COLOR = "rgba(198,40,40,0.55)";
  const ASSET_COLOR = "rgba(55,71,79,0.7)";
  function sectionColor(type) {
    let h = 0;
    for (const ch of String(type)) h = (h * 31 + ch.codePointAt(0)) >>> 0;
    return SECTION_COLORS[h % SECTION_COLORS.length];
  }
  let run = null, wheels = [], full = null, current = null, data = {}, shapes = [], annotations = [];
  let busy = false, pending = null, seq = 0;
  const COLUMNS = "sleeper_amp,speed_mean,sleeper_force_amp,sleeper_step"; // what the map draws and exports
  let reference = null; // the reference curves the index used (from the profile answer)

  function maxPoints() { return Math.max(600, Math.min(4000, Math.round(2 * (el.clientWidth || 1200)))); }

  function runKm(r) {
    const len = (r.summary.distance_m || 0) / 1000;
    const end = r.km_increasing === false ? r.km_start - len : r.km_start + len;
    return [Math.min(r.km_start, end), Math.max(r.km_start, end)];
  }

  function meta(r) {
    const job = r.latest_job || {};
    const s = job.settings || {};
    const [a, b] = runKm(r);
    // [label, value, data]: data (ids, names of the recording) are shown as they are, not translated
    const items = [
      [T._("Vehicle"), r.vehicle_id, true], [T._("Line / track"), `${r.line_id} / ${r.track}`, true], [T._("Direction"), r.direction, true],
      [T._("Start"), T.datetime(r.start_time)], ["km", `${T.fmt(a)} – ${T.fmt(b)}`],
      [T._("Speed"), `${T.fmt(r.summary.speed_min_kmh || 0, 0)} – ${T.fmt(r.summary.speed_max_kmh || 0, 0)} km/h`],
      [T._("Sample rate"), `${T.fmt(r.summary.fs / 1000, 1)} kHz`],
      [T._("Job"), `${job.id ?? "–"} (${job.status ? T.jobStatus(job.status) : T._("none")})`],
      [T._("Bandwidth"), T._("{orders} orders · track resolution {m} m · q = {q}",
        { orders: s.bandwidth_orders ?? "–", m: s.track_resolution_m ?? "–", q: s.filter_order ?? "–" })],
      [T._("Wheel diameters"), Object.entries((r.metadata || {}).wheel_diameters || {}).map(([w, d]) => `${T.wheelLabel(w)} ${T.fmt(d, 3)} m`).join(", ")],
      [T._("File sha256"), (r.sha256 || "").slice(0, 16) + "…", true],
    ];
    document.getElementById("run-meta").innerHTML = items.map(([k, v, raw]) =>
      `<div><span>${T.esc(k)}</span><b${raw ? ' translate="no"' : ""}>${T.esc(v)}</b></div>`).join("");
    const warn = document.getElementById("run-warnings");
    const list = r.warnings || [];
    warn.hidden = list.length === 0;
    // the warnings were written when the file was read; the API answers them in the reader's language
    warn.innerHTML = list.length ? `<b>${T.esc(T._("Ingest warnings"))}</b><ul>` + list.map((w) => `<li>${T.esc(w)}</li>`).join("") + "</ul>" : "";
  }

  /* Shading and marks of the reference data in [a, b] km, and their legend below the plot:
   * one swatch per superstructure type, the maintenance mark with the action types. */
  async function loadReference(a, b) {
    shapes = []; annotations = [];
    const info = [], legend = [];
    const q = { line_id: run.line_id, track: run.track, km_from: a, km_to: b };
    { // superstructure sections: shading with a label
      const res = await T.api.optional("/reference/superstructure", q);
      const items = (res && res.items) || [];
      const types = new Map();
      for (const s of items) {
        types.set(s.type, s.details || "");
        shapes.push({ type: "rect", xref: "x", yref: "paper", x0: s.km_from, x1: s.km_to, y0: 0, y1: 1,
          fillcolor: sectionColor(s.type), line: { width: 0 }, layer: "below" });
        // the label sits in the middle of the section's visible part, so it stays on screen
        const lo = Math.max(s.km_from, a), hi = Math.min(s.km_to, b);
        if (hi > lo && (hi - lo) >= 0.04 * (b - a)) {
          annotations.push({ x: (lo + hi) / 2, y: 1, xref: "x", yref: "paper", yanchor: "bottom",
            text: T.esc(s.type), showarrow: false, font: { size: 11, color: "#5d6b7a" }, translate: false });
        }
      }
      for (const [type, details] of types) {
        legend.push(`<span class="swatch-item" title="${T.esc(details)}"><span class="swatch" style="background:${sectionColor(type)}"></span><span translate="no">${T.esc(type)}</span></span>`);
      }
      info.push(items.length ? T.ngettext("{n} superstructure section", "{n} superstructure sections", items.length) : T._("no superstructure data"));
    }
    { // maintenance actions: marks at the bottom
      const res = await T.api.optional("/reference/maintenance", q);
      const items = (res && res.items) || [];
      for (const m of items) {
        shapes.push({ type: "rect", xref: "x", yref: "paper", x0: m.km_from, x1: Math.max(m.km_to, m.km_from + 0.0005),
          y0: 0, y1: 0.04, fillcolor: MAINT_COLOR, line: { width: 0 } });
      }
      if (items.length) {
        const kinds = [...new Set(items.map((m) => T.label("maintenance type", m.type)))].sort().join(", ");
        legend.push(`<span class="swatch-item"><span class="swatch mark" style="background:${MAINT_COLOR}"></span>${T.esc(T._("maintenance action ({types}), mark at the bottom over its km range", { types: kinds }))}</span>`);
      }
      info.push(T.ngettext("{n} maintenance action", "{n} maintenance actions", items.length));
    }
    { // known discontinuities (assets): a dotted line at each, labelled with its type
      const res = await T.api.optional("/assets", { line_id: run.line_id, track: run.track });
      const items = ((res && res.items) || []).filter((x) => (x.km_to ?? x.km) >= a && x.km <= b);
      const label = items.length <= 40;
      for (const x of items) {
        const x1 = x.km_to ?? x.km;
        shapes.push(x1 > x.km
          ? { type: "rect", xref: "x", yref: "paper", x0: x.km, x1, y0: 0, y1: 1, fillcolor: ASSET_COLOR.replace("0.7", "0.10"), line: { width: 0 } }
          : { type: "line", xref: "x", yref: "paper", x0: x.km, x1: x.km, y0: 0, y1: 1, line: { color: ASSET_COLOR, width: 1, dash: "dot" } });
        if (label) {
          annotations.push({ x: (x.km + x1) / 2, y: 0.97, xref: "x", yref: "paper", yanchor: "top", showarrow: false,
            text: `◆ ${T.esc(T.label("asset type", x.type))}`, font: { size: 10, color: "#37474f" }, bgcolor: "rgba(255,255,255,0.75)",
            hovertext: `${T.esc(T.label("asset type", x.type))}${x.name ? " " + T.esc(x.name) : ""} · km ${T.fmt(x.km, 3)}${x1 > x.km ? "–" + T.fmt(x1, 3) : ""}` });
        }
      }
      if (items.length) {
        const kinds = [...new Set(items.map((x) => T.label("asset type", x.type)))].sort().join(", ");
        legend.push(`<span class="swatch-item"><span class="swatch asset"></span>${T.esc(T._("asset ({types}), dotted line at its km", { types: kinds }))}</span>`);
      }
      info.push(T.ngettext("{n} asset", "{n} assets", items.length));
    }
    document.getElementById("sections-info").textContent = info.join(" · ");
    const box = document.getElementById("map-legend");
    box.innerHTML = legend.length ? `<span class="muted">${T.esc(T._("Shading:"))}</span> ${legend.join("")}` : "";
    box.hidden = !legend.length;
  }

  async function fetchRange(a, b) {
    // in steps of 200 points: plots of about the same width ask the same question (server and browser caches)
    const mp = Math.ceil(maxPoints() / 200) * 200;
    const out = {};
    await Promise.all(wheels.map(async (w) => {
      out[w] = await T.api.profile(`/runs/${runId}/profile`, { wheel: w, km_from: a, km_to: b, max_points: mp, columns: COLUMNS, index: true });
    }));
    return out;
  }

  function showIndex() { return document.getElementById("map-value").value === "index"; }
  /* The amplitude with its step estimate (the levels between change points: a step's position and the
   * levels either side where the amplitude's own fluctuation hides them; docs/indicator.md). */
  function showSteps() { return document.getElementById("map-value").value === "steps"; }
  /* Whether the job stored the step estimate (false: processed before it was stored). */
  function stepsStored() { return wheels.length > 0 && data[wheels[0]].step_estimate_stored !== false; }

  function referenceText(ref) {
    if (!ref) return "";
    if (!ref.available) return T.esc(T._("No stiffness index: {reason}. Showing the raw amplitude.", { reason: ref.reason }));
    // the superstructure classes are the reference data's own names (not translated)
    const cls = (ref.classes || []).map((c) => {
      const [lo, hi] = c.speed_range_kmh || [];
      const range = lo == null ? T._("no speeds") : `${T.fmt(lo, 0)}–${T.fmt(hi, 0)} km/h`;
      const name = c.class ? `<span translate="no">${T.esc(c.class)}</span>` : T.esc(T._("line"));
      return `${name} (${T.esc(range)}, ${T.esc(T.ngettext("{n} run", "{n} runs", c.n_runs))}, ${T.esc(T.label("curve method", c.method))})`;
    }).join("; ");
    const text = T._("Index = ln(A / A_ref): 0 is a typical location of its superstructure class at the same speed, +0.1 = 10.5 % more amplitude. Reference curves of line {line} track {track} from runs {runs} (computed {when}, matched speed ±{tol} %): {classes}. Gaps: no reference passes at that speed, or near a change of superstructure.",
      { line: "\u0001L", track: "\u0001T", runs: (ref.run_ids || []).join(", "), when: T.datetime(ref.computed_at),
        tol: T.fmt(100 * ref.speed_tolerance, 0), classes: "\u0001C" });
    return T.esc(text).replace("\u0001L", `<span translate="no">${T.esc(ref.line_id)}</span>`)
      .replace("\u0001T", T.esc(ref.track)).replace("\u0001C", cls);
  }

  /* The value drawn of a row: the stiffness index or the raw amplitude. */
  function valueOf(r, index) { return index ? (r.stiffness_index ?? null) : r.sleeper_amp; }

  /* Wheels whose drawn values are the same along the whole range: the two wheels of an axle that
   * share the two-rail value (the sleeper-passage order of both rails). One trace stands for them. */
  function sameValues(a, b, index, steps) {
    const ra = data[a].rows, rb = data[b].rows;
    if (!ra.length || ra.length !== rb.length) return false;
    for (let i = 0; i < ra.length; i++) {
      if (ra[i].km !== rb[i].km) return false;
      // with the step estimate drawn, the two wheels share a trace only if they share that too
      for (const [x, y] of steps ? [[valueOf(ra[i], index), valueOf(rb[i], index)], [ra[i].sleeper_step ?? null, rb[i].sleeper_step ?? null]]
        : [[valueOf(ra[i], index), valueOf(rb[i], index)]]) {
        if (x === null || y === null ? x !== y : Math.abs(x - y) > 1e-9 * Math.max(1, Math.abs(x))) return false;
      }
    }
    return true;
  }

  /* One trace per wheel, or one per axle where its two wheels share the value (said in its name). */
  function wheelGroups(index, steps) {
    const groups = [], used = new Set();
    for (const w of wheels) {
      if (used.has(w)) continue;
      const mate = wheels.find((o) => o !== w && !used.has(o) && o.slice(0, -1) === w.slice(0, -1) && sameValues(w, o, index, steps));
      used.add(w);
      if (mate) { used.add(mate); groups.push([w, mate]); } else groups.push([w]);
    }
    return groups;
  }

  function groupName(group) {
    if (group.length === 1) return T.wheelName(group[0]);
    return T._("axle {axle}: {a} = {b} (both rails, one value)", { axle: group[0].slice(0, -1), a: T.wheelLabel(group[0]), b: T.wheelLabel(group[1]) });
  }

  function traces() {
    const tr = [];
    let speedSrc = null;
    const index = showIndex(), steps = showSteps() && stepsStored();
    const ampWord = T._("amplitude"), refWord = T._("reference"), speedWord = T._("speed"), indexWord = T._("stiffness index");
    const stepWord = T._("step estimate");
    for (const group of wheelGroups(index, steps)) {
      const w = group[0];
      const rows = data[w].rows;
      const label = group.map((g) => T.wheelLabel(g)).join(" = ");
      if (!speedSrc && rows.length) speedSrc = rows;
      tr.push(index ? {
        type: "scatter", mode: "lines", name: groupName(group), line: { color: T.wheelColor(w), width: 1.3 },
        x: rows.map((r) => r.km), y: rows.map((r) => valueOf(r, true)),
        customdata: rows.map((r) => [r.stiffness_index_se ?? NaN, r.sleeper_amp, r.reference_amp ?? NaN, (r.speed_mean ?? NaN) * 3.6]),
        hovertemplate: `${label}<br>km %{x:.4f}<br>${indexWord} %{y:.3f} ± %{customdata[0]:.3f}` +
          `<br>${ampWord} %{customdata[1]:.3f} m/s² (${refWord} %{customdata[2]:.3f})<br>${speedWord} %{customdata[3]:.1f} km/h<extra></extra>`,
      } : {
        type: "scatter", mode: "lines", name: groupName(group), line: { color: T.wheelColor(w), width: 1.3 },
        opacity: steps ? 0.45 : 1,
        x: rows.map((r) => r.km), y: rows.map((r) => r.sleeper_amp),
        customdata: rows.map((r) => (r.speed_mean ?? NaN) * 3.6),
        hovertemplate: `${label}<br>km %{x:.4f}<br>${ampWord} %{y:.3f} m/s²<br>${speedWord} %{customdata:.1f} km/h<extra></extra>`,
      });
      if (steps) {
        tr.push({
          type: "scatter", mode: "lines", name: T._("{wheel}: step estimate", { wheel: groupName(group) }),
          meta: "step-estimate", line: { color: T.wheelColor(w), width: 2.4, shape: "hv" },
          x: rows.map((r) => r.km), y: rows.map((r) => r.sleeper_step ?? null),
          hovertemplate: `${label}<br>km %{x:.4f}<br>${stepWord} %{y:.3f} m/s²<extra></extra>`,
        });
      }
    }
    if (speedSrc) {
      tr.push({
        type: "scatter", mode: "lines", name: speedWord, yaxis: "y2", line: { color: "#7f8c99", width: 1.2, dash: "dot" },
        x: speedSrc.map((r) => r.km), y: speedSrc.map((r) => (r.speed_mean ?? NaN) * 3.6),
        hovertemplate: `km %{x:.4f}<br>${speedWord} %{y:.1f} km/h<extra></extra>`,
      });
    }
    return tr;
  }

  async function draw(a, b) {
    const index = showIndex();
    const scale = index ? "linear" : document.getElementById("amp-scale").value;
    document.getElementById("amp-scale").disabled = index;
    document.getElementById("map-title").textContent = index ? T._("Stiffness index along the track")
      : showSteps() ? T._("Sleeper-passage amplitude and its step estimate along the track") : T._("Sleeper-passage amplitude along the track");
    document.getElementById("reference-info").innerHTML = index ? referenceText(reference)
      : showSteps() ? T.esc(stepsStored()
        ? T._("Step estimate: the amplitude's levels between change points, a step kept where it stands out by about four of its standard deviations. Read it for where a step lies and the levels either side; a short record with a steady ripple reads as stairs.")
        : T._("This job stored no step estimate: it was processed before the step estimate was stored with the profiles. Process the run again to see it."))
      : "";
    const tr = traces();
    const n = wheels.length ? data[wheels[0]].n_rows : 0;
    document.getElementById("map-info").textContent =
      T._("{n} points per wheel in {from}–{to} km (25 cm bins, peaks kept)", { n: n, from: T.fmt(a), to: T.fmt(b) });
    await T.plot(el, tr, {
      uirevision: "map",
      xaxis: T.axis(T._("Track position (km)"), { range: [a, b], tickformat: ".3f" }),
      yaxis: index ? T.axis(T._("Stiffness index ln(A / A_ref) (ln units)"), { zeroline: true })
        : T.axis(T._("Sleeper-passage amplitude (m/s²)"), { type: scale, rangemode: scale === "log" ? undefined : "tozero" }),
      yaxis2: T.axis(T._("Speed (km/h)"), { overlaying: "y", side: "right", showgrid: false, rangemode: "tozero", dtick: 20 }),
      margin: { l: 75, r: 75, t: 40, b: 60 },
      hovermode: "x unified",
      shapes, annotations,
    }, {
      filename: `run-${runId}-stiffness-map`,
      csv: () => {
        const rows = [];
        for (const w of wheels) for (const r of data[w].rows) {
          rows.push([w, r.km, r.sleeper_amp, (r.speed_mean ?? NaN) * 3.6, r.sleeper_force_amp,
            r.stiffness_index ?? NaN, r.stiffness_index_se ?? NaN, r.reference_amp ?? NaN, r.sleeper_step ?? NaN]);
        }
        return { columns: ["wheel", "km", "sleeper_amp_mps2", "speed_kmh", "sleeper_force_amp_kn",
          "stiffness_index", "stiffness_index_se", "reference_amp_mps2", "sleeper_step_mps2"], rows };
      },
    });
  }

  async function show(a, b) {
    if (busy) { pending = [a, b]; return; }
    busy = true;
    const my = ++seq;
    try {
      const got = await fetchRange(a, b);
      if (my !== seq) return;
      data = got; current = [a, b];
      reference = wheels.length ? got[wheels[0]].reference : null;
      if (reference && !reference.available && showIndex()) document.getElementById("map-value").value = "amplitude";
      document.getElementById("km-from").value = a.toFixed(3);
      document.getElementById("km-to").value = b.toFixed(3);
      await loadReference(a, b);
      await draw(a, b);
    } catch (e) {
      T.banner(T._("Could not load the profile: {detail}", { detail: e.detail || e.message }));
    } finally {
      busy = false;
      if (pending) { const p = pending; pending = null; show(p[0], p[1]); }
    }
  }

  let zoomTimer = null;
  function onRelayout(ev) {
    let a, b;
    if (ev["xaxis.autorange"]) { [a, b] = full; }
    else if (ev["xaxis.range[0]"] !== undefined) { a = +ev["xaxis.range[0]"]; b = +ev["xaxis.range[1]"]; }
    else if (ev["xaxis.range"]) { [a, b] = ev["xaxis.range"].map(Number); }
    else return;
    if (current && Math.abs(a - current[0]) < 1e-9 && Math.abs(b - current[1]) < 1e-9) return;
    clearTimeout(zoomTimer);
    zoomTimer = setTimeout(() => show(Math.max(a, full[0] - 0.01), Math.min(b, full[1] + 0.01)), 250);
  }

  document.getElementById("map-controls").addEventListener("submit", (ev) => {
    ev.preventDefault();
    const a = parseFloat(document.getElementById("km-from").value), b = parseFloat(document.getElementById("km-to").value);
    if (!(b > a)) { T.banner(T._("km to must be greater than km from.")); return; }
    T.banner(null);
    show(a, b);
  });
  document.getElementById("km-reset").addEventListener("click", () => show(full[0], full[1]));
  document.getElementById("amp-scale").addEventListener("change", () => current && draw(current[0], current[1]));
  document.getElementById("map-value").addEventListener("change", () => current && draw(current[0], current[1]));

  (async () => {
    try {
      run = await T.api.get(`/runs/${runId}`);
      meta(run);
      document.getElementById("run-subtitle").textContent = T._("stiffness map · {vehicle} on line {line} track {track}, {date}",
        { vehicle: run.vehicle_id, line: run.line_id, track: run.track, date: T.date(run.start_time) });
      if (run.vehicle_id) document.getElementById("wheels-link").href = `/wheels?vehicle_id=${encodeURIComponent(run.vehicle_id)}&run_id=${runId}`;
      const job = run.latest_job;
      if (!job || job.status !== "done") {
        // results of an earlier job may still exist: the profile answers 409 when there are none
      }
      wheels = T.WHEELS.filter((w) => run.summary.channels.includes("Z" + w));
      // the km extent of the stored profile comes with any profile answer (four rows here)
      const first = await T.api.get(`/runs/${runId}/profile`, { wheel: wheels[0], max_points: 4 });
      full = first.km_extent || runKm(run);
      const ka = T.param("km_from"), kb = T.param("km_to");
      await show(ka ? +ka : full[0], kb ? +kb : full[1]);
      el.on("plotly_relayout", onRelayout);
    } catch (e) {
      if (e.status === 409) T.emptyState(el, T._("No results yet"), `<p>${T.esc(e.detail)}. ${T.esc(T._("The map appears when the processing job is done."))}</p>`);
      else T.banner(T._("Could not load run {run}: {detail}", { run: runId, detail: e.detail || e.message }));
    }
    T.ready();
  })();
})();
