/* Correlations: subsidence vs log amplitude with the fitted line and the per-wheel table
 * (paper table tab:01), force vs acceleration with the fitted unsprung mass, maintenance
 * actions per 25 cm vs amplitude as box plots. Data from the analytics endpoints; a helpful
 * empty state while there are no reference data (or no analytics on the server). */
(function () {
  "use strict";
  const T = window.trackvkf;
  const PLOTS = ["subsidence-plot", "mass-plot", "maintenance-plot"];
  const HOWTO = `<p>${T._("Import reference data with {a}, {b} or {c} (CSV or Parquet), then reload this page.",
    { a: "<code>POST /api/v1/reference/subsidence</code>", b: "<code>/maintenance</code>", c: "<code>/superstructure</code>" })}</p>`;
  let fit = null;
  // markers per wheel and plot (SVG markers are slow by the ten thousand), asked of the server
  // as max_points; the fits use every sample
  const DRAW_POINTS = 1500;

  function query() {
    const { line_id, track } = T.lineOf("line-track");
    return { line_id, track, km_from: document.getElementById("km-from").value, km_to: document.getElementById("km-to").value };
  }

  function logOf(base) {
    if (base === "10") return Math.log10;
    if (base === "2") return Math.log2;
    return Math.log;
  }

  function fitTable() {
    const table = document.getElementById("fit-table");
    const ws = ((fit && fit.wheels) || []).filter((w) => (w.n_samples || 0) > 0);
    if (!ws.length) {
      table.innerHTML = `<tbody><tr><td class="muted">${T.esc(T._("No fit: no subsidence data yet."))}</td></tr></tbody>`;
      document.getElementById("fit-csv").disabled = true;
      return;
    }
    const ci = (v) => (v && Number.isFinite(v[0]) && Number.isFinite(v[1]) ? `<br><span class="muted ci">[${T.fmt(v[0], 3)}, ${T.fmt(v[1], 3)}]</span>` : "");
    const row = (label, f) => `<tr><th>${label}</th>${ws.map((w) => `<td class="num">${f(w)}</td>`).join("")}</tr>`;
    table.innerHTML = `<thead><tr><th>${T.esc(T._("Regressor"))}</th>${ws.map((w) => `<th class="num">${T.esc(T.wheelLabel(w.wheel))}</th>`).join("")}</tr></thead><tbody>` +
      row(T.esc(T._("Intercept b (mm)")), (w) => T.fmt(w.intercept, 3) + ci(w.intercept_ci)) +
      row(T.esc(T._("Slope a (mm)")), (w) => T.fmt(w.slope, 3) + ci(w.slope_ci)) +
      row(T.esc(T._("RMSE (mm)")), (w) => T.fmt(w.rmse, 3)) +
      row("R²", (w) => T.fmt(w.r2, 3)) +
      row(T.esc(T._("Samples")), (w) => w.n_samples === null || w.n_samples === undefined ? "–" : T.fmt(w.n_samples, 0)) + "</tbody>";
    // one way to write a unit on every page: m/s² (the API may spell it m/s^2)
    const ampUnit = String(fit.amplitude_unit || "m/s²").replace("^2", "²");
    const base = fit.log_base && fit.log_base !== "e" ? fit.log_base : "e";
    document.getElementById("fit-note").textContent =
      T._("u: subsidence ({u}); Z: sleeper-passage amplitude ({z}); log base {base}; 95 % confidence intervals in brackets.",
        { u: fit.subsidence_unit || "mm", z: ampUnit, base });
    document.getElementById("fit-csv").disabled = false;
  }

  document.getElementById("fit-csv").addEventListener("click", () => {
    const ws = fit.wheels.filter((w) => (w.n_samples || 0) > 0);
    T.downloadCSV("subsidence-fit.csv", ["wheel", "intercept_mm", "intercept_ci_lo", "intercept_ci_hi", "slope_mm", "slope_ci_lo", "slope_ci_hi", "rmse_mm", "r2", "n_samples", "log_base"],
      ws.map((w) => [w.wheel, w.intercept, (w.intercept_ci || [])[0], (w.intercept_ci || [])[1], w.slope, (w.slope_ci || [])[0], (w.slope_ci || [])[1], w.rmse, w.r2, w.n_samples, fit.log_base]));
  });

  async function drawSubsidence() {
    const el = document.getElementById("subsidence-plot");
    const ws = ((fit && fit.wheels) || []).filter((w) => w.points && w.points.amplitude && w.points.amplitude.length);
    if (!ws.length) { T.emptyState(el, T._("No subsidence data yet."), HOWTO); return false; }
    const lg = logOf(fit.log_base);
    const traces = [];
    for (const w of ws) {
      const amps = w.points.amplitude.filter((a) => a > 0);
      traces.push({ type: "scatter", mode: "markers", name: T.wheelLabel(w.wheel), legendgroup: w.wheel,
        x: w.points.amplitude, y: w.points.subsidence_mm, marker: { color: T.wheelColor(w.wheel), size: 4, opacity: 0.35 },
        hovertemplate: `${T.wheelLabel(w.wheel)}<br>%{x:.3f} m/s²<br>%{y:.3f} mm<extra></extra>` });
      if (amps.length && Number.isFinite(w.slope)) {
        const lo = Math.min(...amps), hi = Math.max(...amps);
        const xs = Array.from({ length: 40 }, (_, i) => lo * Math.pow(hi / lo, i / 39));
        traces.push({ type: "scatter", mode: "lines", name: T._("{wheel} fit", { wheel: T.wheelLabel(w.wheel) }), legendgroup: w.wheel, showlegend: false,
          x: xs, y: xs.map((x) => w.slope * lg(x) + w.intercept), line: { color: T.wheelColor(w.wheel), width: 2.5 },
          hovertemplate: `${T.esc(T._("{wheel} fit", { wheel: T.wheelLabel(w.wheel) }))}<br>u = ${T.fmt(w.slope, 3)}·log(Z) ${w.intercept < 0 ? "−" : "+"} ${T.fmt(Math.abs(w.intercept), 3)}<extra></extra>` });
      }
    }
    await T.plot(el, traces, {
      xaxis: T.axis(T._("Sleeper-passage amplitude Z (m/s², log scale)"), { type: "log", tickformat: "~g", dtick: "D2" }),
      yaxis: T.axis(T._("Subsidence u (mm)")),
    }, {
      filename: "subsidence-vs-amplitude",
      csv: () => {
        const rows = [];
        for (const w of ws) w.points.amplitude.forEach((a, i) => rows.push([w.wheel, a, w.points.subsidence_mm[i]]));
        return { columns: ["wheel", "amplitude_mps2", "subsidence_mm"], rows };
      },
    });
    return true;
  }

  /* One panel per wheel (2 x 2, shared axes): the wheels of a vehicle have nearly the same
   * unsprung mass, so in one panel their points and lines would hide each other. */
  async function drawMass(res) {
    const el = document.getElementById("mass-plot");
    const ws = ((res && res.wheels) || []).filter((w) => w.points && w.points.acceleration && w.points.acceleration.length);
    if (!ws.length) { T.emptyState(el, T._("No force channels or no data yet."), `<p>${T._("Runs with vertical force channels Q11…Q42 give the unsprung mass.")}</p>`); return false; }
    const traces = [], lay = {
      grid: { rows: 2, columns: 2, pattern: "independent", xgap: 0.12, ygap: 0.22 },
      showlegend: false, annotations: [], margin: { l: 70, r: 20, t: 30, b: 60 },
    };
    const amax = Math.max(...ws.flatMap((w) => w.points.acceleration.filter(Number.isFinite)));
    const fmax = Math.max(...ws.flatMap((w) => w.points.force_kn.filter(Number.isFinite)));
    ws.forEach((w, i) => {
      const n = i === 0 ? "" : String(i + 1), xa = "x" + n, ya = "y" + n;
      const name = w.plausible ? `${T.wheelLabel(w.wheel)}: ${T.fmt(w.mass_kg, 0)} kg`
        : T._("{wheel}: {mass} kg (implausible)", { wheel: T.wheelLabel(w.wheel), mass: T.fmt(w.mass_kg, 0) });
      traces.push({ type: "scatter", mode: "markers", name, xaxis: xa, yaxis: ya,
        x: w.points.acceleration, y: w.points.force_kn,
        marker: { color: T.wheelColor(w.wheel), size: 4, opacity: 0.35 },
        hovertemplate: `${T.wheelLabel(w.wheel)}<br>%{x:.3f} m/s²<br>%{y:.3f} kN<extra></extra>` });
      traces.push({ type: "scatter", mode: "lines", showlegend: false, xaxis: xa, yaxis: ya, x: [0, amax], y: [0, w.mass_kg * amax / 1000],
        line: { color: "#1d2733", width: 2, dash: "dash" }, hovertemplate: `F = ${T.fmt(w.mass_kg, 0)} kg × a<extra></extra>` });
      const bottom = i >= ws.length - 2, left = i % 2 === 0;
      lay["xaxis" + n] = T.axis(bottom ? T._("Acceleration amplitude (m/s²)") : "", { range: [0, amax * 1.05] });
      lay["yaxis" + n] = T.axis(left ? T._("Force amplitude (kN)") : "", { range: [0, fmax * 1.08] });
      lay.annotations.push({ xref: `${xa} domain`, yref: `${ya} domain`, x: 0.02, y: 0.98, xanchor: "left", yanchor: "top",
        showarrow: false, text: `<b>${T.esc(name)}</b>`, font: { color: T.wheelColor(w.wheel) }, bgcolor: "rgba(255,255,255,0.8)" });
    });
    await T.plot(el, traces, lay, {
      filename: "force-vs-acceleration",
      csv: () => {
        const rows = [];
        for (const w of ws) w.points.acceleration.forEach((a, i) => rows.push([w.wheel, a, w.points.force_kn[i], w.mass_kg]));
        return { columns: ["wheel", "acceleration_mps2", "force_kn", "fitted_mass_kg"], rows };
      },
    });
    return true;
  }

  async function drawMaintenance(res) {
    const el = document.getElementById("maintenance-plot");
    const groups = (res && res.groups) || [];
    if (!groups.length) { T.emptyState(el, T._("No maintenance records yet."), HOWTO); return false; }
    const trace = {
      type: "box", name: T._("amplitude"), x: groups.map((g) => g.n_actions), q1: groups.map((g) => g.q1), median: groups.map((g) => g.median),
      q3: groups.map((g) => g.q3), lowerfence: groups.map((g) => g.whisker_low), upperfence: groups.map((g) => g.whisker_high),
      mean: groups.map((g) => g.mean), marker: { color: "#1f5fa8" }, fillcolor: "rgba(31,95,168,0.25)", line: { color: "#1f5fa8" },
    };
    const reg = res.regression || {};
    await T.plot(el, [trace], {
      xaxis: T.axis(T._("Maintenance actions per 25 cm bin (count)"), { type: "category" }),
      yaxis: T.axis(T._("Sleeper-passage amplitude (m/s²)"), { rangemode: "tozero" }),
      showlegend: false,
      margin: { l: 70, r: 20, t: 44, b: 60 },
      // above the plot area, not over the boxes
      annotations: Number.isFinite(reg.slope) ? [{ xref: "paper", yref: "paper", x: 0, y: 1.02, yanchor: "bottom", showarrow: false, xanchor: "left",
        text: T._("slope {slope} m/s² per action · r = {r} · p = {p} · n = {n}",
          { slope: T.fmt(reg.slope, 3), r: T.fmt(reg.r, 2), p: Number(reg.p_value).toExponential(1), n: reg.n }) }] : [],
    }, {
      filename: "maintenance-vs-amplitude",
      csv: () => ({ columns: ["n_actions", "n_bins", "whisker_low", "q1", "median", "q3", "whisker_high", "mean"],
        rows: groups.map((g) => [g.n_actions, g.n_bins, g.whisker_low, g.q1, g.median, g.q3, g.whisker_high, g.mean]) }),
    });
    return true;
  }

  function showEmpty(html) {
    const box = document.getElementById("corr-empty");
    box.hidden = !html;
    document.getElementById("corr-empty-text").innerHTML = html || "";
  }

  async function show() {
    T.banner(null);
    const q = query();
    if (!q.line_id) {
      for (const id of PLOTS) T.emptyState(id, T._("No runs yet."), `<p>${T._("Upload runs on the Runs page.")}</p>`);
      fit = null; fitTable();
      showEmpty(`<strong>${T._("No lines yet.")}</strong><p>${T._("The correlations compare the processed runs of one line and track with its reference data.")}</p>${HOWTO}`);
      return;
    }
    T.rememberLine(q);
    try {
      const [sub, mass, maint] = await Promise.all([
        T.api.get("/analytics/subsidence-fit", Object.assign({ max_points: DRAW_POINTS }, q)),
        T.api.get("/analytics/unsprung-mass", Object.assign({ max_points: DRAW_POINTS }, q)),
        T.api.get("/analytics/maintenance", Object.assign({ type: document.getElementById("mtype").value }, q)),
      ]);
      fit = sub;
      fitTable();
      const any = [await drawSubsidence(), await drawMass(mass), await drawMaintenance(maint)];
      showEmpty(any.some(Boolean) ? null : `<strong>${T._("No reference data yet.")}</strong><p>${T._("The analyses run as soon as reference data exist for the processed runs.")}</p>${HOWTO}`);
    } catch (e) {
      T.banner(T._("Could not load the correlations (HTTP {status}): {detail}", { status: e.status, detail: e.detail }));
    }
  }

  document.getElementById("corr-controls").addEventListener("submit", (ev) => { ev.preventDefault(); show(); });
  document.getElementById("line-track").addEventListener("change", () => show());

  (async () => {
    try {
      T.fillLinePicker("line-track", await T.allRuns());
      await show();
    } catch (e) {
      T.banner(T._("Could not load the correlations: {detail}", { detail: e.detail || e.message }));
    }
    T.ready();
  })();
})();
