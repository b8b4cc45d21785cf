/* Map: a line geometry with a quantity of its latest processed run coloured along it (the
 * stiffness index first, the raw amplitude and the other profile columns one click away).
 * Without a tile URL (TRACKVKF_MAP_TILE_URL) the geometry is drawn alone in a local metric
 * plane (km east/north of the line's centre): nothing is requested outside the server. With
 * one, the same data go on a MapLibre map over the operator's raster tiles. A click on a
 * segment opens the run's stiffness map at that km, a click on a place the place on the
 * Condition page. On the line: the km (labels at round values), the places to act on (circles
 * in their tier's colour at their peak), the known discontinuities (assets: diamonds labelled
 * with their type). */
(function () {
  "use strict";
  const T = window.trackvkf;
  const tiles = T.boot.tiles || null;
  const TIER_COLORS = T.TIER_COLORS;
  let geometries = [];

  function option(g) { return `<option value="${g.id}">${T.esc(g.line_id)} / ${T.esc(g.track)} (km ${T.fmt(g.km_from)}–${T.fmt(g.km_to)})</option>`; }

  function runLink(seg, runId) {
    const a = Math.min(seg.km_from, seg.km_to) - 0.05, b = Math.max(seg.km_from, seg.km_to) + 0.05;
    return `/runs/${runId}?km_from=${a.toFixed(3)}&km_to=${b.toFixed(3)}`;
  }

  /* Linear interpolation of the geometry's vertices at km (null outside). */
  function along(geom, km, key) {
    const k = geom.km, v = geom[key];
    if (!k || !k.length) return null;
    const up = k[k.length - 1] >= k[0];
    for (let i = 1; i < k.length; i++) {
      const a = k[i - 1], b = k[i];
      if ((up && km >= a && km <= b) || (!up && km <= a && km >= b)) {
        const t = b === a ? 0 : (km - a) / (b - a);
        return v[i - 1] + t * (v[i] - v[i - 1]);
      }
    }
    return null;
  }

  function assetTrace(geom, assets) {
    const pts = assets.map((x) => {
      const km = x.km_to != null ? (x.km + x.km_to) / 2 : x.km;
      return tiles
        ? { a: x.lon ?? along(geom, km, "lon"), b: x.lat ?? along(geom, km, "lat"), x }
        : { a: along(geom, km, "x_m"), b: along(geom, km, "y_m"), x };
    }).filter((p) => p.a !== null && p.b !== null);
    const text = pts.map((p) => T.label("asset type", p.x.type));
    const hover = pts.map((p) => `${T.esc(T.label("asset type", p.x.type))}${p.x.name ? " " + T.esc(p.x.name) : ""}<br>km ${T.fmt(p.x.km, 3)}${p.x.km_to != null ? "–" + T.fmt(p.x.km_to, 3) : ""}`);
    // labels alternate above and below, so that two assets close together stay readable
    const textposition = tiles ? "top center" : pts.map((_p, i) => (i % 2 ? "bottom center" : "top center"));
    const base = { mode: "markers+text", name: T._("assets"), text, textposition, hovertext: hover, hoverinfo: "text",
                   textfont: { size: 11, color: "#37474f" } };
    if (tiles) return Object.assign(base, { type: "scattermap", lon: pts.map((p) => p.a), lat: pts.map((p) => p.b), marker: { size: 10, color: "#37474f" } });
    return Object.assign(base, { type: "scatter", x: pts.map((p) => p.a / 1000), y: pts.map((p) => p.b / 1000),
                                 marker: { symbol: "diamond", size: 10, color: "#37474f", line: { color: "#fff", width: 1 } } });
  }

  /* A point on the line at km: [x, y] in the plane (km) or [lon, lat] on tiles; null outside. */
  function pointAt(geom, km) {
    const a = tiles ? along(geom, km, "lon") : along(geom, km, "x_m");
    const b = tiles ? along(geom, km, "lat") : along(geom, km, "y_m");
    if (a === null || b === null) return null;
    return tiles ? [a, b] : [a / 1000, b / 1000];
  }

  /* Labels at round km along the line (about eight of them). */
  function kmTrace(geom) {
    const k = geom.km || [];
    if (k.length < 2) return null;
    const lo = Math.min(k[0], k[k.length - 1]), hi = Math.max(k[0], k[k.length - 1]);
    const step = [0.1, 0.2, 0.5, 1, 2, 5, 10, 20, 50, 100].find((s) => (hi - lo) / s <= 8) || 100;
    const pts = [];
    for (let km = Math.ceil(lo / step - 1e-9) * step; km <= hi + 1e-9; km += step) {
      const p = pointAt(geom, km);
      if (p) pts.push([km, p]);
    }
    const digits = step < 1 ? 1 : 0;
    const text = pts.map(([km]) => `km ${T.fmt(km, digits)}`);
    const base = { mode: "markers+text", name: "km", text, textposition: "middle right", hoverinfo: "skip",
                   textfont: { size: 10, color: "#5d6b7a" }, showlegend: false };
    if (tiles) return Object.assign(base, { type: "scattermap", lon: pts.map(([, p]) => p[0]), lat: pts.map(([, p]) => p[1]), marker: { size: 5, color: "#5d6b7a" } });
    return Object.assign(base, { type: "scatter", x: pts.map(([, p]) => p[0]), y: pts.map(([, p]) => p[1]),
                                 marker: { symbol: "line-ns", size: 8, color: "#5d6b7a", line: { width: 1.5, color: "#5d6b7a" } } });
  }

  /* The places to act on: a circle at each place's peak in its tier's colour. */
  function placeTrace(geom, places) {
    const pts = places.map((pl) => ({ pl, p: pointAt(geom, pl.peak_km) })).filter((x) => x.p);
    if (!pts.length) return null;
    const hover = pts.map(({ pl }) => `${T.esc(T._("Place {id}", { id: pl.id }))} · ${T.esc(T.label("tier", pl.tier))}<br>` +
      `km ${T.fmt(pl.km_from, 3)}–${T.fmt(pl.km_to, 3)}<br>${T.esc(T.label("place status", pl.status))}`);
    const base = { mode: "markers", name: T._("places"), hovertext: hover, hoverinfo: "text",
                   customdata: pts.map(({ pl }) => ["place", pl.id]) };
    const marker = { size: 15, color: pts.map(({ pl }) => TIER_COLORS[pl.tier] || "#c62828"), opacity: 0.85 };
    if (tiles) return Object.assign(base, { type: "scattermap", lon: pts.map(({ p }) => p[0]), lat: pts.map(({ p }) => p[1]), marker });
    return Object.assign(base, { type: "scatter", x: pts.map(({ p }) => p[0]), y: pts.map(({ p }) => p[1]),
                                 marker: Object.assign(marker, { symbol: "circle-open", line: { width: 3 } }) });
  }

  /* The CSV column of the quantity: its name with its unit (as the other pages' CSVs). */
  function csvColumn(ind) {
    const suffix = { "m/s²": "_mps2", "m/s": "_mps", kN: "_kn", mm: "_mm", "ln units": "" }[ind.unit] ?? "";
    const base = ind.quantity === "speed_mean" ? "speed" : ind.quantity.replace(/_mm$/, "");
    return base + suffix;
  }

  function unitText(unit) { return unit === "ln units" ? T._("ln units") : unit; }

  function traces(geom, ind) {
    const segs = ind.segments;
    const withValue = segs.filter((s) => s.value !== null);
    const label = document.querySelector(`#quantity option[value="${ind.quantity}"]`);
    const name = label ? label.textContent : ind.quantity;
    const index = ind.quantity === "stiffness_index";
    const marker = {
      color: withValue.map((s) => s.value), colorscale: index ? "RdBu" : "YlOrRd", reversescale: !index, size: 9,
      cmid: index ? 0 : undefined,
      colorbar: { title: { text: `${name} (${unitText(ind.unit)})`, side: "right" }, thickness: 14 },
    };
    const hover = `km %{customdata[1]:.3f}<br>${T.esc(name)} %{marker.color:.3f} ${T.esc(unitText(ind.unit))}<br>${T.esc(T._("run {run}", { run: "%{customdata[0]}" }))}<extra></extra>`;
    const custom = withValue.map((s) => [ind.run_id, s.km, s.km_from, s.km_to]);
    if (tiles) {
      return [
        { type: "scattermap", mode: "lines", lon: geom.lon, lat: geom.lat, line: { color: "#555", width: 3 }, hoverinfo: "skip", name: T._("line") },
        { type: "scattermap", mode: "markers", lon: withValue.map((s) => s.lon), lat: withValue.map((s) => s.lat), marker, customdata: custom, hovertemplate: hover, name },
      ];
    }
    return [
      { type: "scatter", mode: "lines", x: geom.x_m.map((v) => v / 1000), y: geom.y_m.map((v) => v / 1000), line: { color: "#888", width: 3 }, hoverinfo: "skip", name: T._("line") },
      { type: "scatter", mode: "markers", x: withValue.map((s) => s.x_m / 1000), y: withValue.map((s) => s.y_m / 1000), marker, customdata: custom, hovertemplate: hover, name },
    ];
  }

  function layoutFor(geom) {
    if (tiles) {
      const lon = geom.lon.reduce((a, b) => a + b, 0) / geom.lon.length;
      const lat = geom.lat.reduce((a, b) => a + b, 0) / geom.lat.length;
      return {
        showlegend: false, margin: { l: 10, r: 10, t: 10, b: 10 },
        map: {
          center: { lon, lat }, zoom: 11,
          style: { version: 8, sources: { base: { type: "raster", tiles: [tiles.url], tileSize: 256, attribution: tiles.attribution || "" } },
                   layers: [{ id: "base", type: "raster", source: "base" }] },
        },
      };
    }
    return {
      showlegend: false,
      xaxis: T.axis(T._("East of the line centre (km)"), { zeroline: false }),
      yaxis: T.axis(T._("North of the line centre (km)"), { zeroline: false, scaleanchor: "x", scaleratio: 1 }),
      margin: { l: 70, r: 30, t: 20, b: 60 },
    };
  }

  async function show() {
    const el = document.getElementById("map-plot");
    const id = document.getElementById("geometry").value;
    const quantity = document.getElementById("quantity").value;
    const segment = Number(document.getElementById("segment").value) || T.boot.map_segment_m;
    const [geom, ind] = await Promise.all([
      T.api.get(`/geometry/${id}`),
      T.api.get(`/geometry/${id}/indicator`, { quantity, segment_m: segment }),
    ]);
    const [assetList, placeList] = await Promise.all([
      T.api.get("/assets", { line_id: geom.line_id, track: geom.track }),
      T.api.optional("/condition/places", { line_id: geom.line_id, track: geom.track, limit: 500 }),
    ]);
    const assets = assetList.items, places = (placeList && placeList.items) || [];
    document.getElementById("map-title").textContent = T._("Line {line} track {track}", { line: geom.line_id, track: geom.track });
    const info = [];
    if (ind.run_id) {
      info.push(T._("run {run}", { run: ind.run_id }),
        T.ngettext("{n} segment with data", "{n} segments with data", ind.segments.filter((s) => s.value !== null).length),
        tiles ? T._("basemap on") : T._("no basemap (geometry only)"));
    } else {
      info.push(T._("no processed run on this line and track yet"));
    }
    if (places.length) info.push(T.ngettext("{n} place (○)", "{n} places (○)", places.length));
    if (assets.length) info.push(T.ngettext("{n} asset (◆)", "{n} assets (◆)", assets.length));
    document.getElementById("map-info").textContent = info.join(" · ");
    const all = traces(geom, ind);
    const km = kmTrace(geom);
    if (km) all.push(km);
    if (assets.length) all.push(assetTrace(geom, assets));
    const pl = placeTrace(geom, places);
    if (pl) all.push(pl);
    legend(places);
    await T.plot(el, all, layoutFor(geom), {
      filename: `map-${geom.line_id}-${geom.track}`,
      csv: () => ({ columns: ["km_from", "km_to", "km", "lon", "lat", csvColumn(ind)],
                   rows: ind.segments.map((s) => [s.km_from, s.km_to, s.km, s.lon, s.lat, s.value]) }),
    });
    el.removeAllListeners && el.removeAllListeners("plotly_click");
    el.on("plotly_click", (ev) => {
      const p = ev.points && ev.points[0];
      if (!p || !p.customdata || !p.customdata[0]) return;
      if (p.customdata[0] === "place") {
        window.location.href = `/condition?line_id=${encodeURIComponent(geom.line_id)}&track=${encodeURIComponent(geom.track)}&place=${p.customdata[1]}`;
        return;
      }
      const [runId, , a, b] = p.customdata;
      window.location.href = runLink({ km_from: a, km_to: b }, runId);
    });
  }

  /* Under the map: what the marks are (the places' tiers in their colours). */
  function legend(places) {
    const box = document.getElementById("map-legend");
    const tiers = [...new Set(places.map((p) => p.tier))];
    const items = tiers.map((t) => `<span class="swatch-item"><span class="swatch ring" style="border-color:${TIER_COLORS[t] || "#c62828"}"></span>${T.esc(T.label("tier", t))}</span>`);
    box.innerHTML = `<span class="muted">${T.esc(T._("On the line:"))}</span> ` +
      (items.length ? `${T.esc(T._("places to act on, by tier:"))} ${items.join("")} · ` : "") +
      `${T.esc(T._("◆ assets"))} · ${T.esc(T._("km marks along the line"))}`;
    box.hidden = false;
  }

  (async function init() {
    const el = document.getElementById("map-plot");
    try {
      geometries = (await T.api.get("/geometry")).items;
      if (!geometries.length) {
        T.emptyState(el, T._("No line geometry yet"), `<p>${T._("Import a GeoJSON with km stations: {call} (see docs/positioning.md).", { call: "<code>POST /api/v1/geometry</code>" })}</p>`);
      } else {
        document.getElementById("geometry").innerHTML = geometries.map(option).join("");
        const want = T.param("geometry_id");
        if (want) document.getElementById("geometry").value = want;
        await show();
      }
      document.getElementById("map-controls").addEventListener("submit", async (e) => {
        e.preventDefault();
        try { await show(); } catch (err) { T.banner(err.detail || err.message); }
      });
    } catch (e) {
      T.banner(T._("Could not load the map: {detail}", { detail: e.detail || e.message }));
    }
    T.ready();
  })();
})();
