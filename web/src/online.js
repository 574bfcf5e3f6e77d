// online: a live source tracked as it reads (the simulator replayed in real
// time, or an LLRP reader through the server's LiveSession); the page polls
// for the estimates it has not drawn yet.
import { get, post } from "./api.js";
import { fmt, h, mm, options, table } from "./views.js";
import { antennaSeries, plot, COLORS } from "./plot.js";

let timer = null;

export function leave() { clearTimeout(timer); timer = null; }

export function render(panel) {
  const source = h("select", { name: "source" },
    h("option", { value: "replay", text: "simulated replay" }), h("option", { value: "llrp", text: "LLRP reader" }));
  const scenario = h("select", { name: "scenario" });
  const scenePath = h("input", { type: "text", name: "scene_path", placeholder: "scene.toml on the server" });
  const llrp = h("input", { type: "text", name: "llrp", placeholder: "HOST[:PORT]" });
  const replayOnly = [h("label", {}, "scenario", scenario), h("label", {}, "speed (x real time)", null)];
  const llrpOnly = [h("label", {}, "scene", scenePath), h("label", {}, "reader", llrp)];
  const speed = h("input", { name: "speed", type: "number", value: "1", step: "any", min: "0.1" });
  const duration = h("input", { name: "duration", type: "number", value: "10", min: "1" });
  const start = h("button", { type: "submit", text: "start" });
  const stop = h("button", { type: "button", text: "stop", disabled: "" });
  const status = h("div", { class: "status", "data-testid": "online-status" });
  const view = h("div", { class: "row" });
  replayOnly[1].replaceChildren("speed (x real time)", speed);
  const form = h("form", {}, h("label", {}, "source", source), ...replayOnly, ...llrpOnly,
    h("label", {}, "duration (s)", duration), start, stop);
  const sourceChanged = () => {
    replayOnly.forEach((e) => { e.hidden = source.value !== "replay"; });
    llrpOnly.forEach((e) => { e.hidden = source.value !== "llrp"; });
  };
  source.addEventListener("change", sourceChanged);
  sourceChanged();
  panel.append(h("p", { text: "A live source, each read tracked when it arrives: a simulated reader session replayed in real time, or an LLRP reader (scattertrack emulate-reader, or a real one)." }), form, status, view);
  start.disabled = true; // until the scenarios are in
  get("/api/scenarios").then((list) => { options(scenario, list, "glac-3d-arm"); start.disabled = false; });

  let job = null;
  form.addEventListener("submit", async (event) => {
    event.preventDefault();
    leave();
    const points = {};
    status.className = "status";
    try {
      const request = source.value === "llrp"
        ? { source: "llrp", scene_path: scenePath.value, llrp: llrp.value, duration_s: +duration.value }
        : { scenario: scenario.value, speed: +speed.value, duration_s: +duration.value };
      job = (await post("/api/online/start", request)).job;
    } catch (error) {
      status.className = "status error";
      status.textContent = error.message;
      return;
    }
    stop.removeAttribute("disabled");
    status.textContent = "starting...";
    let since = 0;
    const poll = async () => {
      const state = await get(`/api/online/${job}?since=${since}`);
      for (const [t, epc, x, y, z, sigma] of state.points ?? []) {
        (points[epc] ??= { x: [], y: [], t: [], sigma: [] });
        points[epc].x.push(x); points[epc].y.push(y); points[epc].t.push(t); points[epc].sigma.push(sigma);
      }
      since = state.total ?? since;
      if (state.scene) draw(view, state, points);
      status.textContent = `${state.state}: ${state.message}; ${state.reads ?? 0} reads, ${since} estimates` + (state.error ? ` (${state.error})` : "");
      status.dataset.state = state.state;
      status.dataset.estimates = since;
      if (state.state === "error") status.className = "status error";
      if (state.state === "running") timer = setTimeout(poll, 250);
      else stop.setAttribute("disabled", "");
    };
    poll();
  });
  stop.addEventListener("click", () => job && post(`/api/jobs/${job}/stop`));
}

function draw(view, state, points) {
  const series = Object.entries(points).map(([epc, p], i) =>
    ({ x: p.x, y: p.y, points: true, line: true, width: 0.7, radius: 1.6, color: COLORS[i % COLORS.length], cls: "estimate", label: epc.slice(-8) }));
  series.push(antennaSeries(state.scene));
  const t0 = Math.min(...Object.values(points).map((p) => p.t[0]));
  const sigmas = Object.entries(points).map(([epc, p], i) =>
    ({ x: p.t.map((t) => t - t0), y: p.sigma.map((v) => (v === null ? null : v * 1000)), line: true, color: COLORS[i % COLORS.length] }));
  const tags = table([
    { title: "tag", value: (r) => r.epc },
    { title: "reads", value: (r) => r.reads },
    { title: "reads/s", value: (r) => fmt(r.reads_per_s, 1) },
    { title: "estimates", value: (r) => r.estimates },
    { title: "sigma (mm)", value: (r) => mm(r.sigma_m) },
    { title: "x, y, z (m)", value: (r) => (r.position ? r.position.map((v) => fmt(v, 3)).join(", ") : "-") },
  ], state.tags, { "data-testid": "online-tags" });
  view.replaceChildren(
    h("div", {}, plot(series, { title: "live track (top view)", xlabel: "x (m)", ylabel: "y (m)", equal: true })),
    h("div", {}, tags, plot(sigmas, { title: "position sigma", xlabel: "time since the first estimate (s)", ylabel: "sigma (mm)", height: 260 })));
}
