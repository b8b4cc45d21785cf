/* Condition page: an exception report of a line — the section classes, the places (the work
 * list) and a place's history, the rail findings (welds, joints: never ranked with the places),
 * the runs × segments heat map and a segment's trend, the maintenance actions and their effect,
 * the webhooks (admins). This file chooses the line and draws the panels (each in a file of its
 * own under condition/) in the order of the page. */
(function () {
  "use strict";
  const C = window.trackvkfCondition;
  const { T, $, state } = C;

  /* Draws every panel for the line chosen. A line chosen (and shown) while this one still draws
   * makes this draw stale (C.begin): it stops at its next await and writes nothing more, so every
   * panel shows the line it was started for. When all panels are drawn, #cond-controls carries
   * data-drawn = the line's key. */
  async function show() {
    T.banner(null);
    const before = state.view;
    const view = C.begin();
    delete $("cond-controls").dataset.drawn;
    if (before && before.key !== view.key) {
      // the segment and the place belong to the line shown before
      $("cond-trend-km").value = "";
      state.placeId = null;
    }
    const line = state.lines.find((l) => `${l.line_id}\u0001${l.track}` === view.key);
    $("cond-info").textContent = line ? T.ngettext("{n} run", "{n} runs", line.n_runs) +
      `, ${T.date(line.first_run)} – ${T.date(line.last_run)}, km ${T.fmt(line.km_min, 2)}–${T.fmt(line.km_max, 2)}` : "";
    if (!view.line_id || !line) return;
    try {
      await drawPanels(view, line);
    } catch (e) {
      if (view.live()) throw e;  // a stale draw's failure is no news about the line shown
    }
  }

  async function drawPanels(view, line) {
    await C.drawSections(view);
    if (!view.live()) return;
    const res = await C.drawPlaces(view);
    if (!view.live() || !res) return;
    const top = res.items[0];
    if (top && !(res.items.some((p) => p.id === state.placeId))) state.placeId = top.id;
    if (state.placeId) await C.drawPlace(state.placeId, view);
    else C.clearPlace(T._("No place on this line."), `<p>${T._("Places appear once two runs find the same exceedance (at once at the intervention tier).")}</p>`);
    if (!view.live()) return;
    await C.drawRails(view);
    if (!view.live()) return;
    await C.drawHeatmap(view);
    if (!view.live()) return;
    if (!$("cond-trend-km").value) {
      $("cond-trend-km").value = top ? top.peak_km.toFixed(3) : ((line.km_min + line.km_max) / 2).toFixed(3);
      $("cond-trend-seg").value = String(top ? C.RULES.fineSegmentM : C.RULES.overviewSegmentM);
    }
    await C.drawTrend(view);
    if (!view.live()) return;
    await C.drawActions(view);
    if (view.live()) $("cond-controls").dataset.drawn = view.key;
  }

  $("cond-controls").addEventListener("submit", (ev) => { ev.preventDefault(); show().catch(C.fail(T._("Could not load the condition"))); });

  (async () => {
    try {
      $("cond-wheel").innerHTML += T.WHEELS.map((w) => `<option value="${w}">${T.wheelLabel(w)}</option>`).join("");
      state.me = await T.api.get("/auth/me").catch(() => null);
      state.lines = (await T.api.get("/condition/lines")).items;
      if (!state.lines.length) {
        for (const id of ["cond-sections", "place-history", "cond-heatmap", "cond-trend", "cond-effect"]) {
          T.emptyState(id, T._("No runs in the condition store yet."),
            `<p>${T._("Processed runs with a line id appear here: {command} processes a short history of a line.", { command: "<code>./scripts/demo.sh</code>" })}</p>`);
        }
        $("places-body").innerHTML = `<tr><td colspan="12" class="muted">${T.esc(T._("No places yet."))}</td></tr>`;
      } else {
        const best = state.lines.reduce((a, b) => (b.n_runs > a.n_runs ? b : a));
        $("cond-line").innerHTML = state.lines.map((l) => `<option value="${T.esc(l.line_id)}\u0001${T.esc(l.track)}">` +
          `${T.esc(T._("line {line} / track {track}", { line: l.line_id, track: l.track }))} (${T.esc(T.ngettext("{n} run", "{n} runs", l.n_runs))})</option>`).join("");
        const asked = T.param("line_id") !== null ? `${T.param("line_id")}\u0001${T.param("track") || ""}` : null;
        $("cond-line").value = asked && state.lines.some((l) => `${l.line_id}\u0001${l.track}` === asked) ? asked : `${best.line_id}\u0001${best.track}`;
        const want = T.param("place");
        if (want) state.placeId = Number(want);
        await show();
      }
      await C.drawWebhooks();
    } catch (e) {
      T.banner(T._("Could not load the condition page: {detail}", { detail: e.detail || e.message }));
    }
    T.ready();
  })();
})();
