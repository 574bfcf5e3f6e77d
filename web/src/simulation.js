// simulation: a scenario simulated once and tracked by the chosen methods, compared.
import { get, post, waitForJob } from "./api.js";
import { errorPlots, fmt, h, mm, options, table, trackPlot } from "./views.js";

export function render(panel) {
  const scenario = h("select", { name: "scenario" });
  const seed = h("input", { type: "number", name: "seed", value: "1", min: "0" });
  const duration = h("input", { type: "number", name: "duration", value: "10", min: "1" });
  const methods = h("div", { class: "methods" });
  const run = h("button", { type: "submit", text: "simulate and track" });
  const form = h("form", {}, h("label", {}, "scenario", scenario), h("label", {}, "seed", seed),
    h("label", {}, "duration (s)", duration), h("label", {}, "methods", methods), run);
  const status = h("div", { class: "status", "data-testid": "simulation-status" });
  const progress = h("progress", { max: "1", value: "0" });
  const out = h("div");
  panel.append(form, progress, status, out);
  run.disabled = true; // until both lists are in: a submit before would send an empty choice
  Promise.all([get("/api/scenarios").then((list) => options(scenario, list, "glac-3d-arm")), get("/api/methods").then((list) => methods.replaceChildren(...list.map((m) =>
    h("span", {}, h("input", { type: "checkbox", value: m.name, ...(["glac", "glac-no-velocity"].includes(m.name) ? { checked: "" } : {}) }), ` ${m.name} `))))]).then(() => { run.disabled = false; });

  form.addEventListener("submit", async (event) => {
    event.preventDefault();
    const chosen = [...methods.querySelectorAll("input:checked")].map((c) => c.value);
    status.className = "status";
    try {
      const { job } = await post("/api/simulation/run", { scenario: scenario.value, seed: +seed.value, duration_s: +duration.value, methods: chosen });
      const result = await waitForJob(job, (j) => { progress.value = j.progress; status.textContent = j.message; });
      status.textContent = `${result.scenario}, seed ${result.seed}: ${chosen.length} methods compared`;
      status.dataset.done = "1";
      const reports = Object.fromEntries(Object.entries(result.results).map(([m, r]) => [m, r.report]));
      const first = Object.values(result.results)[0];
      out.replaceChildren(
        table([
          { title: "method", value: (r) => r.method },
          { title: "estimates", value: (r) => r.rows },
          { title: "median 3D (mm)", value: (r) => mm(r.median_3d_m) },
          { title: "p90 3D (mm)", value: (r) => mm(r.p90_3d_m) },
          { title: "converged (s)", value: (r) => fmt(r.convergence_time_s, 2) },
          { title: "tracked in (ms)", value: (r) => fmt(r.wall_s * 1000, 0) },
        ], result.table, { "data-testid": "simulation-table" }),
        h("div", { class: "plots" }, first ? trackPlot(first.track, result.truth, result.scene, `${first.method} (top view)`) : ""),
        errorPlots(reports));
    } catch (error) {
      status.className = "status error";
      status.textContent = error.message;
    }
  });
}
