// batch: many seeds of a scenario, one method, one summary table, with progress.
import { get, post, waitForJob } from "./api.js";
import { fmt, h, mm, options, table } from "./views.js";

const COLUMNS = [
  { title: "seed", value: (r) => r.seed },
  { title: "estimates", value: (r) => r.rows },
  { title: "median 3D (mm)", value: (r) => mm(r.median_3d_m) },
  { title: "p90 3D (mm)", value: (r) => mm(r.p90_3d_m) },
  { title: "converged (s)", value: (r) => fmt(r.convergence_time_s, 2) },
];

export function render(panel) {
  const scenario = h("select", { name: "scenario" });
  const method = h("select", { name: "method" });
  const seeds = h("input", { type: "number", name: "seeds", value: "5", min: "1" });
  const duration = h("input", { type: "number", name: "duration", value: "8", min: "1" });
  const form = h("form", {}, h("label", {}, "scenario", scenario), h("label", {}, "method", method),
    h("label", {}, "seeds", seeds), h("label", {}, "duration (s)", duration), h("button", { type: "submit", text: "run batch" }));
  const progress = h("progress", { max: "1", value: "0" });
  const status = h("div", { class: "status", "data-testid": "batch-status" });
  const out = h("div");
  panel.append(form, progress, status, out);
  const run = form.querySelector("button");
  run.disabled = true; // until both lists are in: a submit before would send an empty choice
  Promise.all([get("/api/scenarios").then((list) => options(scenario, list, "glac-3d-arm")),
    get("/api/methods").then((list) => options(method, list, "glac"))]).then(() => { run.disabled = false; });

  form.addEventListener("submit", async (event) => {
    event.preventDefault();
    status.className = "status";
    try {
      const { job } = await post("/api/batch/run", { scenario: scenario.value, method: method.value, seeds: +seeds.value, duration_s: +duration.value });
      const result = await waitForJob(job, (j) => {
        progress.value = j.progress;
        status.textContent = j.message;
        if (j.live?.rows) out.replaceChildren(table(COLUMNS, j.live.rows));
      });
      const s = result.summary;
      status.textContent = `${result.method} on ${result.scenario}: ${s.seeds} seeds`;
      status.dataset.done = "1";
      out.replaceChildren(
        table([
          { title: "seeds", value: () => s.seeds },
          { title: "median of median 3D (mm)", value: () => mm(s.median_3d_m) },
          { title: "median of p90 3D (mm)", value: () => mm(s.p90_3d_m) },
          { title: "median convergence (s)", value: () => fmt(s.convergence_time_s, 2) },
          { title: "seeds converged", value: () => `${Math.round(s.converged_share * 100)} %` },
        ], [s], { "data-testid": "batch-summary" }),
        table(COLUMNS, result.rows, { "data-testid": "batch-rows" }));
    } catch (error) {
      status.className = "status error";
      status.textContent = error.message;
    }
  });
}
