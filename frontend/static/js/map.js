/* Map: a line geometry with a profile quantity of its latest processed run coloured along it.
 * Without a tile URL (TRACKVKF_MAP_TILE_URL) the geometry is drawn alone in a local metric
 * plane (km east/north of the line's centre): nothing is requested outside the server. With
 * one, the same data go on a MapLibre map over the operator's raster tiles. A click on a
 * segment opens the run's stiffness map at that km. The line's known discontinuities (assets)
 * are diamonds labelled with their type, placed at their km on the geometry. */
(function () {
  "use strict";
  const T = window.trackvkf;
  const tiles = T.boot.tiles || null;
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
    const text = pts.map((p) => p.x.type.replace(/_/g, " "));
    const hover = pts.map((p) => `${T.esc(p.x.type.replace(/_/g, " "))}${p.x.name ? " " + T.esc(p.x.name) : ""}<br>km ${p.x.km.toFixed(3)}${p.x.km_to != null ? "–" + p.x.km_to.toFixed(3) : ""}`);
    // labels alternate above and below, so that two assets close together stay readable
    const textposition = tiles ? "top center" : pts.map((_, i) => (i % 2 ? "bottom center" : "top center"));
    const base = { mode: "markers+text", name: "assets", text, textposition, hovertext: hover, hoverinfo: "text",
                   textfont: { size: 11, color: "#37474f" } };
    if (tiles) return Object.assign(base, { type: "scattermap", lon: pts.map((p) => p.a), lat: pts.map((p) => p.b), marker: { size: 10, color: "#37474f" } });
    return Object.assign(base, { type: "scatter", x: pts.map((p) => p.a / 1000), y: pts.map((p) => p.b / 1000),
                                 marker: { symbol: "diamond", size: 10, color: "#37474f", line: { color: "#fff", width: 1 } } });
  }

  function traces(geom, ind) {
    const segs = ind.segments;
    const withValue = segs.filter((s) => s.value !== null);
    const label = document.querySelector(`#quantity option[value="${ind.quantity}"]`);
    const name = label ? label.textContent : ind.quantity;
    const marker = {
      color: withValue.map((s) => s.value), colorscale: "YlOrRd", reversescale: true, size: 9,
      colorbar: { title: { text: `${name} (${ind.unit})`, side: "right" }, thickness: 14 },
    };
    const hover = `km %{customdata[1]:.3f}<br>${name} %{marker.color:.3f} ${ind.unit}<br>run %{customdata[0]}<extra></extra>`;
    const custom = withValue.map((s) => [ind.run_id, s.km, s.km_from, s.km_to]);
    if (tiles) {
      return [
        { type: "scattermap", mode: "lines", lon: geom.lon, lat: geom.lat, line: { color: "#555", width: 3 }, hoverinfo: "skip", name: "line" },
        { type: "scattermap", mode: "markers", lon: withValue.map((s) => s.lon), lat: withValue.map((s) => s.lat), marker, customdata: custom, hovertemplate: hover, name },
      ];
    }
    return [
      { type: "scatter", mode: "lines", x: geom.x_m.map((v) => v / 1000), y: geom.y_m.map((v) => v / 1000), line: { color: "#888", width: 3 }, hoverinfo: "skip", name: "line" },
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
      xaxis: T.axis("East of the line centre (km)", { zeroline: false }),
      yaxis: T.axis("North of the line centre (km)", { zeroline: false, scaleanchor: "x", scaleratio: 1 }),
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
    const assets = (await T.api.get("/assets", { line_id: geom.line_id, track: geom.track })).items;
    document.getElementById("map-title").textContent = `Line ${geom.line_id} track ${geom.track}`;
    document.getElementById("map-info").textContent = ind.run_id
      ? `run ${ind.run_id} · ${ind.segments.filter((s) => s.value !== null).length} segments with data · ${tiles ? "basemap on" : "no basemap (geometry only)"}`
      : "no processed run on this line and track yet";
    if (assets.length) document.getElementById("map-info").textContent += ` · ${assets.length} asset${assets.length === 1 ? "" : "s"} (◆)`;
    const all = traces(geom, ind);
    if (assets.length) all.push(assetTrace(geom, assets));
    await T.plot(el, all, layoutFor(geom), {
      filename: `map-${geom.line_id}-${geom.track}`,
      csv: () => ({ columns: ["km_from", "km_to", "km", "lon", "lat", `${ind.quantity}_${ind.unit}`],
                   rows: ind.segments.map((s) => [s.km_from, s.km_to, s.km, s.lon, s.lat, s.value]) }),
    });
    el.removeAllListeners && el.removeAllListeners("plotly_click");
    el.on("plotly_click", (ev) => {
      const p = ev.points && ev.points[0];
      if (!p || !p.customdata || !p.customdata[0]) return;
      const [runId, , a, b] = p.customdata;
      window.location.href = runLink({ km_from: a, km_to: b }, runId);
    });
  }

  (async function init() {
    const el = document.getElementById("map-plot");
    try {
      geometries = (await T.api.get("/geometry")).items;
      if (!geometries.length) {
        T.emptyState(el, "No line geometry yet", "<p>Import a GeoJSON with km stations: <code>POST /api/v1/geometry</code> (see docs/positioning.md).</p>");
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
      T.banner(`Could not load the map: ${e.detail || e.message}`);
    }
    T.ready();
  })();
})();
