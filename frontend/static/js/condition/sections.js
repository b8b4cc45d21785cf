/* Condition page: the section classes along the line (A … E per section, from the rms of the
 * stiffness index over the section against the limits the answer states) and the length per class
 * now and a year before, each class with its meaning (the boot data's words). */
(function () {
  "use strict";
  const C = window.trackvkfCondition;
  const { T, $ } = C;
  const CLASS_COLORS = { A: "#2e7d32", B: "#8bc34a", C: "#e6c619", D: "#fb8c00", E: "#c62828", "": "#cfd8dc" };

  function className(c) { return c ? T._("class {c}", { c }) : T._("no class"); }

  /* "A ≤ 0.05 < B ≤ 0.10 < C ≤ …": the classes between the limits the answer gives. */
  function limitsText(classes, limits) {
    const parts = [classes[0]];
    limits.forEach((x, i) => { parts.push(`≤ ${T.fmt(x, 2)} <`, classes[i + 1]); });
    return T._("class from the rms of the index over a section: {limits}", { limits: parts.join(" ") });
  }

  async function drawSections() {
    const el = $("cond-sections");
    const { line_id, track } = C.current();
    const s = await T.api.get("/condition/sections", { line_id, track });
    $("sections-sub").textContent = T._("(per {m} m, run of {date})", { m: T.fmt(s.section_m, 0), date: T.date(s.run_time) });
    $("sections-info").textContent = limitsText(s.classes, s.limits);
    const traces = s.classes.concat([""]).map((c) => {
      const part = s.sections.filter((x) => x.class === c);
      return {
        type: "bar", orientation: "v", name: className(c), x: part.map((x) => (x.km_from + x.km_to) / 2),
        y: part.map(() => 1), width: part.map((x) => (x.km_to - x.km_from) * 0.98), marker: { color: CLASS_COLORS[c] },
        customdata: part.map((x) => [x.km_from, x.km_to, x.level, x.spread, x.rms, Math.round(100 * x.fill)]),
        hovertemplate: `${T.esc(className(c))}<br>km %{customdata[0]:.2f}–%{customdata[1]:.2f}<br>` +
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
      csv: () => ({ columns: ["km_from", "km_to", "class", "level", "spread", "rms", "fill"],
                    rows: s.sections.map((x) => [x.km_from, x.km_to, x.class, x.level, x.spread, x.rms, x.fill]) }),
    });
    const old = s.length_by_class_year_ago;
    $("class-lengths-body").innerHTML = s.classes.concat([""]).map((c) => {
      const now = (s.length_by_class[c] || 0) / 1000, before = old ? (old[c] || 0) / 1000 : null;
      if (!c && !now && !before) return "";
      return `<tr><td><span class="swatch" style="background:${CLASS_COLORS[c]}"></span> ${T.esc(c || T._("no class"))}</td>
        <td class="num">${T.fmt(now, 2)}</td><td class="num">${before === null ? "–" : T.fmt(before, 2)}</td>
        <td class="num">${before === null ? "–" : C.signed(now - before, 2)}</td><td class="muted">${T.esc(T.label("section class", c))}</td></tr>`;
    }).join("") + (old ? "" : `<tr><td colspan="5" class="muted">${T.esc(T._("No run of this line a year or more before the newest: no change over the year yet."))}</td></tr>`);
    return s;
  }

  C.drawSections = drawSections;
})();
