/* Shared plotting helpers: wheel colours, layout, PNG (Plotly modebar) and CSV downloads,
 * empty states, banner, formatting of numbers and dates in the page's locale (Plotly's too:
 * its buttons, month names and separators from the page's catalogue). */
(function () {
  "use strict";
  const T = window.trackvkf;
  const PLOTLY_LOCALE = T.catalogue.plotly;
  if (window.Plotly && PLOTLY_LOCALE && T.lang !== "en") {
    Plotly.register({ moduleType: "locale", name: T.lang, dictionary: PLOTLY_LOCALE.dictionary, format: PLOTLY_LOCALE.format });
  }
  const NUMBER = T.boot.number_format || { decimal: ".", thousands: "," };
  /* dates on axes and in hover labels in the locale's order (ISO in English) */
  const DATE_FMT = T.boot.date_order || "%Y-%m-%d";
  const WHEELS = ["11", "12", "41", "42"];
  const WHEEL_COLORS = { "11": "#1f5fa8", "12": "#e07b00", "41": "#2e8b57", "42": "#8e44ad" };
  /* each tier's colour on every page (the .tier-* badges of app.css) */
  const TIER_COLORS = { watch: "#607d8b", alert: "#d49b00", intervention: "#e65100", immediate: "#c62828" };
  const FONT = { family: '"DejaVu Sans", "Segoe UI", Roboto, Helvetica, Arial, sans-serif', size: 13, color: "#1d2733" };
  const csvProviders = new Map();

  function wheelId(w) { return String(w).replace(/^Z/, ""); }
  function wheelLabel(w) { return "Z" + wheelId(w); }
  function wheelColor(w) { return WHEEL_COLORS[wheelId(w)] || "#555"; }
  /* "Z11 · axle 1 right": channel name with axle and side (side 1 right, 2 left; docs/run-format.md). */
  function wheelName(w) {
    const id = wheelId(w);
    const axle = id.slice(0, -1), wheel = wheelLabel(id);
    if (id.slice(-1) === "1") return T._("{wheel} · axle {axle} right", { wheel, axle });
    if (id.slice(-1) === "2") return T._("{wheel} · axle {axle} left", { wheel, axle });
    return wheel;
  }

  function axis(title, extra) {
    return Object.assign({ title: { text: title }, gridcolor: "#e6ebf0", zerolinecolor: "#c9d2dc",
      linecolor: "#9aa8b6", showline: true, ticks: "outside", automargin: true }, extra || {});
  }

  function layout(extra) {
    return Object.assign({
      font: FONT, paper_bgcolor: "#fff", plot_bgcolor: "#fff",
      margin: { l: 70, r: 30, t: 20, b: 60 },
      separators: NUMBER.decimal + NUMBER.thousands,
      legend: { orientation: "h", x: 0, y: 1.02, yanchor: "bottom" },
      hoverlabel: { font: { family: FONT.family, size: 12 } },
    }, extra || {});
  }

  function config(filename) {
    return {
      displaylogo: false, displayModeBar: true, responsive: true, locale: T.lang,
      modeBarButtonsToRemove: ["lasso2d", "select2d", "sendChartToCloud", "sendDataToCloud"],
      showSendToCloud: false, showEditInChartStudio: false, plotlyServerURL: "",
      toImageButtonOptions: { format: "png", filename: filename || "trackvkf-plot", scale: 2 },
    };
  }

  function countPoints(traces) {
    let n = 0;
    for (const t of traces) {
      const v = t.z || t.r || t.y || t.x || [];
      n += Array.isArray(v) ? v.length : 0;
    }
    return n;
  }

  /* Draw a plot; `csv` is a function returning {columns, rows} for the "Download CSV" button. */
  async function plot(el, traces, lay, { filename, csv } = {}) {
    el = typeof el === "string" ? document.getElementById(el) : el;
    const empty = el.querySelector(".empty");
    if (empty) empty.remove();
    await Plotly.react(el, traces, layout(lay), config(filename));
    el.dataset.state = "ready";
    el.dataset.points = String(countPoints(traces));
    if (csv) csvProviders.set(el.id, { filename: filename || el.id, csv });
    const btn = document.querySelector(`button[data-csv-for="${el.id}"]`);
    if (btn) btn.disabled = !csv;
    return el;
  }

  function csvCell(v) {
    if (v === null || v === undefined || (typeof v === "number" && !Number.isFinite(v))) return "";
    const s = String(v), q = String.fromCharCode(34);  // a quote: written so, the message extraction reads this file right
    return s.includes(q) || s.includes(",") || s.includes("\n") ? q + s.split(q).join(q + q) + q : s;
  }

  /* The header of a downloaded CSV: the field names in English (what a program reads), the
   * columns' names with their units in the other languages. */
  const CSV_HEADERS = {
    run_id: T._("Run"), start_time: T._("Start (UTC)"), run_time: T._("Run start (UTC)"), vehicle_id: T._("Vehicle"),
    line_id: T._("Line"), track: T._("Track"), direction: T._("Direction"), km: "km", km_from: T._("km from"), km_to: T._("km to"),
    length_km: T._("Length (km)"), file: T._("File"), sha256: "sha256", job_id: T._("Job"), job_status: T._("Job status"),
    job_progress: T._("Progress (0–1)"), wheel: T._("Wheel"), lon: T._("Longitude (°)"), lat: T._("Latitude (°)"),
    stiffness_index: T._("Stiffness index (ln units)"), stiffness_index_se: T._("Stiffness index, standard uncertainty (ln units)"),
    stiffness_index_mean: T._("Stiffness index, mean (ln units)"), ln_a: T._("Condition index ln A (ln units)"),
    sleeper_amp_mps2: T._("Sleeper-passage amplitude (m/s²)"), sleeper_amp_mean_mps2: T._("Sleeper-passage amplitude, mean (m/s²)"),
    sleeper_amp_max_mps2: T._("Sleeper-passage amplitude, maximum (m/s²)"), reference_amp_mps2: T._("Reference amplitude (m/s²)"),
    sleeper_force_amp_kn: T._("Sleeper-passage force amplitude (kN)"), amp_mean_mps2: T._("Amplitude, mean (m/s²)"),
    amplitude_mps2: T._("Amplitude (m/s²)"), acceleration_mps2: T._("Acceleration amplitude (m/s²)"), accel_amp_mps2: T._("Acceleration amplitude (m/s²)"),
    force_kn: T._("Force amplitude (kN)"), fitted_mass_kg: T._("Fitted mass (kg)"), speed_kmh: T._("Speed (km/h)"),
    speed_mps: T._("Speed (m/s)"), residual_rms_mps2: T._("Residual RMS (m/s²)"), order_amp_01_mps2: T._("Wheel order 1 amplitude (m/s²)"),
    track_impact_mm: T._("Track impact depth (mm)"), sleeper_step_mps2: T._("Step estimate of the sleeper-passage amplitude (m/s²)"),
    relative_mean: T._("Relative to the surroundings (ln units)"), change_z: T._("Change score (z)"), flagged: T._("Flagged (1 = yes)"),
    class: T._("Class"), level: T._("Level (ln units)"), spread: T._("Spread (ln units)"), rms: T._("RMS (ln units)"), fill: T._("Data share (0–1)"),
    change: T._("Change (ln units)"), tier: T._("Tier"), method_version: T._("Method version"),
    index_before: T._("Index before (ln units)"), index_after: T._("Index after (ln units)"),
    time_s: T._("Time (s)"), freq_hz: T._("Frequency (Hz)"), raw_psd_db: T._("Raw PSD (dB)"), components_psd_db: T._("Components PSD (dB)"),
    angle_deg: T._("Angle (°)"), radius_deviation_um: T._("Radius deviation (µm)"), p05_um: T._("5th percentile (µm)"), p95_um: T._("95th percentile (µm)"),
    order: T._("Order"), radius_um: T._("Radius deviation amplitude (µm)"), radius_um_p05: T._("Radius deviation, 5th percentile (µm)"),
    radius_um_p95: T._("Radius deviation, 95th percentile (µm)"), phase_rad: T._("Phase (rad)"), circumference_mm: T._("Along the circumference (mm)"),
    wheel_diameter_m: T._("Wheel diameter (m)"), peak_to_peak_um: T._("Peak-to-peak of r(θ) (µm)"), flat_depth_mm: T._("Wheel flat depth (mm)"),
    subsidence_mm: T._("Subsidence u (mm)"), intercept_mm: T._("Intercept b (mm)"), intercept_ci_lo: T._("Intercept b, 95 % low (mm)"),
    intercept_ci_hi: T._("Intercept b, 95 % high (mm)"), slope_mm: T._("Slope a (mm)"), slope_ci_lo: T._("Slope a, 95 % low (mm)"),
    slope_ci_hi: T._("Slope a, 95 % high (mm)"), rmse_mm: T._("RMSE (mm)"), r2: "R²", n_samples: T._("Samples"), log_base: T._("Log base"),
    n_actions: T._("Maintenance actions per bin"), n_bins: T._("Bins"), whisker_low: T._("Lower whisker (m/s²)"), q1: T._("First quartile (m/s²)"),
    median: T._("Median (m/s²)"), q3: T._("Third quartile (m/s²)"), whisker_high: T._("Upper whisker (m/s²)"), mean: T._("Mean (m/s²)"),
  };
  function csvHeader(name) {
    if (T.lang === "en") return name;
    const order = /^order_(\d+)_radius_um$/.exec(name);
    if (order) return T._("Order {order} radius deviation (µm)", { order: order[1] });
    return CSV_HEADERS[name] ?? name;
  }

  function csvText(columns, rows) {
    return [columns.map(csvHeader).map(csvCell).join(","), ...rows.map((r) => r.map(csvCell).join(","))].join("\n") + "\n";
  }

  function downloadCSV(filename, columns, rows) {
    const blob = new Blob([csvText(columns, rows)], { type: "text/csv" });
    const a = document.createElement("a");
    a.href = URL.createObjectURL(blob);
    a.download = filename.endsWith(".csv") ? filename : filename + ".csv";
    document.body.appendChild(a);
    a.click();
    setTimeout(() => { URL.revokeObjectURL(a.href); a.remove(); }, 0);
  }

  document.addEventListener("click", (ev) => {
    const btn = ev.target.closest("button[data-csv-for]");
    if (!btn) return;
    const p = csvProviders.get(btn.dataset.csvFor);
    if (!p) return;
    const { columns, rows } = p.csv();
    downloadCSV(p.filename, columns, rows);
  });

  function emptyState(el, title, html) {
    el = typeof el === "string" ? document.getElementById(el) : el;
    if (window.Plotly && el.data) Plotly.purge(el);
    el.innerHTML = `<div class="empty"><strong>${title}</strong>${html || ""}</div>`;
    el.dataset.state = "empty";
    el.dataset.points = "0";
    delete el.dataset.clickBound;
    csvProviders.delete(el.id);
    const btn = document.querySelector(`button[data-csv-for="${el.id}"]`);
    if (btn) btn.disabled = true;
  }

  function banner(message, kind) {
    const b = document.getElementById("banner");
    if (!message) { b.hidden = true; b.textContent = ""; return; }
    b.className = "banner" + (kind ? " " + kind : "");
    b.textContent = message;
    b.hidden = false;
  }

  function esc(s) {
    return String(s ?? "").replace(/[&<>"']/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;" }[c]));
  }
  /* Numbers in the page's locale, with `digits` decimals (3 unless told). */
  const numberFormats = new Map();
  function fmt(v, digits) {
    if (v === null || v === undefined || !Number.isFinite(Number(v))) return "–";
    const d = digits ?? 3;
    if (!numberFormats.has(d)) numberFormats.set(d, new Intl.NumberFormat(T.locale, { minimumFractionDigits: d, maximumFractionDigits: d }));
    return numberFormats.get(d).format(Number(v));
  }
  /* Dates (of an ISO text) in the page's locale: English keeps ISO (2025-01-15, never 1/15/25),
   * the other languages their own order (15.01.2025, 15/01/2025). Times are UTC, said so. */
  const DATE = T.lang === "en" ? null : new Intl.DateTimeFormat(T.locale, { year: "numeric", month: "2-digit", day: "2-digit", timeZone: "UTC" });
  function date(iso) {
    if (!iso) return "–";
    const d = String(iso).slice(0, 10);
    if (!DATE || !/^\d{4}-\d{2}-\d{2}$/.test(d)) return d;
    return DATE.format(new Date(d + "T00:00:00Z"));
  }
  function datetime(iso) {
    if (!iso) return "–";
    const s = String(iso);
    const ms = Date.parse(/[zZ]|[+-]\d\d:?\d\d$/.test(s) ? s : s + "Z");
    if (!Number.isFinite(ms)) return s;
    const u = new Date(ms).toISOString();
    return `${date(u)} ${u.slice(11, 16)} UTC`;
  }
  function ready() { document.body.dataset.ready = "1"; }
  function param(name) { return new URLSearchParams(window.location.search).get(name); }

  /* Distinct runs metadata for selectors (line/track, vehicles). */
  async function allRuns(params) {
    const out = [];
    for (let offset = 0; offset < 5000; offset += 500) {
      const page = await T.api.get("/runs", Object.assign({ limit: 500, offset }, params || {}));
      out.push(...page.items);
      if (out.length >= page.total || page.items.length === 0) break;
    }
    return out;
  }

  /* A date axis with ISO dates: days as ticks, and a range of at least `minDays` around the
   * dates (one run date would otherwise give sub-millisecond ticks). */
  function dateAxis(title, dates, extra, minDays) {
    const ms = (dates || []).map((d) => Date.parse(d)).filter(Number.isFinite);
    const out = { type: "date", tickformat: DATE_FMT, hoverformat: `${DATE_FMT} %H:%M` };
    if (ms.length) {
      const day = 86400000, pad = (minDays || 60) * day;
      let lo = Math.min(...ms), hi = Math.max(...ms);
      if (hi - lo < pad) { const mid = (lo + hi) / 2; lo = mid - pad / 2; hi = mid + pad / 2; }
      else { const m = (hi - lo) * 0.05; lo -= m; hi += m; }
      out.range = [new Date(lo).toISOString(), new Date(hi).toISOString()];
    }
    return axis(title, Object.assign(out, extra || {}));
  }

  /* "lines+markers" for a trend over run dates, "markers" when two points share a time (a line
   * between them would be a vertical stroke that means nothing). */
  function trendMode(dates) {
    const ms = (dates || []).map((d) => Date.parse(d));
    return new Set(ms).size < ms.length ? "markers" : "lines+markers";
  }

  /* Line/track picker: one option per line and track of the runs ("line L / track T · n runs"),
   * chosen from the page URL (?line_id=&track=) or else the one with the most processed runs.
   * Returns the keys (line_id + "\u0001" + track). */
  const LINE_SEP = "\u0001";
  function lineKey(r) { return `${r.line_id}${LINE_SEP}${r.track}`; }
  function fillLinePicker(select, runs) {
    select = typeof select === "string" ? document.getElementById(select) : select;
    const count = new Map(), done = new Map();
    for (const r of runs.filter((x) => x.line_id)) {
      const k = lineKey(r);
      count.set(k, (count.get(k) || 0) + 1);
      if (r.latest_job && r.latest_job.status === "done") done.set(k, (done.get(k) || 0) + 1);
    }
    const keys = [...count.keys()].sort();
    select.innerHTML = keys.map((k) => {
      const [l, t] = k.split(LINE_SEP), n = count.get(k);
      return `<option value="${esc(k)}">${esc(T._("line {line} / track {track}", { line: l, track: t }))} · ${esc(T.ngettext("{n} run", "{n} runs", n))}</option>`;
    }).join("");
    const asked = param("line_id") !== null ? `${param("line_id")}${LINE_SEP}${param("track") || ""}` : null;
    const best = keys.slice().sort((a, b) => (done.get(b) || 0) - (done.get(a) || 0) || (count.get(b) - count.get(a)))[0];
    if (asked && keys.includes(asked)) select.value = asked;
    else if (best) select.value = best;
    return keys;
  }
  function lineOf(select) {
    select = typeof select === "string" ? document.getElementById(select) : select;
    const [line_id, track] = (select.value || "").split(LINE_SEP);
    return { line_id: line_id || undefined, track: track || undefined };
  }
  /* Put the chosen line into the page URL (reload and links keep it). */
  function rememberLine(line) {
    const u = new URL(window.location.href);
    if (line.line_id) u.searchParams.set("line_id", line.line_id); else u.searchParams.delete("line_id");
    if (line.track) u.searchParams.set("track", line.track); else u.searchParams.delete("track");
    window.history.replaceState(null, "", u.pathname + u.search);
  }

  /* The words of a code the API answers (a tier, a status, a maintenance type ...) in the page's
   * language: the boot data's labels (app/web/vocabulary.py), else the code with spaces. */
  const LABELS = T.boot.labels || {};
  function label(kind, code) {
    if (code === null || code === undefined) return "–";
    const words = LABELS[kind] || {};
    return words[code] ?? String(code).replace(/_/g, " ");
  }
  function jobStatus(code) { return label("job status", code); }

  Object.assign(T, {
    label, jobStatus, DATE_FMT,
    WHEELS, WHEEL_COLORS, TIER_COLORS, wheelId, wheelLabel, wheelName, wheelColor, axis, dateAxis, trendMode, layout, config, plot,
    emptyState, banner, downloadCSV, csvText, csvHeader, esc, fmt, date, datetime, ready, param, allRuns,
    lineKey, fillLinePicker, lineOf, rememberLine,
  });
})();
