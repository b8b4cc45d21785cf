/* Condition page: the maintenance actions of the line and their effect — the change of the index
 * over the action's extent relative to the surrounding track, after − before (negative: lower
 * amplitude), with the runs it rests on (n before / after), the slope after, and how long it held
 * as far as the runs saw (never a projection past the last run) — and one action's before/after. */
(function () {
  "use strict";
  const C = window.trackvkfCondition;
  const { T, $, state } = C;

  /* the ±1 σ interval of a change (ln units) in per cent of the amplitude */
  function rangeText(low, high) {
    if (low === undefined || low === null || high === undefined || high === null) return "";
    const title = T.esc(T._("±1 σ (68 %)"));
    return ` <span class="muted" title="${title}">(${C.signed(100 * Math.expm1(low), 1)} … ${C.signed(100 * Math.expm1(high), 1)})</span>`;
  }
  function changeText(a) {
    if (a.recovery === null || a.recovery === undefined) return "–";
    return `${C.signed(a.recovery_pct, 1)} %${rangeText(a.recovery_low, a.recovery_high)} <span class="muted">(${C.signed(a.recovery, 3)})</span>`;
  }
  function heldText(a) {
    if (a.lasted_days_observed !== null && a.lasted_days_observed !== undefined) {
      if (!a.rail_surface) return T.fmt(a.lasted_days_observed, 0);
      const of = T._("of the rail surface's change");
      return `<span title="${T.esc(of)}">${T.fmt(a.lasted_days_observed, 0)}</span>`;
    }
    const still = a.followed_days === null || a.followed_days === undefined
      ? T._("the change still held at the last run after the action")
      : T._("not lost within the {days} days the runs saw after the action", { days: T.fmt(a.followed_days, 0) });
    return `<span class="muted" title="${T.esc(still)}">–</span>`;
  }

  /* the rail surface's response across a grinding (the support's change is read against the new surface) */
  function railText(a) {
    if (!a.rail_surface) return "";
    const title = T._("the rail surface's response across the work; the support's change is read against the new surface's own baseline");
    if (a.rail_surface_change === null || a.rail_surface_change === undefined) return "";
    const text = T._("rail surface {pct} %", { pct: C.signed(a.rail_surface_change_pct, 1) });
    return `<br><span class="muted" title="${T.esc(title)}">${T.esc(text)}</span>${rangeText(a.rail_surface_change_low, a.rail_surface_change_high)}`;
  }
  function slopeTitle(a) {
    if (a.slope_after_per_year === null) return "";
    return T.esc(T._("{rate} ln units a year", { rate: C.signed(a.slope_after_per_year, 2) }));
  }
  async function drawActions(view = C.view()) {
    const body = $("actions-body");
    if (!view.live()) return null;  // a draw for a line no longer chosen writes nothing
    const { line_id, track } = view;
    const res = await T.api.get("/condition/maintenance-effect", { line_id, track });
    if (!view.live()) return;  // another line was chosen meanwhile
    if (!res.items.length) {
      body.innerHTML = `<tr><td colspan="7" class="muted">${T._("No maintenance actions imported for this line ({call}).", { call: "<code>POST /api/v1/reference/maintenance</code>" })}</td></tr>`;
      T.emptyState("cond-effect", T._("No maintenance action."), "");
      return;
    }
    // an action no run of the line passed over (before or after) has no before/after view
    const covered = (a) => a.n_runs > 0;
    const uncovered = T.esc(T._("no run of this line covers it"));
    body.innerHTML = res.items.map((a) => `<tr ${covered(a) ? `data-action="${a.action_id}" style="cursor:pointer"` : `class="muted" title="${uncovered}"`}>
      <td>${T.date(a.date)}</td><td>${T.esc(T.label("maintenance type", a.type))}</td><td>${T.fmt(a.km_from, 3)}–${T.fmt(a.km_to, 3)}</td>
      <td class="num">${a.n_runs_before} / ${a.n_runs_after}</td><td class="num">${changeText(a)}${railText(a)}</td>
      <td class="num" title="${slopeTitle(a)}">${a.slope_after_per_year === null ? "–" : C.signed(C.ampRate(a.slope_after_per_year), 1)}</td>
      <td class="num">${heldText(a)}</td></tr>`).join("");
    const best = res.items.find((a) => a.recovery !== null) || res.items.find(covered);
    if (!best) {
      $("effect-title").textContent = T._("Before / after");
      T.emptyState("cond-effect", T._("No run of this line covers its maintenance actions yet."),
        `<p>${T._("The before/after view needs runs over the action's km range.")}</p>`);
      return;
    }
    await drawEffect(best.action_id, view);
  }

  async function drawEffect(actionId, view = C.view()) {
    const el = $("cond-effect");
    const e = await T.api.get(`/condition/maintenance-effect/${actionId}`);
    if (!view.live()) return;
    state.effect = e;
    $("effect-title").textContent = T._("Before / after: {type} on {date}, km {from}–{to}",
      { type: T.label("maintenance type", e.type), date: T.date(e.date), from: T.fmt(e.km_from, 3), to: T.fmt(e.km_to, 3) });
    const xs = e.profile_km.map((k) => k + 0.005);
    const traces = [
      { type: "scatter", mode: "lines", name: T.ngettext("before (n = {n} run)", "before (n = {n} runs)", e.n_runs_before), x: xs, y: e.profile_before, line: { color: "#c62828", width: 2 } },
      { type: "scatter", mode: "lines", name: T.ngettext("after (n = {n} run)", "after (n = {n} runs)", e.n_runs_after), x: xs, y: e.profile_after, line: { color: "#1565c0", width: 2 } },
      { type: "scatter", mode: "markers", name: T._("per run"), x: e.series.map((p) => p.start_time), y: e.series.map((p) => p.condition_index),
        xaxis: "x2", yaxis: "y2", marker: { size: 4, color: "#5d6b7a" } },
    ];
    await T.plot(el, traces, {
      xaxis: T.axis(T._("Track position (km)"), { domain: [0, 0.52], tickformat: ".2f" }),
      yaxis: T.axis(T._("Index relative to the surroundings (ln units)")),
      xaxis2: T.axis(T._("Run date"), { domain: [0.62, 1], type: "date", anchor: "y2" }),
      yaxis2: T.axis(T._("Over the extent (ln units)"), { anchor: "x2" }),
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

  $("actions-body").addEventListener("click", (ev) => {
    const row = ev.target.closest("tr[data-action]");
    if (row) drawEffect(row.dataset.action).catch(C.fail(T._("Maintenance effect")));
  });

  C.drawActions = drawActions;
})();
