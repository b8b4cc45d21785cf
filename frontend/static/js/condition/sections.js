/* Condition page: the section classes along the line (A … E per section, from the rms of the
 * stiffness index over the section against the limits the answer states), shown in the railway's
 * class scheme (TRACKVKF_PLACES_CLASS_SCHEME; default A … E; its names in the page's language from
 * the answer), and the length per class now and a year before, each class with its meaning (the
 * boot data's words); the planning report's link. */
(function () {
  "use strict";
  const C = window.trackvkfCondition;
  const { T, $ } = C;
  const NO_CLASS_COLOUR = "#cfd8dc";

  /* "A ≤ 0.05 < B ≤ 0.10 < C ≤ …": the classes between the limits the answer gives. */
  function limitsText(classes, limits) {
    const parts = [classes[0]];
    limits.forEach((x, i) => { parts.push(`≤ ${T.fmt(x, 2)} <`, classes[i + 1]); });
    return T._("class from the rms of the index over a section: {limits}", { limits: parts.join(" ") });
  }

  async function drawSections(view = C.view()) {
    const el = $("cond-sections");
    if (!view.live()) return null;  // a draw for a line no longer chosen writes nothing
    const { line_id, track } = view;
    $("report-pdf").href = `${T.boot.api}/condition/report.pdf?${new URLSearchParams({ line_id, track })}`;
    const s = await T.api.get("/condition/sections", { line_id, track });
    if (!view.live()) return null;  // another line was chosen meanwhile
    $("sections-sub").textContent = T._("(per {m} m, run of {date})", { m: T.fmt(s.section_m, 0), date: T.date(s.run_time) });
    $("sections-info").textContent = limitsText(s.classes, s.limits);
    /* the railway's class scheme: one trace per class of it (and one of the sections without a class) */
    const groups = s.scheme.classes.concat([{ code: "", name: T._("no class"), colour: NO_CLASS_COLOUR, of: [""] }]);
    const traces = groups.map((g) => {
      const part = s.sections.filter((x) => x.scheme_class === g.code);
      return {
        type: "bar", orientation: "v", name: g.name, x: part.map((x) => (x.km_from + x.km_to) / 2),
        y: part.map(() => 1), width: part.map((x) => (x.km_to - x.km_from) * 0.98), marker: { color: g.colour },
        customdata: part.map((x) => [x.km_from, x.km_to, x.level, x.spread, x.rms, Math.round(100 * x.fill), x.class || "–"]),
        hovertemplate: `${T.esc(g.name)} (${T.esc(T._("class {c}", { c: "%{customdata[6]}" }))})<br>km %{customdata[0]:.2f}–%{customdata[1]:.2f}<br>` +
          `${T.esc(T._("rms"))} %{customdata[4]:.3f}, ${T.esc(T._("level"))} %{customdata[2]:.3f}, ${T.esc(T._("spread"))} %{customdata[3]:.3f}<br>` +
          `${T.esc(T._("data"))} %{customdata[5]} %<extra></extra>`,
      };
    }).filter((t) => t.x.length);
    if (!s.sections.length) { T.emptyState(el, T._("No section with data."), ""); return s; }
    await T.plot(el, traces, {
      barmode: "overlay", bargap: 0, showlegend: true,
      xaxis: T.axis(T._("Track position (km)"), { tickformat: ".1f", range: [s.sections[0].km_from, s.sections[s.sections.length - 1].km_to] }),
      yaxis: { visible: false, range: [0, 1], fixedrange: true },
      margin: { l: 20, r: 20, t: 30, b: 50 },
    }, {
      filename: `section-classes-${line_id}`,
      csv: () => ({ columns: ["km_from", "km_to", "class", "scheme_class", "level", "spread", "rms", "fill"],
                    rows: s.sections.map((x) => [x.km_from, x.km_to, x.class, x.scheme_class, x.level, x.spread, x.rms, x.fill]) }),
    });
    if (!view.live()) return null;
    const old = s.length_by_scheme_class_year_ago;
    $("class-lengths-scheme").textContent = s.scheme.name;
    $("class-lengths-body").innerHTML = groups.map((g) => {
      const now = (s.length_by_scheme_class[g.code] || 0) / 1000, before = old ? (old[g.code] || 0) / 1000 : null;
      if (!g.code && !now && !before) return "";
      const meaning = g.of.map((c) => (c ? `${c}: ` : "") + T.label("section class", c)).join("; ");
      return `<tr><td><span class="swatch" style="background:${g.colour}"></span> ${T.esc(g.name)}</td>
        <td class="num">${T.fmt(now, 2)}</td><td class="num">${before === null ? "–" : T.fmt(before, 2)}</td>
        <td class="num">${before === null ? "–" : C.signed(now - before, 2)}</td><td class="muted">${T.esc(meaning)}</td></tr>`;
    }).join("") + (old ? "" : `<tr><td colspan="5" class="muted">${T.esc(T._("No run of this line a year or more before the newest: no change over the year yet."))}</td></tr>`);
    return s;
  }

  C.drawSections = drawSections;
})();
