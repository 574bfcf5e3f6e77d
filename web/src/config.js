// config: a scene's TOML edited here; the geometry check's lines and the antennas drawn.
import { get, post } from "./api.js";
import { h, options } from "./views.js";
import { antennaSeries, plot } from "./plot.js";

export function render(panel) {
  const scenario = h("select", { name: "scenario" });
  const load = h("button", { type: "button", text: "load its scene" });
  const text = h("textarea", { name: "toml", spellcheck: "false" });
  const check = h("button", { type: "button", text: "check" });
  const lines = h("div", { "data-testid": "config-lines" });
  const drawing = h("div", { class: "plots" });
  panel.append(h("div", { class: "controls" }, h("label", {}, "scenario", scenario), load),
    h("div", { class: "row" }, h("div", {}, text, check), h("div", {}, lines, drawing)));

  const fromScenario = async () => {
    lines.replaceChildren(h("div", { class: "status", text: "loading..." }));
    text.value = (await get(`/api/config/scene?scenario=${encodeURIComponent(scenario.value)}`)).toml;
    await run();
  };
  const run = async () => {
    lines.replaceChildren(h("div", { class: "status", text: "checking..." }));
    try {
      const result = await post("/api/config/check", { toml: text.value });
      lines.replaceChildren(
        h("div", { class: "status", "data-testid": "config-status", "data-warnings": result.warnings,
          text: `${result.warnings} warning${result.warnings === 1 ? "" : "s"}` }),
        ...result.lines.map((line) => h("pre", { class: line.startsWith("warning:") ? "warning" : "", text: line })));
      const a = result.scene;
      const side = { x: a.antennas.map((x) => x.position[0]), y: a.antennas.map((x) => x.position[2]), marker: "triangle", color: "#333", cls: "antenna-side", labels: a.antennas.map((x) => `${x.id}`) };
      drawing.replaceChildren(
        plot([antennaSeries(a)], { title: "antennas, top view (x, y)", xlabel: "x (m)", ylabel: "y (m)", equal: true, width: 360, height: 300 }),
        plot([side], { title: "antennas, side view (x, z)", xlabel: "x (m)", ylabel: "z (m)", equal: true, width: 360, height: 300 }));
    } catch (error) {
      lines.replaceChildren(h("div", { class: "status error", "data-testid": "config-status", text: error.message }));
    }
  };
  load.addEventListener("click", fromScenario);
  check.addEventListener("click", run);
  get("/api/scenarios").then((list) => { options(scenario, list, "glac-3d-arm-paper-layout"); fromScenario(); });
}
