/* Spectrogram of a km window (paper fig. 3): (a) raw ABA with the tracked order frequencies,
 * (b) the sum of the VKF-extracted orders, (c) speed. The tracked orders are named for what they
 * are: the sleeper passage ("sleeper"), its harmonics ("sleeper_2", "sleeper_3") and the wheel
 * out-of-roundness orders ("1" … "11"), counted from the answer's labels. */
(function () {
  "use strict";
  const T = window.trackvkf;
  const runId = T.boot.run_id;
  const el = document.getElementById("spectrogram-plot");
  let spec = null;

  /* The kind of a tracked order by its label: the sleeper passage, a harmonic of it, a wheel order. */
  function kindOf(label) {
    if (label === "sleeper") return "sleeper";
    return /^\d+$/.test(label) ? "wheel" : "harmonic";
  }
  function counts() {
    const c = { sleeper: 0, harmonic: 0, wheel: 0 };
    for (const o of spec.orders) c[kindOf(o.label)] += 1;
    return c;
  }
  function orderName(o) {
    const kind = kindOf(o.label);
    if (kind === "sleeper") return T._("sleeper passage");
    if (kind === "harmonic") return T._("sleeper passage × {h}", { h: o.label.split("_").pop() });
    return T._("wheel order {l}", { l: o.label });
  }
  function groupName(kind) {
    const c = counts();
    if (kind === "sleeper") return T._("sleeper passage");
    if (kind === "harmonic") return T.ngettext("{n} sleeper-passage harmonic", "{n} sleeper-passage harmonics", c.harmonic);
    return T.ngettext("{n} wheel order", "{n} wheel orders", c.wheel);
  }
  const STYLE = {
    // the tracked orders lie on the bright bands: dark dashes show on green and yellow alike
    sleeper: { color: "#ff1744", width: 2.4, dash: "dash" },
    harmonic: { color: "#ff8a80", width: 1.6, dash: "dot" },
    wheel: { color: "#000000", width: 1.6, dash: "dash" },
  };

  function orderLines(yaxis, showlegend) {
    const shown = new Set();
    return spec.orders.map((o) => {
      const kind = kindOf(o.label);
      const first = !shown.has(kind);
      shown.add(kind);
      return {
        type: "scatter", mode: "lines", x: spec.km, y: o.freq_hz, xaxis: "x", yaxis,
        name: groupName(kind), legendgroup: kind, showlegend: showlegend && first, line: STYLE[kind],
        hovertemplate: `${T.esc(orderName(o))}<br>km %{x:.4f}<br>%{y:.1f} Hz<extra></extra>`,
      };
    });
  }

  function heat(z, yaxis, showscale) {
    return {
      type: "heatmap", x: spec.km, y: spec.freq_hz, z, xaxis: "x", yaxis, colorscale: "Viridis",
      zmin: zRange()[0], zmax: zRange()[1], showscale,
      colorbar: { title: { text: T._("PSD (dB re 1 (m/s²)²/Hz)"), side: "right" }, len: 0.62, y: 0.69, thickness: 14 },
      hovertemplate: "km %{x:.4f}<br>%{y:.1f} Hz<br>%{z:.1f} dB<extra></extra>",
    };
  }

  function zRange() {
    let max = -Infinity;
    for (const row of spec.raw_db) for (const v of row) if (v !== null && v > max) max = v;
    return [max - 60, max];
  }

  async function draw() {
    const fTop = spec.freq_hz[spec.freq_hz.length - 1];
    const traces = [
      heat(spec.raw_db, "y", true), ...orderLines("y", true),
      heat(spec.components_db, "y2", false),
      { type: "scatter", mode: "lines", x: spec.km, y: spec.speed_kmh, xaxis: "x", yaxis: "y3", name: T._("speed"),
        line: { color: "#1f3b57", width: 1.6 }, hovertemplate: "km %{x:.4f}<br>%{y:.1f} km/h<extra></extra>" },
    ];
    const ann = (text, y) => ({ text, x: 0, xref: "paper", y, yref: "paper", xanchor: "left", yanchor: "bottom",
      showarrow: false, font: { size: 12, color: "#1d2733" } });
    await T.plot(el, traces, {
      grid: { rows: 3, columns: 1 },
      xaxis: T.axis(T._("Track position (km)"), { anchor: "y3", tickformat: ".3f", range: [spec.km[0], spec.km[spec.km.length - 1]] }),
      yaxis: T.axis(T._("Frequency (Hz)"), { domain: [0.6, 0.96], range: [0, fTop] }),
      yaxis2: T.axis(T._("Frequency (Hz)"), { domain: [0.24, 0.56], range: [0, fTop] }),
      yaxis3: T.axis(T._("Speed (km/h)"), { domain: [0, 0.18] }),
      annotations: [
        ann(T._("a) raw ABA {channel}", { channel: spec.channel }), 0.96),
        ann(T._("b) extracted components {channel} (sleeper passage, {harmonics} and {wheel})",
          { channel: spec.channel, harmonics: groupName("harmonic"), wheel: groupName("wheel") }), 0.56),
        ann(T._("c) speed"), 0.18)],
      margin: { l: 75, r: 30, t: 50, b: 60 },
      legend: { orientation: "h", x: 0.45, y: 1.0, yanchor: "bottom", bgcolor: "rgba(0,0,0,0)" },
    }, {
      filename: `run-${runId}-spectrogram-${spec.channel}`,
      csv: () => {
        const rows = [];
        for (let j = 0; j < spec.km.length; j++) {
          for (let i = 0; i < spec.freq_hz.length; i++) {
            rows.push([spec.km[j], spec.time_s[j], spec.speed_kmh[j], spec.freq_hz[i], spec.raw_db[i][j], spec.components_db[i][j]]);
          }
        }
        return { columns: ["km", "time_s", "speed_kmh", "freq_hz", "raw_psd_db", "components_psd_db"], rows };
      },
    });
    document.getElementById("spec-info").textContent = T._(
      "{channel}: {frames} frames × {freqs} frequencies, resolution {res} Hz, bandwidth {bw} orders, q = {q}, d_w = {dw} m",
      { channel: spec.channel, frames: spec.km.length, freqs: spec.freq_hz.length, res: T.fmt(spec.resolution_hz, 2),
        bw: spec.settings.bandwidth_orders, q: spec.settings.filter_order, dw: T.fmt(spec.wheel_diameter_m, 3) });
  }

  async function compute() {
    const wheel = document.getElementById("wheel").value;
    const a = parseFloat(document.getElementById("km-from").value), b = parseFloat(document.getElementById("km-to").value);
    const revolutions = parseFloat(document.getElementById("revs").value) || 8;
    T.banner(null);
    el.style.opacity = 0.5;
    try {
      spec = await T.api.get(`/runs/${runId}/spectrogram`, { wheel, km_from: a, km_to: b, revolutions });
      await draw();
    } catch (e) {
      T.banner(T._("Spectrogram not available (HTTP {status}): {detail}", { status: e.status, detail: e.detail }));
    } finally {
      el.style.opacity = 1;
    }
  }

  document.getElementById("spec-controls").addEventListener("submit", (ev) => { ev.preventDefault(); compute(); });

  (async () => {
    try {
      const run = await T.api.get(`/runs/${runId}`);
      document.getElementById("run-subtitle").textContent = T._("spectrogram · {vehicle} on line {line} track {track}, {date}",
        { vehicle: run.vehicle_id, line: run.line_id, track: run.track, date: T.date(run.start_time) });
      const wheels = T.WHEELS.filter((w) => run.summary.channels.includes("Z" + w));
      const sel = document.getElementById("wheel");
      sel.innerHTML = wheels.map((w) => `<option value="${w}">${T.wheelLabel(w)}</option>`).join("");
      sel.value = wheels.includes(T.param("wheel") || "12") ? (T.param("wheel") || "12") : wheels[0];
      const len = (run.summary.distance_m || 0) / 1000;
      const end = run.km_increasing === false ? run.km_start - len : run.km_start + len;
      const lo = Math.min(run.km_start, end), hi = Math.max(run.km_start, end);
      const mid = (lo + hi) / 2;
      const half = Math.min(0.1, (hi - lo) / 2);
      document.getElementById("km-from").value = (T.param("km_from") || (mid - half).toFixed(3));
      document.getElementById("km-to").value = (T.param("km_to") || (mid + half).toFixed(3));
      await compute();
    } catch (e) {
      T.banner(T._("Could not load run {run}: {detail}", { run: runId, detail: e.detail || e.message }));
    }
    T.ready();
  })();
})();
