/* Condition page: the rail findings of the line — the track impacts its runs found (dipped welds,
 * joints), followed over the runs (/condition/rail-findings): km, type, the newest run's dip depth,
 * runs seen of the runs that passed, the depth's trend, and the asset register's asset where one
 * lies on a finding. Rail features, not support defects: the store keeps them out of every value a
 * place is graded on, and this list is never ranked with the places. */
(function () {
  "use strict";
  const C = window.trackvkfCondition;
  const { T, $, state } = C;
  const COLS = 7;

  /* The depth's trend (mm a year, ± its standard error), with what it says where it is significant, and since
   * when: the latest work on the rails' surface over the finding (grinding, rail renewal) starts it anew. */
  function trendText(f) {
    const rate = f.depth_trend_mm_per_year;
    const since = f.depth_trend_since
      ? ` <span class="muted">${T.esc(T._("since the rail work of {date}", { date: T.date(f.depth_trend_since) }))}</span>` : "";
    if (rate === null || rate === undefined) {
      const why = T._("a trend needs the finding in three runs or more");
      return `<span class="muted" title="${T.esc(why)}">–</span>${since}`;
    }
    const se = f.depth_trend_se_mm_per_year;
    const value = se === null || se === undefined
      ? T._("{rate} mm a year", { rate: C.signed(rate, 3) })
      : T._("{rate} ± {se} mm a year", { rate: C.signed(rate, 3), se: T.fmt(se, 3) });
    const words = !f.depth_trend_significant ? T._("not significant")
      : rate > 0 ? T._("deepening") : T._("getting shallower");
    return `${T.esc(value)} <span class="${f.depth_trend_significant ? "" : "muted"}">(${T.esc(words)})</span>${since}`;
  }

  function depthText(f) {
    const depth = f.depth_mm === null || f.depth_mm === undefined ? "–" : `${T.fmt(f.depth_mm, 2)} mm`;
    const length = f.length_m === null || f.length_m === undefined ? ""
      : ` <span class="muted">${T.esc(T._("over {length} m", { length: T.fmt(f.length_m, 1) }))}</span>`;
    return depth + length;
  }

  function assetText(f) {
    if (!f.asset) return `<span class="muted">–</span>`;
    const a = f.asset;
    return `${T.esc(T.label("asset type", a.type))}${a.name ? ` <span class="muted" translate="no">${T.esc(a.name)}</span>` : ""}` +
      ` <span class="muted">km ${T.fmt(a.km, 3)}</span>`;
  }

  async function drawRails(view = C.view()) {
    const body = $("rails-body");
    if (!view.live()) return null;  // a draw for a line no longer chosen writes nothing
    const { line_id, track } = view;
    // the steady findings (seen by at least half the runs that passed them), or every one on request
    const q = C.qs({ line_id, track, steady: $("rails-all").checked ? undefined : "true" });
    $("rails-csv").href = `${T.boot.api}/condition/rail-findings.csv?${q}&header=labels`;
    const res = await T.api.get(`/condition/rail-findings?${q}`);
    if (!view.live()) return null;  // another line was chosen meanwhile
    state.rails = { key: view.key, items: res.items };
    body.dataset.line = view.key;
    const hidden = res.steady_only ? res.unsteady : 0;
    $("rails-info").textContent = T.ngettext("{n} rail finding", "{n} rail findings", res.items.length) + ", " +
      T.ngettext("{n} run", "{n} runs", res.runs) +
      (hidden ? ", " + T.ngettext("{n} seen by fewer than half the runs not shown", "{n} seen by fewer than half the runs not shown", hidden) : "");
    if (!res.items.length) {
      const none = hidden ? T._("No rail finding seen by half the runs or more.")
        : T._("No rail finding on this line: no run found a track impact (weld, joint).");
      body.innerHTML = `<tr><td colspan="${COLS}" class="muted">${T.esc(none)}</td></tr>`;
      return res;
    }
    const seenTitle = T.esc(T._("runs that found it / runs that passed it"));
    body.innerHTML = res.items.map((f) => `<tr data-finding="${T.esc(f.id)}" data-type="${T.esc(f.type)}">
      <td class="num">${T.fmt(f.km, 3)}</td><td>${T.esc(T.label("rail finding", f.type))}</td>
      <td class="num nowrap">${depthText(f)}</td>
      <td class="num" title="${seenTitle}">${f.runs_seen} / ${f.runs_passed}</td>
      <td class="wrap">${trendText(f)}</td>
      <td>${f.first_seen === f.last_seen ? T.date(f.first_seen) : `${T.date(f.first_seen)} – ${T.date(f.last_seen)}`}</td>
      <td class="wrap">${assetText(f)}</td></tr>`).join("");
    return res;
  }

  C.drawRails = drawRails;
  // the list and the heat map's marks of the findings shown
  $("rails-all").addEventListener("change", async () => {
    try {
      const view = C.view();
      if (await drawRails(view)) await C.drawHeatmap(view);
    } catch (e) { C.fail(T._("Rail findings"))(e); }
  });
})();
