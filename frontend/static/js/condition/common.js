/* Condition page, shared part: the page's state, its rules (from the boot data the server renders
 * the page with: tiers, statuses, segment lengths, limits), the line chosen and the texts of a
 * place that several panels show. Each panel is a file of its own (sections, places, place,
 * heatmap, trend, effects, webhooks); main.js puts them together. Every number comes from
 * /api/v1/condition/… and /api/v1/assets. */
(function () {
  "use strict";
  const T = window.trackvkf;
  const boot = T.boot;
  const $ = (id) => document.getElementById(id);

  /* The rules of the page, as the server states them (nothing restated here). */
  const RULES = {
    tiers: boot.tiers.slice().reverse(),        // lowest first (the boot lists the highest first, as the filter)
    statuses: boot.statuses,
    openStatuses: boot.open_statuses,
    fineSegmentM: boot.fine_segment_m,           // a place's segments
    overviewSegmentM: boot.overview_segment_m,   // the heat map's segments
    tierLimits: boot.tier_limits || {},          // {class: {alert, intervention, immediate}}, "" = every other class
  };

  const state = {
    lines: [], me: null, placeId: null, placeList: null, heat: null, trend: null, effect: null, formPlace: null,
    // answers can arrive out of order (a filter clicked twice, a place opened while another loads):
    // only the newest request of each view is drawn
    placesSeq: 0, placeSeq: 0,
    // the line shown (a view, begin()) and the generation of the newest draw of a line
    view: null, generation: 0,
  };

  /* The line chosen in the picker (not necessarily the one shown: see view()). */
  function current() {
    const [line_id, track] = ($("cond-line").value || "\u0001").split("\u0001");
    return { line_id, track };
  }
  /* A new draw of the chosen line: from now on every draw started for an earlier one is stale and
   * never writes the page (a line chosen while another still draws gets its own km and places).
   * A view is {line_id, track, key, live()}; every panel reads its line from the view it was started
   * for and checks live() after each await, before it writes. */
  function begin() {
    const { line_id, track } = current();
    const generation = ++state.generation;
    state.view = { line_id, track, key: `${line_id}\u0001${track}`, live: () => generation === state.generation };
    return state.view;
  }
  /* The view of the line shown: what a panel's own controls (a filter, a wheel, a click) draw for. */
  function view() {
    return state.view || { line_id: "", track: "", key: "", live: () => false };
  }
  function qs(params) {
    const u = new URLSearchParams();
    for (const [k, v] of Object.entries(params)) {
      if (Array.isArray(v)) v.forEach((x) => u.append(k, x));
      else if (v !== undefined && v !== null && v !== "") u.set(k, v);
    }
    return u.toString();
  }
  /* A signed number in the page's locale ("+3.2", "−1.0"). */
  function signed(v, digits) {
    if (v === null || v === undefined || !Number.isFinite(Number(v))) return "–";
    return `${v > 0 ? "+" : ""}${T.fmt(v, digits ?? 1)}`;
  }
  function tierBadge(t) { return `<span class="tier tier-${T.esc(t)}">${T.esc(T.label("tier", t))}</span>`; }
  function statusBadge(s) { return `<span class="status status-${T.esc(s)}" data-status="${T.esc(s)}">${T.esc(T.label("place status", s))}</span>`; }
  function canEdit() { return !!state.me && (state.me.role === "engineer" || state.me.role === "admin"); }
  function mapLink(runId, a, b) { return `/runs/${runId}?km_from=${(a - 0.05).toFixed(3)}&km_to=${(b + 0.05).toFixed(3)}`; }

  // a rate of the amplitude, per cent a year, from its ln rate (expm1: −1 ln unit a year is −63 %, never "−100 %")
  function ampRate(ln) { return 100 * Math.expm1(ln); }
  function trendText(p) {
    if (p.rate_per_year === null) return `<span class="muted">${T.esc(p.tendency ? T.label("tendency", p.tendency) : "–")}</span>`;
    // the rate is of the severity (direction · index, ln units a year); shown as the amplitude's change a year
    const d = p.direction === "soft" ? -1 : 1;
    const r = (v) => { const a = ampRate(d * v); return a > 999 ? "> +999 %" : `${signed(a, 0)} %`; };
    const arrow = { growing: "↗", shrinking: "↘", stable: "→" }[p.tendency] || "";
    const [lo, hi] = d > 0 ? [p.rate_low, p.rate_high] : [p.rate_high, p.rate_low];
    const iv = lo !== null && hi !== null ? ` <span class="muted">(${r(lo)} … ${r(hi)})</span>` : "";
    const title = T._("severity {rate} ln units a year", { rate: signed(p.rate_per_year, 2) });
    const text = T._("{tendency}: amplitude {rate} a year", { tendency: T.label("tendency", p.tendency), rate: r(p.rate_per_year) });
    return `<span title="${T.esc(title)}">${arrow} ${T.esc(text)}</span>${iv}`;
  }
  /* The time to limit: the projected days until the next tier's limit with the days at the ends of the
   * rate's 95 % interval; where there is none, why (API: no_projection). */
  const NO_PROJECTION = {
    top_tier: () => T._("top tier"),
    no_limit: () => T._("no limit above for its class"),
    too_few_runs: () => T._("too few runs for a trend (3 needed)"),
    stable: () => T._("stable: no time to limit"),
    shrinking: () => T._("shrinking: no time to limit"),
  };
  function limitText(p) {
    if (!p.next_tier) return `<span class="muted">${T.esc(T._("top tier"))}</span>`;
    const next = T.label("tier", p.next_tier);
    if (p.days_to_next_tier === null) {
      const why = NO_PROJECTION[p.no_projection];
      return `<span class="muted">${T.esc(why ? why() : T._("no significant trend towards {tier}", { tier: next }))}</span>`;
    }
    const early = p.days_to_next_tier_early, late = p.days_to_next_tier_late;
    const iv = early === null || early === undefined ? "" : late === null || late === undefined
      ? T._("95 %: {early} d or later", { early: T.fmt(early, 0) })
      : T._("95 %: {early}–{late} d", { early: T.fmt(early, 0), late: T.fmt(late, 0) });
    return `${T.esc(T._("≈ {days} d to {tier}", { days: T.fmt(p.days_to_next_tier, 0), tier: next }))} ` +
      `<span class="muted">(${T.date(p.projected_date)}${iv ? `; ${T.esc(iv)}` : ""})</span>`;
  }
  const READING = { stiffer: T._("stiffer"), softer: T._("softer"), "higher amplitude": T._("higher amplitude"),
                    "lower amplitude": T._("lower amplitude") };
  function peakText(p) {
    // the stated 1-sigma of the peak in per cent (delta method: 100 · sd · e^peak); none where not stated
    const sdTitle = T._("stated 1-σ of the peak (roughness, noise)");
    const sd = p.peak_sd === null || p.peak_sd === undefined ? "" :
      ` <span class="muted" title="${T.esc(sdTitle)}">± ${T.fmt(100 * p.peak_sd * Math.exp(p.peak), 0)} %</span>`;
    // stiffer / softer only where the place was read fast enough for the amplitude to rank stiffness (API: reading)
    const words = READING[p.reading] || (p.direction === "soft" ? READING["lower amplitude"] : READING["higher amplitude"]);
    const dir = `${p.direction === "soft" ? "▼" : "▲"} ${T.esc(words)}`;
    let where = T._("index {index} at km {km}", { index: T.fmt(p.peak, 3), km: T.fmt(p.peak_km, 3) });
    if (p.speed_kmh !== null && p.speed_kmh !== undefined) where += T._(", read at {v} km/h", { v: T.fmt(p.speed_kmh, 0) });
    return `<span title="${T.esc(where)}">${signed(p.peak_percent, 0)} %${sd} ${dir}</span>`;
  }
  /* a new place: found by the newest run, on the list at once, confirmed (and alerted) by the next run */
  function confirmText(p) {
    if (p.confirmed !== false) return "";
    const title = T._("found by one run"), text = T._("new, to be confirmed by the next run");
    return `<br><span class="badge unconfirmed" title="${T.esc(title)}">${T.esc(text)}</span>`;
  }
  function assetsText(p) {
    const list = (p.assets || []).map((a) => `${T.esc(T.label("asset type", a.type))}${a.name ? ` <span class="muted" translate="no">${T.esc(a.name)}</span>` : ""}`).join(", ");
    const muted = p.muted ? ` <span class="badge muted-badge" title="${T.esc(p.muted_reason || "")}">${T.esc(T._("muted"))}</span>` : "";
    return (list || `<span class="muted">–</span>`) + muted;
  }
  /* A fixed place's status date: the day of the repair that fixed it (not the day the service noticed). */
  function statusDate(p) {
    if (p.status === "fixed") {
      const repair = (p.actions || []).filter((a) => a.relation === "repaired").sort((a, b) => String(b.date).localeCompare(String(a.date)))[0];
      if (repair) return { date: repair.date, text: T._("repaired by {type} on {date}", { type: T.label("maintenance type", repair.kind), date: T.date(repair.date) }) };
    }
    return p.status_at ? { date: p.status_at, text: T._("by {who} on {date}", { who: p.status_by || "–", date: T.date(p.status_at) }) } : null;
  }

  const fail = (what) => (e) => T.banner(`${what}: ${e.detail || e.message}`);

  window.trackvkfCondition = {
    T, $, RULES, state, current, begin, view, qs, signed, tierBadge, statusBadge, canEdit, mapLink,
    ampRate, trendText, limitText, peakText, confirmText, assetsText, statusDate, fail,
  };
})();
