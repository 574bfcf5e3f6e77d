// offline: a scene and reads already on the server's disk (by path) or
// uploaded, any method, and the report when a truth is given.
import { get, post } from "./api.js";
import { errorPlots, h, options, trackPlot } from "./views.js";

export function render(panel) {
  const method = h("select", { name: "method" });
  const field = (name, title) => {
    const path = h("input", { type: "text", name: `${name}_path`, placeholder: "path on the server" });
    const file = h("input", { type: "file", name: `${name}_file` });
    return h("label", {}, title, path, file);
  };
  const run = h("button", { type: "submit", text: "track" });
  const form = h("form", {}, field("scene", "scene.toml"), field("reads", "reads.csv"), field("truth", "truth.csv (optional)"),
    h("label", {}, "method", method), run);
  const status = h("div", { class: "status", "data-testid": "offline-status" });
  const out = h("div");
  panel.append(form, status, out);
  run.disabled = true; // until the methods are in
  get("/api/methods").then((list) => { options(method, list, "glac"); run.disabled = false; });

  form.addEventListener("submit", async (event) => {
    event.preventDefault();
    const data = new FormData(form);
    for (const [k, v] of [...data.entries()]) if (v instanceof File && !v.name) data.delete(k);
    status.textContent = "tracking...";
    status.className = "status";
    try {
      const result = await post("/api/offline/run", data);
      status.textContent = `${result.method}: ${result.track.rows} estimates from ${result.reads} reads in ${(result.wall_s * 1000).toFixed(0)} ms`;
      status.dataset.rows = result.track.rows;
      out.replaceChildren(
        h("div", { class: "plots" }, trackPlot(result.track, result.truth, result.scene)),
        ...(result.report ? [errorPlots({ [result.method]: result.report }), h("pre", { "data-testid": "report", text: result.report.text })] : []));
    } catch (error) {
      status.className = "status error";
      status.textContent = error.message;
    }
  });
}
