/* Condition page: one place's history — its observations over the runs against its class's tier
 * limits (from the boot data), the matched passes of the segment it is read at (and a developing place's trend), the events, the maintenance over it within its runs' span, the
 * status history — and its status workflow (engineers change it with a comment; viewers read it). */
(function () {
  "use strict";
  const C = window.trackvkfCondition;
  const { T, $, state } = C;
  const EMPTY = { title: $("place-title").innerHTML, events: $("place-events-body").innerHTML,
                  maint: $("place-maint-body").innerHTML, status: $("place-status-body").innerHTML };

  function tierChange(e) {
    if (e.old_tier && e.new_tier && e.old_tier !== e.new_tier) return `${C.tierBadge(e.old_tier)} → ${C.tierBadge(e.new_tier)}`;
    return e.new_tier || e.old_tier ? C.tierBadge(e.new_tier || e.old_tier) : "–";
  }

  async function drawPlace(id, view = C.view()) {
    if (!view.live()) return null;
    state.placeId = Number(id);
    for (const tr of document.querySelectorAll("#places-body tr[data-place]")) tr.classList.toggle("selected", Number(tr.dataset.place) === state.placeId);
    const mine = ++state.placeSeq;
    // the place and its passes together: the card's title and its chart change at once
    const [p, pp] = await Promise.all([T.api.get(`/condition/places/${state.placeId}`),
                                       T.api.get(`/condition/places/${state.placeId}/passes`)]);
    // another place (or a newer state of this one) is on its way, or another line was chosen meanwhile
    if (mine !== state.placeSeq || !view.live()) return null;
    $("place-title").innerHTML = `${T.esc(T._("Place {id}: km {from}–{to}", { id: p.id, from: T.fmt(p.km_from, 3), to: T.fmt(p.km_to, 3) }))} ${C.tierBadge(p.tier)}`;
    const link = $("place-map");
    link.href = C.mapLink(p.last_run_id, p.km_from, p.km_to);
    link.hidden = false;
    const when = C.statusDate(p);
    const kv = [
      [T._("Action"), T.esc(T.label("tier action", p.tier))],
      [T._("Peak"), `${C.peakText(p)} <span class="muted">(${T.esc(T._("index {index}", { index: T.fmt(p.peak, 3) }))})</span>`],
      [T._("Evidence"), T.esc(p.evidence.map((e) => T.label("evidence", e)).join(", ") || "–")],
      [T._("Wheels"), `<span translate="no">${T.esc(p.wheels.join(", ") || "–")}</span>`],
      [T._("Trend per year (95 %)"), C.trendText(p)], [T._("Time to limit"), C.limitText(p)],
      [T._("First seen / last confirmed"), `${T.date(p.first_seen)} / ${T.date(p.last_confirmed)}`],
      [T._("Runs confirming"), String(p.runs_confirming) + (p.active ? "" : ` <span class="muted">(${T.esc(T._("not seen lately"))})</span>`) + C.confirmText(p)],
      [T._("Status"), C.statusBadge(p.status) + (when ? ` <span class="muted">${T.esc(when.text)}</span>` : "")],
      [T._("Assets"), C.assetsText(p)], [T._("Method version"), `<span class="muted" translate="no">${T.esc(p.method_version || "–")}</span>`],
    ];
    $("place-kv").innerHTML = kv.map(([k, v]) => `<div><span>${T.esc(k)}</span><b>${v}</b></div>`).join("");
    await drawPlaceHistory(p, pp);
    if (!view.live()) return null;
    $("place-events-body").innerHTML = p.events.length ? p.events.map((e) => `<tr><td>${T.date(e.time)}</td><td>${T.esc(T.label("place event", e.kind))}</td>
      <td>${e.run_id ?? "–"}</td><td>${tierChange(e)}</td></tr>`).join("")
      : `<tr><td colspan="4" class="muted">${T.esc(T._("No events."))}</td></tr>`;
    $("place-maint-body").innerHTML = p.maintenance.length ? p.maintenance.map((m) => `<tr><td>${T.date(m.date)}</td><td>${T.esc(T.label("maintenance type", m.kind || m.type))}</td>
      <td>${T.fmt(m.km_from, 3)}–${T.fmt(m.km_to, 3)}</td></tr>`).join("")
      : `<tr><td colspan="3" class="muted">${T.esc(T._("No maintenance action over this place within its runs' span."))}</td></tr>`;
    // the comments are the engineers' own words (and the service's, in English): shown as written
    $("place-status-body").innerHTML = p.status_history.length ? p.status_history.map((h) => `<tr><td>${T.datetime(h.at)}</td><td translate="no">${T.esc(h.by)}</td>
      <td>${T.esc(T.label("place status", h.old))} → <b>${T.esc(T.label("place status", h.new))}</b></td><td class="wrap" translate="no">${T.esc(h.comment)}</td></tr>`).join("")
      : `<tr><td colspan="4" class="muted">${T.esc(T._("Status {status} since the place was found; no change yet.", { status: T.label("place status", p.status) }))}</td></tr>`;
    $("status-form").hidden = !C.canEdit();
    $("status-readonly").hidden = C.canEdit();
    // the form starts from the place's status when another place is shown; a redraw of the same place
    // (a click's answer landing late) leaves what the engineer is choosing alone
    if (state.formPlace !== p.id) {
      state.formPlace = p.id;
      $("status-new").value = p.status;
      $("status-comment").value = "";
    }
    // the card's parts are all this place's now (a test, or a screen reader's user, waits for this)
    $("place-card").dataset.place = String(p.id);
    return p;
  }

  /* The limits of the place's class on its side (soft: below zero), from the boot data. */
  function limitLines(p) {
    const limits = C.RULES.tierLimits[p.class] || C.RULES.tierLimits[""] || {};
    const sign = p.direction === "soft" ? -1 : 1;
    return Object.entries(limits).map(([tier, v]) => ({ tier, y: sign * Math.abs(v) }));
  }

  /* The segment the place is read at, run by run (GET …/passes: its peak, or where a developing place grows
   * fastest): its matched passes as the place was read against
   * them, the other passes (another speed or vehicle; off until asked for) and a developing place's trend. */
  function passTraces(pp) {
    if (!pp || !pp.passes.length) return [];
    const seg = `km ${T.fmt(pp.km_from, 3)}–${T.fmt(pp.km_to, 3)}`;
    const hover = `%{x|${T.DATE_FMT}} ${T.esc(T._("run {run}", { run: "%{customdata[0]}" }))}<br>${T.esc(T._("stiffness index"))} %{y:.3f}` +
      "<br>%{customdata[1]:.0f} km/h, %{customdata[2]}<extra></extra>";
    const matched = pp.passes.filter((o) => o.matched_index !== null);
    const other = pp.passes.filter((o) => o.matched_index === null);
    const out = [];
    if (matched.length) out.push({ type: "scatter", mode: "markers", name: pp.at === "trend" ? T._("matched passes where it grows fastest ({segment})", { segment: seg })
      : T._("matched passes at its peak segment ({segment})", { segment: seg }),
      x: matched.map((o) => o.run_time), y: matched.map((o) => o.matched_index),
      marker: { symbol: "circle-open", size: 8, color: "#3f6ea5", line: { width: 1.5 } },
      customdata: matched.map((o) => [o.run_id, o.speed_kmh, o.vehicle || "–"]), hovertemplate: hover });
    if (other.length) out.push({ type: "scatter", mode: "markers", name: T._("other passes (another speed or vehicle)"), visible: "legendonly",
      x: other.map((o) => o.run_time), y: other.map((o) => o.index), marker: { size: 5, color: "#aab6c2" },
      customdata: other.map((o) => [o.run_id, o.speed_kmh, o.vehicle || "–"]), hovertemplate: hover });
    const tr = pp.trend;
    if (tr) out.push({ type: "scatter", mode: "lines", name: T._("trend over the matched passes ({rate} a year)", { rate: `${C.signed(C.ampRate(tr.rate_per_year), 0)} %` }),
      x: [tr.from_time, tr.to_time], y: [tr.from_index, tr.to_index], line: { color: "#b5651d", width: 2, dash: "dash" },
      hovertemplate: `%{x|${T.DATE_FMT}}: %{y:.3f}<extra></extra>` });
    return out;
  }

  async function drawPlaceHistory(p, pp) {
    const el = $("place-history");
    const obs = p.observations;
    if (!obs.length) { T.emptyState(el, T._("No observation of this place."), ""); return; }
    const x = obs.map((o) => o.run_time);
    const traces = [
      { type: "scatter", mode: "lines+markers", name: T._("stiffness index at the place (ln units)"), x, y: obs.map((o) => o.level),
        line: { color: "#1d2733", width: 2 }, marker: { size: 9, color: obs.map((o) => T.TIER_COLORS[o.tier] || "#999") },
        customdata: obs.map((o) => [o.run_id, T.label("tier", o.tier), o.speed_kmh, o.km_from, o.km_to]),
        hovertemplate: `%{x|${T.DATE_FMT}} ${T.esc(T._("run {run}", { run: "%{customdata[0]}" }))}<br>${T.esc(T._("stiffness index"))} %{y:.3f} (%{customdata[1]})` +
          "<br>km %{customdata[3]:.3f}–%{customdata[4]:.3f}, %{customdata[2]:.0f} km/h<extra></extra>" },
    ];
    traces.push(...passTraces(pp));
    const withChange = obs.filter((o) => o.change !== null);
    if (withChange.length) traces.push({ type: "scatter", mode: "markers", name: T._("change against its baseline"), x: withChange.map((o) => o.run_time),
      y: withChange.map((o) => o.change), marker: { symbol: "diamond-open", size: 8, color: "#5d6b7a" },
      hovertemplate: `%{x|${T.DATE_FMT}}: ${T.esc(T._("change"))} %{y:.3f}<extra></extra>` });
    const shapes = [], annotations = [];
    for (const { tier, y } of limitLines(p)) {
      const next = tier === p.next_tier;
      shapes.push({ type: "line", xref: "paper", x0: 0, x1: 1, yref: "y", y0: y, y1: y,
        line: { color: T.TIER_COLORS[tier], width: next ? 1.5 : 1, dash: next ? "dot" : "dashdot" } });
      annotations.push({ xref: "paper", x: 1, y, yanchor: "bottom", xanchor: "right", showarrow: false,
        text: T.esc(T._("{tier} limit", { tier: T.label("tier", tier) })), font: { size: 11, color: T.TIER_COLORS[tier] } });
    }
    for (const m of p.maintenance) {
      shapes.push({ type: "line", xref: "x", yref: "paper", x0: m.date, x1: m.date, y0: 0, y1: 1, line: { color: "#2e7d32", width: 2, dash: "dash" } });
      annotations.push({ x: m.date, y: 1, xref: "x", yref: "paper", yanchor: "bottom", showarrow: false, text: T.esc(T.label("maintenance type", m.kind || m.type)), font: { size: 11, color: "#2e7d32" } });
    }
    await T.plot(el, traces, {
      xaxis: T.dateAxis(T._("Run date"), [...x, ...(pp ? pp.passes.map((o) => o.run_time) : [])], {}, 30),
      yaxis: T.axis(T._("Stiffness index ln(A / A_ref) (ln units)"), { zeroline: true }),
      shapes, annotations, margin: { l: 80, r: 30, t: 30, b: 55 },
    }, {
      filename: `place-${p.id}-history`,
      // the place's observations, then its segment's passes (series "pass"; matched_index: as read against)
      csv: () => ({ columns: ["series", "run_id", "run_time", "speed_kmh", "level", "change", "tier", "km_from", "km_to", "method_version", "vehicle", "matched_index"],
                    rows: [...obs.map((o) => ["observation", o.run_id, o.run_time, o.speed_kmh, o.level, o.change, o.tier, o.km_from, o.km_to, o.method_version, null, null]),
                           ...(pp ? pp.passes.map((o) => ["pass", o.run_id, o.run_time, o.speed_kmh, o.index, null, null, pp.km_from, pp.km_to, null, o.vehicle, o.matched_index]) : [])] }),
    });
  }

  $("status-form").addEventListener("submit", async (ev) => {
    ev.preventDefault();
    const comment = $("status-comment").value.trim();
    if (!comment) { T.banner(T._("A status change needs a comment: what was decided and why.")); $("status-comment").focus(); return; }
    const status = $("status-new").value;
    try {
      await T.api.patch(`/condition/places/${state.placeId}/status`, { status, comment });
      $("status-comment").value = "";
      T.banner(T._("Place {id}: status set to {status}.", { id: state.placeId, status: T.label("place status", status) }), "ok");
      await C.drawPlaces();
      await drawPlace(state.placeId);
    } catch (e) { T.banner(T._("Status not changed (HTTP {status}): {detail}", { status: e.status, detail: e.detail })); }
  });

  /* No place on the line shown: the card says so and keeps nothing of another line's place. */
  function clearPlace(why, hint) {
    state.placeId = null;
    delete $("place-card").dataset.place;
    $("place-title").innerHTML = EMPTY.title;
    $("place-map").hidden = true;
    $("place-kv").innerHTML = "";
    $("place-events-body").innerHTML = EMPTY.events;
    $("place-maint-body").innerHTML = EMPTY.maint;
    $("place-status-body").innerHTML = EMPTY.status;
    $("status-form").hidden = true;
    $("status-readonly").hidden = true;
    state.formPlace = null;
    T.emptyState("place-history", why, hint);
  }

  C.drawPlace = drawPlace;
  C.clearPlace = clearPlace;
})();
