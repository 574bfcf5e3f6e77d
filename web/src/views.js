// Views shared by the tabs: the track plot, the error plots, tables.
import { antennaSeries, plot, COLORS } from "./plot.js";

export function h(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === "text") node.textContent = v;
    else if (k.startsWith("on")) node.addEventListener(k.slice(2), v);
    else node.setAttribute(k, v);
  }
  for (const c of children) node.append(c);
  return node;
}

export const fmt = (v, digits = 3) => (v === null || v === undefined ? "-" : typeof v === "number" ? v.toFixed(digits) : String(v));
export const mm = (v) => (v === null || v === undefined ? "-" : (v * 1000).toFixed(1));

export function table(columns, rows, attrs = {}) {
  return h("table", attrs,
    h("thead", {}, h("tr", {}, ...columns.map((c) => h("th", { text: c.title })))),
    h("tbody", {}, ...rows.map((r) => h("tr", {}, ...columns.map((c) => h("td", { text: c.value(r) }))))));
}

// Top view of the estimates (one circle per estimate, class "estimate"), the truth and the antennas.
export function trackPlot(track, truth, scene, title = "track (top view)") {
  const series = [];
  Object.entries(track.tags).forEach(([epc, t], i) =>
    series.push({ x: t.x, y: t.y, points: true, color: COLORS[i % COLORS.length], cls: "estimate", label: epc.slice(-8) }));
  // The truth over the estimates, thin and dark: where they agree it still shows.
  if (truth) Object.values(truth.tags).forEach((t, i) =>
    series.push({ x: t.x, y: t.y, line: true, color: "#333", width: 1, cls: "truth", label: i === 0 ? "truth" : undefined }));
  if (scene) series.push(antennaSeries(scene));
  return plot(series, { title, xlabel: "x (m)", ylabel: "y (m)", equal: true });
}

export function errorPlots(reports) {
  // reports: {name: report payload}; one curve per method (all tags of it).
  const overTime = [], cdf = [];
  Object.entries(reports).forEach(([name, report], i) => {
    Object.values(report.errors).forEach((e, k) => {
      overTime.push({ x: e.t, y: e.error_m.map((v) => (v === null ? null : v * 1000)), line: true, color: COLORS[i % COLORS.length], label: k === 0 ? name : undefined });
      cdf.push({ x: e.cdf_error_m.map((v) => v * 1000), y: e.cdf_fraction, line: true, color: COLORS[i % COLORS.length], label: k === 0 ? name : undefined });
    });
  });
  return h("div", { class: "plots" },
    plot(overTime, { title: "3D error over time", xlabel: "time (s)", ylabel: "error (mm)" }),
    plot(cdf, { title: "3D error CDF", xlabel: "error (mm)", ylabel: "fraction of estimates" }));
}

export function options(select, values, selected) {
  select.replaceChildren(...values.map((v) => h("option", { value: v.name ?? v, text: v.name ?? v, ...(String(v.name ?? v) === selected ? { selected: "" } : {}) })));
  return select;
}
