// Plain SVG plots: a few hundred lines of our own instead of a charting
// library. Each plot is an <svg> with axes, lines and points; points carry
// a class (e.g. "estimate") so that a page test can count what is drawn.
const NS = "http://www.w3.org/2000/svg";
export const COLORS = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf"];

function el(name, attrs = {}, parent = null) {
  const node = document.createElementNS(NS, name);
  for (const [k, v] of Object.entries(attrs)) node.setAttribute(k, v);
  if (parent) parent.appendChild(node);
  return node;
}

function extent(values) {
  let lo = Infinity, hi = -Infinity;
  for (const v of values) if (v !== null && Number.isFinite(v)) { lo = Math.min(lo, v); hi = Math.max(hi, v); }
  if (!Number.isFinite(lo)) return [0, 1];
  if (lo === hi) return [lo - 0.5, hi + 0.5];
  const pad = (hi - lo) * 0.05;
  return [lo - pad, hi + pad];
}

function ticks([lo, hi], count = 5) {
  const step = 10 ** Math.floor(Math.log10((hi - lo) / count));
  const nice = [1, 2, 5, 10].map((m) => m * step).find((s) => (hi - lo) / s <= count) ?? step * 10;
  const out = [];
  for (let v = Math.ceil(lo / nice) * nice; v <= hi + 1e-12; v += nice) out.push(+v.toPrecision(10));
  return out;
}

// series: [{x: [], y: [], color, line: bool, points: bool, cls, label, marker: "triangle"}]
export function plot(series, { title = "", xlabel = "", ylabel = "", width = 520, height = 380, equal = false } = {}) {
  const m = { l: 56, r: 12, t: 26, b: 40 };
  const svg = el("svg", { width, height, class: "plot", viewBox: `0 0 ${width} ${height}` });
  let xr = extent(series.flatMap((s) => s.x));
  let yr = extent(series.flatMap((s) => s.y));
  const w = width - m.l - m.r, h = height - m.t - m.b;
  if (equal) {
    // Same metres per pixel on both axes: positions look as they are.
    const scale = Math.max((xr[1] - xr[0]) / w, (yr[1] - yr[0]) / h);
    const cx = (xr[0] + xr[1]) / 2, cy = (yr[0] + yr[1]) / 2;
    xr = [cx - (scale * w) / 2, cx + (scale * w) / 2];
    yr = [cy - (scale * h) / 2, cy + (scale * h) / 2];
  }
  const X = (v) => m.l + ((v - xr[0]) / (xr[1] - xr[0])) * w;
  const Y = (v) => m.t + h - ((v - yr[0]) / (yr[1] - yr[0])) * h;
  el("text", { x: m.l, y: 16, "font-size": 13, "font-weight": "bold" }, svg).textContent = title;
  el("rect", { x: m.l, y: m.t, width: w, height: h, fill: "none", stroke: "#999" }, svg);
  for (const v of ticks(xr)) {
    el("line", { x1: X(v), x2: X(v), y1: m.t, y2: m.t + h, stroke: "#eee" }, svg);
    el("text", { x: X(v), y: m.t + h + 14, "font-size": 10, "text-anchor": "middle" }, svg).textContent = v;
  }
  for (const v of ticks(yr)) {
    el("line", { x1: m.l, x2: m.l + w, y1: Y(v), y2: Y(v), stroke: "#eee" }, svg);
    el("text", { x: m.l - 4, y: Y(v) + 3, "font-size": 10, "text-anchor": "end" }, svg).textContent = v;
  }
  el("text", { x: m.l + w / 2, y: height - 6, "font-size": 11, "text-anchor": "middle" }, svg).textContent = xlabel;
  el("text", { x: 12, y: m.t + h / 2, "font-size": 11, "text-anchor": "middle", transform: `rotate(-90 12 ${m.t + h / 2})` }, svg).textContent = ylabel;
  const inside = (x, y) => x !== null && y !== null && Number.isFinite(x) && Number.isFinite(y);
  series.forEach((s, i) => {
    const color = s.color ?? COLORS[i % COLORS.length];
    if (s.line) {
      let d = "", pen = "M";
      s.x.forEach((x, k) => {
        const y = s.y[k];
        if (!inside(x, y)) { pen = "M"; return; }
        d += `${pen}${X(x).toFixed(1)},${Y(y).toFixed(1)}`;
        pen = "L";
      });
      el("path", { d, fill: "none", stroke: color, "stroke-width": s.width ?? 1.5, class: s.cls ?? "" }, svg);
    }
    if (s.points || s.marker) {
      s.x.forEach((x, k) => {
        const y = s.y[k];
        if (!inside(x, y)) return;
        if (s.marker === "triangle") {
          const px = X(x), py = Y(y);
          el("path", { d: `M${px},${py - 7}L${px - 6},${py + 5}L${px + 6},${py + 5}Z`, fill: color, class: s.cls ?? "" }, svg);
          if (s.labels) el("text", { x: px + 8, y: py + 4, "font-size": 11 }, svg).textContent = s.labels[k];
        } else {
          el("circle", { cx: X(x).toFixed(1), cy: Y(y).toFixed(1), r: s.radius ?? 2, fill: color, class: s.cls ?? "" }, svg);
        }
      });
    }
  });
  // The legend in the title row, right-aligned: it never hides a point.
  const named = series.filter((s) => s.label);
  named.forEach((s, i) => {
    const color = s.color ?? COLORS[series.indexOf(s) % COLORS.length];
    const x = m.l + w - (named.length - i) * 100;
    el("rect", { x, y: 8, width: 10, height: 10, fill: color }, svg);
    el("text", { x: x + 14, y: 17, "font-size": 10 }, svg).textContent = s.label;
  });
  return svg;
}

// The antennas of a scene as a plot series (top view, x-y).
export function antennaSeries(scene) {
  return {
    x: scene.antennas.map((a) => a.position[0]),
    y: scene.antennas.map((a) => a.position[1]),
    marker: "triangle", color: "#333", cls: "antenna", label: "antennas",
    labels: scene.antennas.map((a) => `${a.id}`),
  };
}
