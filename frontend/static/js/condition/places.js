/* Condition page: the places (the work list) of the line, ranked by the server (tier, then time to
 * limit, then size), filtered by tier and status; CSV and GeoJSON of the same filter. The first
 * column is the rank in the list; the place's own id is written under its km. */
(function () {
  "use strict";
  const C = window.trackvkfCondition;
  const { T, $, state } = C;

  function checked(name) { return [...document.querySelectorAll(`#places-filter input[name='${name}']:checked`)].map((x) => x.value); }

  function actionsText(p) {
    if (!p.actions.length) return `<span class="muted">–</span>`;
    return p.actions.map((a) => `${T.esc(T.label("maintenance type", a.kind))} ${T.date(a.date)}`).join(", ");
  }

  async function drawPlaces(view = C.view()) {
    const body = $("places-body");
    if (!view.live()) return null;  // a draw for a line no longer chosen writes nothing
    const { line_id, track } = view;
    const params = { line_id, track, tier: checked("tier"), status: checked("status"),
                     include_closed: $("include-inactive").checked ? "true" : undefined };
    const q = C.qs(params);
    $("places-csv").href = `${T.boot.api}/condition/places.csv?${q}&limit=1000&header=labels`;
    $("places-geojson").href = `${T.boot.api}/condition/places.geojson?${q}&limit=1000`;
    if (!params.tier.length || !params.status.length) {
      state.placesSeq++;
      state.placeList = { items: [], total: 0 };
      body.innerHTML = `<tr><td colspan="12" class="muted">${T.esc(T._("Choose at least one tier and one status."))}</td></tr>`;
      $("places-info").textContent = "";
      return state.placeList;
    }
    const mine = ++state.placesSeq;
    const res = await T.api.get(`/condition/places?${q}&limit=200`);
    // a newer filter is on its way, or another line was chosen meanwhile (its own draw writes the list)
    if (mine !== state.placesSeq || !view.live()) return null;
    state.placeList = res;
    $("places-info").textContent = T.ngettext("{n} place", "{n} places", res.total) +
      (res.total > res.items.length ? ", " + T._("first {n}", { n: res.items.length }) : "");
    if (!res.items.length) {
      body.innerHTML = `<tr><td colspan="12" class="muted">${T.esc(T._("No place with these tiers and statuses."))}</td></tr>`;
      return res;
    }
    const confirming = T.esc(T._("runs confirming"));
    body.innerHTML = res.items.map((p, i) => `<tr data-place="${p.id}" class="${p.id === state.placeId ? "selected" : ""}${p.muted ? " is-muted" : ""}">
      <td class="num">${i + 1}</td><td>${C.tierBadge(p.tier)}${C.confirmText(p)}</td>
      <td>${T.fmt(p.km_from, 3)}–${T.fmt(p.km_to, 3)}<br><span class="muted">${T.fmt(p.length_m, 0)} m · ${T.esc(T._("place {id}", { id: p.id }))}</span></td>
      <td class="num nowrap">${C.peakText(p)}</td><td class="wrap">${C.trendText(p)}</td><td class="wrap">${C.limitText(p)}</td>
      <td>${C.statusBadge(p.status)}</td>
      <td>${T.date(p.first_seen)}</td><td class="num" title="${confirming}">${p.runs_confirming}</td>
      <td class="wrap">${actionsText(p)}</td>
      <td class="wrap">${C.assetsText(p)}</td>
      <td><button class="btn small" type="button" data-act="history">${T.esc(T._("History"))}</button>
        <a class="btn small" href="${C.mapLink(p.last_run_id, p.km_from, p.km_to)}">${T.esc(T._("Map"))}</a></td></tr>`).join("");
    return res;
  }

  $("places-filter").addEventListener("change", () => drawPlaces().catch(C.fail(T._("Places"))));
  $("places-body").addEventListener("click", (ev) => {
    const btn = ev.target.closest("button[data-act='history']");
    if (!btn) return;
    const row = btn.closest("tr");
    C.drawPlace(row.dataset.place).then((p) => {
      if (!p) return null;  // another place or line was chosen meanwhile
      $("cond-trend-km").value = p.peak_km.toFixed(3);
      $("cond-trend-seg").value = String(C.RULES.fineSegmentM);
      $("place-card").scrollIntoView({ behavior: "smooth", block: "start" });
      return C.drawTrend();
    }).catch(C.fail(T._("Place")));
  });

  C.drawPlaces = drawPlaces;
})();
