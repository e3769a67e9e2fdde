/* The dashboard of `dualfem report html`: every plot and table is drawn here from the JSON embedded in
   #dash-data (dualfem/reports/_dash_data.py documents it), filtered by the selection of the side panel.
   When everything is drawn, <html> gets data-dash-rendered="ok" (a headless browser test waits for it). */
"use strict";
(function () {
  const D = JSON.parse(document.getElementById("dash-data").textContent);
  const R = D.runs;
  const NRUNS = (R.solver || []).length;
  const { g, medianBand, FLOOR_ERR, QLO, QHI } = window.DashLib;
  const byId = (id) => document.getElementById(id);
  const el = (tag, attrs, text) => {
    const e = document.createElement(tag);
    for (const [k, v] of Object.entries(attrs || {})) e.setAttribute(k, v);
    if (text !== undefined) e.textContent = text;
    return e;
  };
  const g3 = (v) => g(v, 3);
  const gg = (v) => g(v, 6);
  const f2 = (v) => (v === null || v === undefined || !isFinite(v)) ? "n/a" : v.toFixed(2);
  const pct = (v) => (v === null || v === undefined || !isFinite(v)) ? "-" : Math.round(100 * v) + " %";
  const solverIndex = new Map(D.solvers.map((s, i) => [s.name, i]));

  /* ---------- controls ---------- */
  function options(sel, values, labels) {
    sel.appendChild(el("option", { value: "-1" }, "all"));
    values.forEach((v, i) => sel.appendChild(el("option", { value: String(i) }, labels ? labels[i] : String(v))));
  }
  options(byId("f-scene"), D.scenes);
  options(byId("f-delta"), D.deltas, D.deltas.map(gg));
  options(byId("f-tier"), D.tiers.map((t) => t.name),
          D.tiers.map((t) => t.tol === null ? t.name : `${t.name} (tol ${gg(t.tol)})`));

  function markerSvg(s, filled) {
    const ns = "http://www.w3.org/2000/svg";
    const svg = document.createElementNS(ns, "svg");
    svg.setAttribute("width", "14"); svg.setAttribute("height", "14"); svg.setAttribute("viewBox", "0 0 14 14");
    const pts = {
      "square": "2,2 12,2 12,12 2,12", "diamond": "7,1 13,7 7,13 1,7", "triangle-up": "7,1 13,12 1,12",
      "triangle-down": "1,2 13,2 7,13", "hexagon": "7,1 12.2,4 12.2,10 7,13 1.8,10 1.8,4",
      "pentagon": "7,1 13,5.5 10.7,12.5 3.3,12.5 1,5.5",
      "star": "7,1 8.6,5.2 13,5.3 9.6,8.1 10.8,12.5 7,10 3.2,12.5 4.4,8.1 1,5.3 5.4,5.2",
      "cross": "5,1 9,1 9,5 13,5 13,9 9,9 9,13 5,13 5,9 1,9 1,5 5,5",
      "x": "2.5,1 7,5.5 11.5,1 13,2.5 8.5,7 13,11.5 11.5,13 7,8.5 2.5,13 1,11.5 5.5,7 1,2.5",
    }[s.symbol];
    const shape = document.createElementNS(ns, pts ? "polygon" : "circle");
    if (pts) shape.setAttribute("points", pts);
    else { shape.setAttribute("cx", "7"); shape.setAttribute("cy", "7"); shape.setAttribute("r", "5"); }
    shape.setAttribute("fill", filled ? s.color : "none");
    shape.setAttribute("stroke", s.edge || s.color);
    shape.setAttribute("stroke-width", "1.5");
    svg.appendChild(shape);
    return svg;
  }

  const checks = [];          // solver index -> its checkbox
  const famChecks = {};
  const list = byId("solver-list");
  for (const fam of D.families) {
    const fs = el("fieldset", { class: "family" });
    const lg = el("legend");
    const fc = el("input", { type: "checkbox", "data-family": fam });
    fc.checked = true;
    const members = D.solvers.map((s, i) => [s, i]).filter(([s]) => s.family === fam);
    lg.appendChild(fc);
    lg.appendChild(document.createTextNode(` ${fam} (${members.length})`));
    fs.appendChild(lg);
    famChecks[fam] = fc;
    for (const [s, i] of members) {
      const lab = el("label", { class: "solver" + (s.ran ? "" : " notrun"),
                                title: s.ran ? `${s.name} (${s.family})` : `${s.name}: not run (${s.skipped})` });
      const cb = el("input", { type: "checkbox", "data-solver": s.name });
      cb.checked = s.ran;
      checks[i] = cb;
      lab.appendChild(cb);
      lab.appendChild(markerSvg(s, true));
      lab.appendChild(document.createTextNode(s.name + (s.ran ? "" : " (not run)")));
      fs.appendChild(lab);
      cb.addEventListener("change", () => { syncFamilies(); update(); });
      lab.addEventListener("dblclick", (ev) => {
        ev.preventDefault();
        checks.forEach((c, j) => { c.checked = j === i; });
        syncFamilies(); update();
      });
    }
    fc.addEventListener("change", () => {
      for (const [, i] of members) checks[i].checked = fc.checked;
      syncFamilies(); update();
    });
    list.appendChild(fs);
  }
  function syncFamilies() {
    for (const fam of D.families) {
      const idx = D.solvers.map((s, i) => i).filter((i) => D.solvers[i].family === fam);
      const on = idx.filter((i) => checks[i].checked).length;
      famChecks[fam].checked = on === idx.length;
      famChecks[fam].indeterminate = on > 0 && on < idx.length;
    }
    byId("solver-count").textContent = `(${checks.filter((c) => c.checked).length} of ${checks.length})`;
  }
  document.querySelectorAll("button[data-pick]").forEach((b) => b.addEventListener("click", () => {
    D.solvers.forEach((s, i) => { checks[i].checked = b.dataset.pick === "all" || (b.dataset.pick === "ran" && s.ran); });
    syncFamilies(); update();
  }));
  for (const id of ["f-scene", "f-delta", "f-tier", "f-error", "f-panels"]) byId(id).addEventListener("change", update);

  function selection() {
    const v = (id) => Number(byId(id).value);
    return { scene: v("f-scene"), delta: v("f-delta"), tier: v("f-tier"),
             error: byId("f-error").value, panels: byId("f-panels").value,
             solvers: new Set(checks.map((c, i) => c.checked ? i : -1).filter((i) => i >= 0)) };
  }
  function selectedRuns(sel) {
    const out = [];
    for (let k = 0; k < NRUNS; k++) {
      if (!sel.solvers.has(R.solver[k])) continue;
      if (sel.scene >= 0 && R.scene[k] !== sel.scene) continue;
      if (sel.delta >= 0 && R.delta[k] !== D.deltas[sel.delta]) continue;
      if (sel.tier >= 0 && R.tier[k] !== sel.tier) continue;
      out.push(k);
    }
    return out;
  }

  /* ---------- work-precision ---------- */
  function rgba(hex, a) {
    const n = parseInt(hex.slice(1), 16);
    return `rgba(${(n >> 16) & 255},${(n >> 8) & 255},${n & 255},${a})`;
  }
  const esc = (t) => String(t).replace(/[<>&"]/g, (c) => ({ "<": "&lt;", ">": "&gt;", "&": "&amp;", '"': "&quot;" })[c]);
  function hover(k) {         // plotly hover text is HTML: every text of the results is escaped
    const s = D.solvers[R.solver[k]], tier = D.tiers[R.tier[k]];
    return `<b>${esc(s.name)}</b> (${esc(s.family)})<br>${esc(R.label[k] || D.scenes[R.scene[k]])}, ` +
      `tier ${esc(tier.name)}<br>status ${esc(D.statuses[R.status[k]])} (claimed ${esc(R.claimed[k])}), grade ` +
      `${esc(R.grade[k] || "-")}<br>time ${g3(R.time[k])} s, error ${g3(R.err[k])}, KKT ${g3(R.kkt[k])}` +
      (R.message[k] ? `<br>${esc(R.message[k].slice(0, 100))}` : "");
  }
  function wpTraces(sel, runs, panelOf) {
    // one series per (solver, panel); in the energy-norm view the reference solver's own runs (error 0 by
    // construction) are no competitor: they are drawn as a line (wpLayout), not as points
    const traces = [];
    const bySolver = new Map();
    let nSelfRef = 0;
    for (const k of runs) {
      const y = sel.error === "err" ? R.err[k] : R.kkt[k];
      if (R.time[k] === null || y === null || !(R.time[k] > 0)) continue;
      if (sel.error === "err" && R.selfref[k]) { nSelfRef += 1; continue; }
      const key = `${R.solver[k]}|${panelOf(k)}`;
      if (!bySolver.has(key)) bySolver.set(key, []);
      bySolver.get(key).push(k);
    }
    const nMarkers = [...bySolver.values()].reduce((a, ks) => a + ks.length, 0);
    const faceted = sel.panels === "scene-delta";
    const oneScene = (faceted || (sel.scene >= 0 && sel.delta >= 0)) && sel.tier < 0;
    const kind = sel.error === "err" ? "reference" : "kkt";
    let nCurves = 0, nPoints = 0;
    const solversDrawn = new Set(), medians = new Set();
    for (const [key, ks] of bySolver) {
      const si = R.solver[ks[0]], s = D.solvers[si], ax = panelOf(ks[0]);
      solversDrawn.add(si);
      const xa = ax === 1 ? "x" : "x" + ax, ya = ax === 1 ? "y" : "y" + ax;
      // the median of the curves of the solver's tightest tier that has any (as the static figures): tiers
      // stop at different errors, and a median across them would saw-tooth
      const withCurve = ks.filter((k) => D.curves[R.id[k]] && D.curves[R.id[k]].kind === kind);
      const tolOf = (k) => { const t = D.tiers[R.tier[k]].tol; return t === null ? Infinity : t; };
      const tight = Math.min(...withCurve.map(tolOf));
      const curves = withCurve.filter((k) => tolOf(k) === tight).map((k) => D.curves[R.id[k]]);
      if (curves.length) {
        const b = medianBand(curves);
        if (b) {
          nCurves += curves.length;
          medians.add(si);
          const common = { x: b.t, xaxis: xa, yaxis: ya, hoverinfo: "skip", showlegend: false, legendgroup: s.name };
          traces.push(Object.assign({ y: b.lo, mode: "lines", line: { width: 0, color: s.color } }, common));
          traces.push(Object.assign({ y: b.hi, mode: "lines", line: { width: 0, color: s.color }, fill: "tonexty",
                                      fillcolor: rgba(s.color, 0.18) }, common));
          traces.push({ x: b.t, y: b.med, xaxis: xa, yaxis: ya, mode: "lines", name: s.name, showlegend: false,
                        line: { color: s.color, width: 2, dash: s.dash },
                        hovertemplate: `<b>${esc(s.name)}</b>: median of ${curves.length} curve(s)<br>t %{x:.3g} s, error %{y:.3g}<extra></extra>` });
        }
      }
      if (oneScene) ks.sort((a, b) => (D.tiers[R.tier[b]].tol || 0) - (D.tiers[R.tier[a]].tol || 0));
      nPoints += ks.length;
      traces.push({
        x: ks.map((k) => R.time[k]), y: ks.map((k) => Math.max(sel.error === "err" ? R.err[k] : R.kkt[k], FLOOR_ERR)),
        xaxis: xa, yaxis: ya, name: s.name, showlegend: false, type: "scatter",
        mode: oneScene && !curves.length ? "lines+markers" : "markers",
        line: { color: s.color, dash: s.dash, width: 1.5 },
        marker: { color: s.color, size: nMarkers > 400 ? 7 : 9, opacity: nMarkers > 400 ? 0.85 : 1,
                  line: { color: s.edge || s.color, width: 1.5 },
                  symbol: ks.map((k) => D.statuses[R.status[k]] === "solved" ? s.symbol : s.symbol + "-open") },
        text: ks.map(hover), hovertemplate: "%{text}<extra></extra>",
      });
    }
    return { traces, nCurves, nPoints, nMedians: medians.size, nSolvers: solversDrawn.size, nSelfRef };
  }
  function wpLayout(sel, panels, runs, ncols) {
    const ytitle = sel.error === "err" ? "relative energy-norm error vs certified reference" : "KKT error (evaluator)";
    const n = panels.length, cols = n > 1 ? (ncols || 2) : 1, rows = Math.ceil(n / cols);
    const layout = { height: n > 1 ? 330 * rows + 60 : 560, margin: { l: 70, r: 20, t: 40, b: 60 },
                     hovermode: "closest", showlegend: false, annotations: [], shapes: [],
                     plot_bgcolor: "#fff", paper_bgcolor: "#fff" };
    if (n > 1) layout.grid = { rows, columns: cols, pattern: "independent", xgap: 0.08, ygap: 0.14 };
    panels.forEach((panel, i) => {
      const fam = panel.title;
      const ax = i + 1, sx = ax === 1 ? "" : String(ax);
      const bottom = Math.floor(i / cols) === rows - 1 || i + cols >= n;
      layout["xaxis" + sx] = { type: "log", title: { text: bottom ? "time = setup + solve [s]" : "" }, gridcolor: "#e5e5e5",
                              exponentformat: "power", matches: ax === 1 ? undefined : "x" };
      layout["yaxis" + sx] = { type: "log", title: { text: n > 1 && i % cols ? "" : ytitle }, gridcolor: "#e5e5e5",
                              exponentformat: "power", matches: ax === 1 ? undefined : "y" };
      if (n > 1) layout.annotations.push({ text: `<b>${esc(fam)}</b>`, xref: `x${sx} domain`, yref: `y${sx} domain`,
                                           x: 0.5, y: 1.02, xanchor: "center", yanchor: "bottom", showarrow: false });
      const mine = runs.filter((k) => panel.has(k));
      const scenes = new Set(mine.map((k) => R.scene[k]));
      const vline = (x, text, dash, y) => {
        layout.shapes.push({ type: "line", xref: "x" + sx, yref: `y${sx} domain`, x0: x, x1: x, y0: 0, y1: 1,
                             line: { color: "#666", width: 1, dash } });
        layout.annotations.push({ text, xref: "x" + sx, yref: `y${sx} domain`, x: Math.log10(x), y,
                                  textangle: -90, xanchor: "right", yanchor: "bottom", showarrow: false,
                                  font: { size: 10, color: "#666" } });
      };
      for (const f of D.floors) {       // the floor of each scene of the panel: one factorization + one solve of K
        if (!scenes.has(f.scene) || f.time === null) continue;
        vline(f.time, scenes.size > 1 ? `floor ${esc(D.scenes[f.scene])}` : "floor", "dash", 0.02);
      }
      if (sel.error === "err") {        // the reference solver's own runs: a line at their median time
        const own = mine.filter((k) => R.selfref[k] && R.time[k] > 0).map((k) => R.time[k]).sort((a, b) => a - b);
        if (own.length) {
          const names = [...new Set(mine.filter((k) => R.selfref[k]).map((k) => D.solvers[R.solver[k]].name))];
          vline(own[Math.floor(own.length / 2)], `reference (${esc(names.join(", "))})`, "dot", 0.35);
        }
      }
    });
    return layout;
  }
  function facetPanels(sel, runs) {
    // one panel per (scene, delta) of the selected runs, scenes as rows, deltas as columns
    const scenes = [...new Set(runs.map((k) => R.scene[k]))].sort((a, b) => a - b);
    const deltas = [...new Set(runs.map((k) => R.delta[k]))].sort((a, b) => (b === null) - (a === null) || b - a);
    const panels = [], where = new Map();
    for (const sc of scenes) for (const d of deltas) {
      const ks = runs.filter((k) => R.scene[k] === sc && R.delta[k] === d);
      if (!ks.length) continue;
      const set = new Set(ks);
      panels.push({ title: `${D.scenes[sc]}, delta = ${d === null ? "n/a" : gg(d)}`, has: (k) => set.has(k) });
      for (const k of ks) where.set(k, panels.length);
    }
    return { panels, panelOf: (k) => where.get(k) || 1, ncols: Math.min(Math.max(deltas.length, 1), 3) };
  }
  function drawWp(sel, runs) {
    let panels, panelOf, ncols;
    if (sel.panels === "scene-delta") {
      ({ panels, panelOf, ncols } = facetPanels(sel, runs));
      if (!panels.length) panels = [{ title: "all", has: () => true }];
    } else {
      const present = D.families.filter((f) => runs.some((k) => D.solvers[R.solver[k]].family === f));
      const nSel = new Set(runs.map((k) => R.solver[k])).size;
      const split = sel.panels === "family" || (sel.panels === "auto" && nSel > D.max_series);
      const fams = split && present.length > 1 ? present : ["all"];
      panels = fams.map((f) => ({ title: f, has: (k) => f === "all" || D.solvers[R.solver[k]].family === f }));
      panelOf = (k) => fams.length > 1 ? fams.indexOf(D.solvers[R.solver[k]].family) + 1 : 1;
    }
    const w = wpTraces(sel, runs, panelOf);
    const curvesNote = Object.keys(D.curves).length ?
      `Lines: at each time, the median over the selected runs of each solver's tightest tier (per panel) started by then of their convergence ` +
      `curve (interpolated in log time and log error between samples; a finished run keeps its last error), ` +
      `bands: the ${100 * QLO}-${100 * QHI} % quantiles of log error (${w.nCurves} curves; as the static ` +
      `figures of 'dualfem report bench'); markers: the runs' final answers.` :
      "These results hold no convergence curves (bench spec key curves = true records them): each run is a point.";
    byId("dash-status").dataset.medianCurves = String(w.nMedians);
    byId("wp-note").textContent = `${w.nPoints} runs of ${w.nSolvers} solvers drawn (runs without a time or this ` +
      `error are left out). ${curvesNote} ` +
      "Hollow markers: status not solved (the solver's claim demoted, or a failure with an iterate). " +
      `Errors below ${FLOOR_ERR} are drawn at ${FLOOR_ERR}. Dashed: the floor (one factorization + one solve of K). ` +
      (w.nSelfRef ? `Dotted: the reference solver's own runs (${w.nSelfRef}; their error against their own ` +
        "reference is 0 by construction, so they are a line at their median time, not a competitor; the KKT view " +
        "draws them as points). " : "") +
      "Hover a point for its run; the side panel selects solvers, by family.";
    return Plotly.react("wp-plot", w.traces, wpLayout(sel, panels, runs, ncols), { displaylogo: false, responsive: true });
  }

  /* ---------- ranking and rates ---------- */
  const RC = Object.fromEntries(D.rank_columns.map((c, i) => [c, i]));
  function rankKey(ti, sel) { return `${ti}|${sel.scene}|${sel.delta}`; }
  function rankedTiers(sel) {
    const out = [];
    for (let ti = 0; ti < D.ranked_tiers; ti++) if (sel.tier < 0 || sel.tier === ti) out.push(ti);
    return out;
  }
  function drawRates(sel) {
    const tiers = rankedTiers(sel).filter((ti) => D.rank[rankKey(ti, sel)]);
    const traces = [], names = D.solvers.map((s) => s.name).filter((n, i) => sel.solvers.has(i));
    const layout = { height: Math.max(260, 17 * names.length + 110), margin: { l: 150, r: 20, t: 40, b: 50 },
                     barmode: "group", annotations: [], legend: { orientation: "h", x: 0, y: 1.12 },
                     plot_bgcolor: "#fff", paper_bgcolor: "#fff" };
    if (tiers.length > 1) layout.grid = { rows: 1, columns: tiers.length, pattern: "independent", xgap: 0.06 };
    tiers.forEach((ti, j) => {
      const sx = j === 0 ? "" : String(j + 1);
      const rows = D.rank[rankKey(ti, sel)].rows.filter((r) => sel.solvers.has(r[0]));
      const y = rows.map((r) => D.solvers[r[0]].name);
      for (const [key, label, color] of [["success", "success rate", "#0072B2"], ["correct", "correct rate", "#E69F00"]]) {
        traces.push({ type: "bar", orientation: "h", y, x: rows.map((r) => r[RC[key]] === null ? null : 100 * r[RC[key]]),
                      name: label, marker: { color }, xaxis: "x" + sx, yaxis: "y" + sx, showlegend: j === 0,
                      legendgroup: key, hovertemplate: `%{y}: ${label} %{x:.0f} %<extra>tier ${esc(D.tiers[ti].name)}</extra>` });
      }
      layout["xaxis" + sx] = { range: [0, 104], tickvals: [0, 25, 50, 75, 100], title: { text: `% (tier ${D.tiers[ti].name})` }, gridcolor: "#e5e5e5" };
      layout["yaxis" + sx] = { categoryorder: "array", categoryarray: names.slice().reverse(), showticklabels: j === 0,
                               matches: j === 0 ? undefined : "y", automargin: true };
    });
    byId("rate-note").textContent = tiers.length ? "Per tier, over the scenes, sizes and deltas selected: success " +
      "rate (certified correct claims within the time limit / runs) and correct rate (certified correct / checkable " +
      "solved claims; no bar: no checkable claim). Definitions below." : "No ranked runs in this selection.";
    return Plotly.react("rate-plot", traces, layout, { displaylogo: false, responsive: true });
  }
  function cell(tr, text, cls) { const td = el("td", cls ? { class: cls } : {}, text); tr.appendChild(td); return td; }
  function nameCell(tr, si) {
    const s = D.solvers[si], td = el("td", { class: "name" });
    td.appendChild(el("span", { class: "swatch", style: `background:${s.color}` }));
    td.appendChild(document.createTextNode(s.name));
    tr.appendChild(td);
  }
  function wrong(r) {
    const parts = [["demoted", "demoted"], ["flagged", "flagged"], ["silent_wrong", "silent wrong"]]
      .filter(([k]) => r[RC[k]]).map(([k, w]) => `${r[RC[k]]} ${w}`);
    return (parts.join(", ") || "0") + (r[RC.unverified] ? ` (+${r[RC.unverified]} unverified)` : "");
  }
  function drawRanking(sel) {
    const box = byId("rank-tables");
    box.replaceChildren();
    for (const ti of rankedTiers(sel)) {
      const t = D.tiers[ti], data = D.rank[rankKey(ti, sel)];
      box.appendChild(el("h3", {}, t.tol === null ? `tier ${t.name}` : `tier ${t.name} (tol ${gg(t.tol)})`));
      if (!data) { box.appendChild(el("p", { class: "note" }, "No runs of this tier in the selection.")); continue; }
      box.appendChild(el("p", { class: "note" }, `Shifted geometric mean of time over the ${data.n} scenes every ` +
        "solver of this table ran; ranks among all solvers of the results (unticked ones are hidden, not re-ranked)."));
      const tab = el("table"), head = el("tr");
      for (const h of ["rank", "solver", "runs", "success rate", "solved claims", "certified correct", "correct rate",
                       "claims agree", "wrong claims", "shifted GM of time (rel.)", "plain GM (rel.)"]) {
        head.appendChild(el("th", h === "solver" ? { class: "name" } : {}, h));
      }
      tab.appendChild(head);
      data.rows.forEach((r, i) => {
        if (!sel.solvers.has(r[0])) return;
        const tr = el("tr");
        cell(tr, String(i + 1)); nameCell(tr, r[0]); cell(tr, String(r[RC.runs])); cell(tr, pct(r[RC.success]));
        cell(tr, String(r[RC.claims]));
        cell(tr, String(r[RC.certified]) + (r[RC.over_time] ? ` (${r[RC.over_time]} over time)` : ""));
        cell(tr, pct(r[RC.correct])); cell(tr, pct(r[RC.agree])); cell(tr, wrong(r));
        cell(tr, `${f2(r[RC.sgm_rel])} (${g3(r[RC.sgm])} s)`); cell(tr, f2(r[RC.gm_rel]));
        tab.appendChild(tr);
      });
      box.appendChild(tab);
    }
    byId("rank-note").textContent = `As in 'dualfem report bench': ranked by success rate, then the shifted ` +
      `geometric mean of time of the successful runs (shift ${D.shift} s; a failure is not given a time), then the ` +
      "correct rate; for the scene and delta selected (all tiers or the one selected).";
  }
  function drawTargets(sel) {
    const box = byId("targets");
    box.replaceChildren();
    const T = D.target_settings;
    byId("targets-section").hidden = !D.show_targets;
    if (!D.show_targets) return;
    const rows = D.targets.filter((c) => (sel.scene < 0 || c.scene === D.scene_names[sel.scene]) &&
      (sel.delta < 0 || c.delta === D.deltas[sel.delta]) &&
      solverIndex.has(c.solver) && sel.solvers.has(solverIndex.get(c.solver)));
    byId("targets-note").textContent = D.targets.length ?
      `Our solvers (${T.ours.join(", ")}) at the two largest sizes: a run counts when solved with relative ` +
      `energy-norm error <= ${gg(T.error)}; time = setup + solve, against the floor (target <= ${T.floor} x) and the ` +
      `fastest competitor at that error (target >= ${T.speed} x faster).` : "No run of our solvers in these results.";
    if (!rows.length) return;
    const tab = el("table"), head = el("tr");
    for (const h of ["scene", "N", "delta", "solver", "time [s] (setup + solve)", "end to end [s]", "peak RSS [MB]",
                     "floor [s]", "x floor", "fastest competitor [s]", "speed-up"]) head.appendChild(el("th", {}, h));
    tab.appendChild(head);
    const misses = [];
    for (const c of rows) {
      const tr = el("tr");
      cell(tr, c.scene, "name"); cell(tr, gg(c.N)); cell(tr, gg(c.delta)); nameCell(tr, solverIndex.get(c.solver));
      if (c.met) {
        cell(tr, `${g3(c.time_s)} (${g3(c.setup_s)} + ${g3(c.solve_s)})`); cell(tr, g3(c.end_to_end_s));
        cell(tr, c.peak_rss_mb === null ? "n/a" : c.peak_rss_mb.toFixed(0));
      } else {
        cell(tr, c.quiet_status !== null ? `status ${c.quiet_status}: error ${g3(c.quiet_error)} in ${g3(c.time_s)} s, ` +
          "not claimed" : `no run reached ${gg(T.error)} (${c.statuses.join(", ")})`, "miss");
        cell(tr, ""); cell(tr, "");
      }
      cell(tr, g3(c.floor_s) + (c.floor_backend ? ` (${c.floor_backend.replace(/^floor_/, "")})` : ""));
      if (!c.met) { cell(tr, "MISSED", "miss"); cell(tr, ""); cell(tr, ""); } else {
        cell(tr, f2(c.floor_ratio) + (c.floor_ok === null ? "" : c.floor_ok ? " ok" : " MISSED"),
             c.floor_ok === null ? "" : c.floor_ok ? "ok" : "miss");
        cell(tr, c.competitor ? `${g3(c.competitor_s)} (${c.competitor}, tier ${c.competitor_tier})` : c.competitor_note);
        cell(tr, c.competitor ? f2(c.speedup) + (c.speedup_ok ? " ok" : " MISSED") :
             c.speedup !== null ? `> ${f2(c.speedup)} (lower bound)` : "n/a",
             c.competitor ? (c.speedup_ok ? "ok" : "miss") : "");
      }
      tab.appendChild(tr);
      misses.push(...c.misses);
    }
    box.appendChild(tab);
    if (misses.length) {
      box.appendChild(el("p", {}, `Targets missed in this selection (${misses.length}):`));
      const ul = el("ul");
      for (const m of misses) ul.appendChild(el("li", {}, m));
      box.appendChild(ul);
    }
  }

  /* ---------- page ---------- */
  function header() {
    const nsrc = D.sources.length;
    byId("dash-summary").textContent = `${NRUNS} runs of ${D.solvers.length} solver variants (${D.families.length} ` +
      `families) on ${D.scenes.length} scene(s) (${D.scenes.join("; ")}), ${D.deltas.length} delta(s), tiers ` +
      `${D.tiers.map((t) => t.name).join(", ")}; from ${nsrc} results folder${nsrc > 1 ? "s" : ""}` +
      (D.command ? `; generated by ${D.command}` : "") + ".";
    const ul = document.querySelector("#dash-sources ul");
    D.sources.forEach((s, i) => {
      const li = el("li");
      li.appendChild(el("code", {}, s.results));
      li.appendChild(document.createTextNode(` (${s.kind}, ${s.kept} of its ${s.n_rows} rows shown` +
        (s.command ? `; written by ` : ")")));
      if (s.command) {
        li.appendChild(el("code", {}, s.command));
        li.appendChild(document.createTextNode(`, ${s.started_utc || "?"} to ${s.finished_utc || "not finished"})`));
      }
      if (nsrc > 1) li.appendChild(document.createTextNode(i ? " (replaces the rows of the earlier ones that measure the same thing)" : ""));
      ul.appendChild(li);
    });
    const defs = byId("definitions");
    for (const text of [D.definitions.correct, D.definitions.success]) defs.appendChild(el("p", { class: "note" }, text.replace(/[*`]/g, "")));
  }
  let busy = Promise.resolve();
  function update() {
    const sel = selection();
    const runs = selectedRuns(sel);
    drawRanking(sel);
    drawTargets(sel);
    busy = Promise.all([drawWp(sel, runs), drawRates(sel)]);
    return busy;
  }
  header();
  // faceted by scene and delta; with more panels than MAX_PANELS, open on one scene (its deltas): the one
  // with the most runs that recorded a convergence curve, else the first
  const MAX_PANELS = 24;
  const nPanels = new Set((R.scene || []).map((sc, k) => `${sc}|${R.delta[k]}`)).size;
  if (nPanels > MAX_PANELS && D.scenes.length > 1) {
    const withCurves = D.scenes.map(() => 0);
    (R.scene || []).forEach((sc, k) => { if (D.curves[R.id[k]]) withCurves[sc] += 1; });
    const open = withCurves.indexOf(Math.max(...withCurves));
    byId("f-scene").value = String(open);
    byId("dash-summary").textContent += ` The work-precision view opens on the scene ${D.scenes[open]} ` +
      `(${nPanels} scene and delta panels in all): choose a scene, or 'all', in the side panel.`;
  }
  syncFamilies();
  update().then(() => {
    const status = byId("dash-status");
    status.dataset.state = "rendered";
    status.textContent = `rendered ${document.querySelectorAll(".js-plotly-plot").length} plots`;
    document.documentElement.setAttribute("data-dash-rendered", "ok");
  }).catch((err) => window.dashReportError("render failed: " + (err && err.stack ? err.stack : err)));
})();
