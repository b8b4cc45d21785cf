/* Wheels page: polar plot of r(θ) (paper fig. 31), order amplitudes as bars, the wheel flats
 * (marked on the plots of r), r along the circumference, and the trend of the OOR over the
 * vehicle's runs. */
(function () {
  "use strict";
  const T = window.trackvkf;
  let runs = [], wheels = null, trend = null;

  function finite(v) { return v !== null && v !== undefined && Number.isFinite(v); }

  async function drawPolar() {
    const el = document.getElementById("polar-plot");
    let lim = 10;
    for (const w of wheels.items) for (const v of w.profile_um) if (finite(v)) lim = Math.max(lim, Math.abs(v));
    lim = Math.ceil(lim * 1.15 / 20) * 20;  // rings every lim / 2: whole µm
    const traces = wheels.items.map((w) => ({
      type: "scatterpolar", mode: "lines", name: T.wheelLabel(w.wheel), theta: w.angles_deg.concat([w.angles_deg[0]]),
      r: w.profile_um.concat([w.profile_um[0]]), line: { color: T.wheelColor(w.wheel), width: 2 },
      hovertemplate: `${T.wheelLabel(w.wheel)}<br>θ %{theta:.0f}°<br>%{r:.1f} µm<extra></extra>`,
    }));
    const flats = wheels.items.filter((w) => w.flat);
    if (flats.length) {
      // a spoke from the centre to the rim at the flat's angle, marked on the rim in the wheel's colour
      const spoke = (f) => [f, f, null];
      traces.push({
        type: "scatterpolar", mode: "lines+markers", name: T._("wheel flat"),
        theta: flats.flatMap((w) => spoke(w.flat.angle_deg)), r: flats.flatMap(() => [-lim, lim, null]),
        line: { color: "#5b6b7b", width: 1, dash: "dot" },
        marker: { symbol: "x", size: flats.flatMap(() => [0, 14, 0]),
          color: flats.flatMap((w) => spoke(T.wheelColor(w.wheel))) },
        customdata: flats.flatMap((w) => spoke([T.wheelLabel(w.wheel), w.flat.depth_mm])),
        hovertemplate: `${T.esc(T._("wheel flat"))}, %{customdata[0]}<br>θ %{theta:.1f}°<br>${T.esc(T._("depth"))} %{customdata[1]:.2f} mm<extra></extra>`,
      });
    }
    await T.plot(el, traces, {
      // ring labels would sit on the curves: the rings are explained in a note instead
      polar: { radialaxis: { range: [-lim, lim], dtick: lim / 2, showticklabels: false, ticks: "", gridcolor: "#e6ebf0" },
        angularaxis: { direction: "clockwise", rotation: 90, ticksuffix: "°", gridcolor: "#e6ebf0" } },
      annotations: [{ xref: "paper", yref: "paper", x: 0, y: 0, xanchor: "left", yanchor: "bottom", showarrow: false,
        align: "left", font: { size: 11, color: "#5b6b7b" },
        text: T._("centre −{lim} µm · rim +{lim} µm<br>rings every {ring} µm (middle ring 0 µm)", { lim: T.fmt(lim, 0), ring: T.fmt(lim / 2, 0) }) }],
      margin: { l: 40, r: 40, t: 40, b: 30 },
      // transparent: the box of the longest name would hide the 315° label beside it
      legend: { orientation: "v", x: 0, y: 1, yanchor: "top", bgcolor: "rgba(0,0,0,0)" },
    }, {
      filename: `run-${wheels.run_id}-wheel-polar`,
      csv: () => {
        const rows = [];
        for (const w of wheels.items) w.angles_deg.forEach((a, i) => rows.push([w.wheel, a, w.profile_um[i], w.profile_p05_um ? w.profile_p05_um[i] : null, w.profile_p95_um ? w.profile_p95_um[i] : null]));
        return { columns: ["wheel", "angle_deg", "radius_deviation_um", "p05_um", "p95_um"], rows };
      },
    });
  }

  async function drawOrders() {
    const el = document.getElementById("orders-plot");
    const traces = wheels.items.map((w) => ({
      type: "bar", name: T.wheelLabel(w.wheel), marker: { color: T.wheelColor(w.wheel) },
      x: w.orders.map((o) => o.order), y: w.orders.map((o) => o.radius_um),
      error_y: { type: "data", symmetric: false, color: "#555", thickness: 1, width: 2,
        array: w.orders.map((o) => finite(o.radius_um_p95) ? o.radius_um_p95 - o.radius_um : 0),
        arrayminus: w.orders.map((o) => finite(o.radius_um_p05) ? o.radius_um - o.radius_um_p05 : 0) },
      hovertemplate: `${T.wheelLabel(w.wheel)} ${T.esc(T._("order {order}", { order: "%{x}" }))}<br>%{y:.1f} µm<extra></extra>`,
    }));
    await T.plot(el, traces, {
      barmode: "group",
      xaxis: T.axis(T._("Wheel out-of-roundness order (harmonics per revolution)"), { dtick: 1 }),
      yaxis: T.axis(T._("Radius deviation amplitude (µm)"), { rangemode: "tozero" }),
      margin: { l: 70, r: 20, t: 40, b: 60 },
    }, {
      filename: `run-${wheels.run_id}-wheel-orders`,
      csv: () => {
        const rows = [];
        for (const w of wheels.items) for (const o of w.orders) rows.push([w.wheel, o.order, o.radius_um, o.radius_um_p05, o.radius_um_p95, o.phase_rad, o.accel_amp]);
        return { columns: ["wheel", "order", "radius_um", "radius_um_p05", "radius_um_p95", "phase_rad", "accel_amp_mps2"], rows };
      },
    });
  }

  async function drawProfile() {
    const el = document.getElementById("profile-plot");
    const traces = wheels.items.map((w) => {
      const circ = Math.PI * (w.wheel_diameter_m || 0.92) * 1000;
      return {
        type: "scatter", mode: "lines", name: T.wheelLabel(w.wheel), line: { color: T.wheelColor(w.wheel), width: 1.6 },
        x: w.angles_deg.map((a) => a / 360 * circ), y: w.profile_um,
        hovertemplate: `${T.wheelLabel(w.wheel)}<br>%{x:.0f} mm<br>%{y:.1f} µm<extra></extra>`,
      };
    });
    // a flat is a short dip (tens of mm): drawn as a band where it is, its depth written on it
    const shapes = [], notes = [];
    for (const w of wheels.items.filter((x) => x.flat)) {
      const circ = Math.PI * (w.wheel_diameter_m || 0.92) * 1000;
      const at = w.flat.angle_deg / 360 * circ, half = (w.flat.length_mm || 40) / 2;
      shapes.push({ type: "rect", xref: "x", yref: "paper", x0: at - half, x1: at + half, y0: 0, y1: 1,
        fillcolor: T.wheelColor(w.wheel), opacity: 0.25, line: { width: 0 } });
      // inside the plot, beside the band: above it the legend sits
      notes.push({ xref: "x", yref: "paper", x: at + half, y: 1, xanchor: "left", yanchor: "top", xshift: 4,
        showarrow: false, font: { size: 11 }, bgcolor: "rgba(255,255,255,0.85)",
        text: T.esc(T._("flat {wheel} · {depth} mm", { wheel: T.wheelLabel(w.wheel), depth: T.fmt(w.flat.depth_mm, 2) })) });
    }
    await T.plot(el, traces, {
      xaxis: T.axis(T._("Position along the circumference (mm)")),
      yaxis: T.axis(T._("Radius deviation (µm)")),
      margin: { l: 70, r: 20, t: 30, b: 55 }, shapes, annotations: notes,
    }, {
      filename: `run-${wheels.run_id}-wheel-circumference`,
      csv: () => {
        const rows = [];
        for (const w of wheels.items) {
          const circ = Math.PI * (w.wheel_diameter_m || 0.92) * 1000;
          w.angles_deg.forEach((a, i) => rows.push([w.wheel, a, a / 360 * circ, w.profile_um[i]]));
        }
        return { columns: ["wheel", "angle_deg", "circumference_mm", "radius_deviation_um"], rows };
      },
    });
  }

  function drawFlats() {
    const body = document.getElementById("flats-body");
    const flats = wheels.items.filter((w) => w.flat);
    if (!flats.length) {
      body.innerHTML = `<tr><td colspan="7" class="muted">${T.esc(T._("No wheel flat found in this run."))}</td></tr>`;
      return;
    }
    body.innerHTML = flats.map((w) => {
      const f = w.flat, circ = Math.PI * (w.wheel_diameter_m || 0.92) * 1000;
      const seen = f.first_seen_run_id === wheels.run_id ? T.esc(T._("this run"))
        : `<a href="/wheels?vehicle_id=${encodeURIComponent(document.getElementById("vehicle").value)}&run_id=${f.first_seen_run_id}">${T.esc(T._("run {run}", { run: f.first_seen_run_id }))}</a> · ${T.date(f.first_seen_time)}`;
      return `<tr><td><i class="swatch" style="background:${T.wheelColor(w.wheel)}"></i> ${T.esc(T.wheelLabel(w.wheel))}</td>` +
        `<td class="num">${T.fmt(f.angle_deg, 1)}</td><td class="num">${T.fmt(f.angle_deg / 360 * circ, 0)}</td>` +
        `<td class="num">${T.fmt(f.depth_mm, 2)}</td><td class="num">${T.fmt(f.length_mm, 0)}</td>` +
        `<td class="num">${f.n_hits} / ${f.n_revolutions ?? "–"}</td><td>${seen}</td></tr>`;
    }).join("");
  }

  function trendValue(item, q) {
    if (q === "flat") return item.flat_depth_mm;
    if (q === "p2p") return item.peak_to_peak_um;
    return item.radius_um[Number(q) - 1];
  }

  async function drawTrend() {
    const el = document.getElementById("trend-plot");
    if (!trend || !trend.items.length) {
      T.emptyState(el, T._("No processed runs of this vehicle yet."), "");
      return;
    }
    const q = document.getElementById("trend-quantity").value;
    const label = q === "flat" ? T._("Wheel flat depth (mm)") : q === "p2p" ? T._("Peak-to-peak of r(θ) (µm)") : T._("Order {order} radius deviation (µm)", { order: q });
    const unit = q === "flat" ? "mm" : "µm";
    const traces = T.WHEELS.filter((w) => trend.items.some((i) => i.wheel === w)).map((w) => {
      const items = trend.items.filter((i) => i.wheel === w);
      return {
        type: "scatter", mode: T.trendMode(items.map((i) => i.start_time)), name: T.wheelLabel(w), line: { color: T.wheelColor(w), width: 2 },
        marker: { size: 8 }, x: items.map((i) => i.start_time), y: items.map((i) => trendValue(i, q)),
        customdata: items.map((i) => i.run_id),
        hovertemplate: `${T.wheelLabel(w)}<br>%{x|${T.DATE_FMT} %H:%M}<br>%{y:.${q === "flat" ? 2 : 1}f} ${unit}<br>${T.esc(T._("run {run}", { run: "%{customdata}" }))}<extra></extra>`,
      };
    });
    await T.plot(el, traces, {
      xaxis: T.dateAxis(T._("Run start (date)"), trend.items.map((i) => i.start_time)),
      yaxis: T.axis(label, { rangemode: "tozero" }),
      margin: { l: 70, r: 20, t: 30, b: 55 },
    }, {
      filename: `vehicle-${trend.vehicle_id}-wheel-trend`,
      csv: () => ({
        columns: ["run_id", "start_time", "wheel", "wheel_diameter_m", "peak_to_peak_um", "flat_depth_mm", ...trend.orders.map((o) => `order_${o}_radius_um`)],
        rows: trend.items.map((i) => [i.run_id, i.start_time, i.wheel, i.wheel_diameter_m, i.peak_to_peak_um, i.flat_depth_mm, ...i.radius_um]),
      }),
    });
  }

  async function loadRun() {
    const runId = document.getElementById("run").value;
    if (!runId) {
      for (const id of ["polar-plot", "orders-plot", "profile-plot"]) T.emptyState(id, T._("No processed run of this vehicle."), `<p>${T._("Upload a run on the Runs page; the wheels appear when its job is done.")}</p>`);
      return;
    }
    try {
      wheels = await T.api.get(`/runs/${runId}/wheels`);
      drawFlats();
      await Promise.all([drawPolar(), drawOrders(), drawProfile()]);
    } catch (e) {
      for (const id of ["polar-plot", "orders-plot", "profile-plot"]) T.emptyState(id, T._("No wheel results"), `<p>${T.esc(e.detail)}</p>`);
      document.getElementById("flats-body").innerHTML = `<tr><td colspan="7" class="muted">–</td></tr>`;
    }
  }

  async function loadVehicle() {
    const vehicle = document.getElementById("vehicle").value;
    const mine = runs.filter((r) => r.vehicle_id === vehicle && r.latest_job && r.latest_job.status === "done");
    const sel = document.getElementById("run");
    sel.innerHTML = mine.map((r) => `<option value="${r.id}">${T.esc(T._("Run {run} · {date} · line {line}/{track}", { run: r.id, date: T.date(r.start_time), line: r.line_id, track: r.track }))}</option>`).join("");
    const want = T.param("run_id");
    if (want && mine.some((r) => String(r.id) === want)) sel.value = want;
    trend = vehicle ? await T.api.get("/wheels/trend", { vehicle_id: vehicle }) : null;
    const qsel = document.getElementById("trend-quantity");
    const orders = trend ? trend.orders : [];
    qsel.innerHTML = `<option value="p2p">${T.esc(T._("peak-to-peak r(θ)"))}</option><option value="flat">${T.esc(T._("wheel flat depth"))}</option>` +
      orders.map((o) => `<option value="${o}">${T.esc(T._("order {order}", { order: o }))}</option>`).join("");
    await Promise.all([loadRun(), drawTrend()]);
  }

  document.getElementById("vehicle").addEventListener("change", loadVehicle);
  document.getElementById("run").addEventListener("change", loadRun);
  document.getElementById("trend-quantity").addEventListener("change", drawTrend);
  document.getElementById("wheel-legend").innerHTML = T.WHEELS.map((w) => `<span><i style="background:${T.wheelColor(w)}"></i>${T.wheelLabel(w)}</span>`).join("");

  (async () => {
    try {
      runs = await T.allRuns();
      const vehicles = [...new Set(runs.filter((r) => r.vehicle_id).map((r) => r.vehicle_id))].sort();
      const sel = document.getElementById("vehicle");
      sel.innerHTML = vehicles.map((v) => `<option translate="no">${T.esc(v)}</option>`).join("");
      if (T.param("vehicle_id") && vehicles.includes(T.param("vehicle_id"))) sel.value = T.param("vehicle_id");
      if (!vehicles.length) {
        for (const id of ["polar-plot", "orders-plot", "profile-plot", "trend-plot"]) T.emptyState(id, T._("No runs yet."), `<p>${T._("Upload a run on the Runs page.")}</p>`);
      } else {
        await loadVehicle();
      }
    } catch (e) {
      T.banner(T._("Could not load the wheels: {detail}", { detail: e.detail || e.message }));
    }
    T.ready();
  })();
})();
