// The dashboard: five tabs, one module each, chosen by the address's #hash
// (so a tab can be linked to, and a page test can open one directly).
import "./style.css";
import * as online from "./online.js";
import * as offline from "./offline.js";
import * as simulation from "./simulation.js";
import * as batch from "./batch.js";
import * as config from "./config.js";

const TABS = { online, offline, simulation, batch, config };
const panel = document.getElementById("panel");
let current = null;

function show() {
  const name = TABS[location.hash.slice(1)] ? location.hash.slice(1) : "online";
  if (name === current) return;
  current?.leave?.();
  current = TABS[name];
  document.querySelectorAll("#tabs button").forEach((b) => b.classList.toggle("active", b.dataset.tab === name));
  panel.replaceChildren();
  panel.dataset.tab = name;
  current.render(panel);
}

document.querySelectorAll("#tabs button").forEach((b) =>
  b.addEventListener("click", () => { location.hash = b.dataset.tab; }));
window.addEventListener("hashchange", show);
show();
