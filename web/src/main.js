// The dashboard's entry: hash routes (#/cohorts, #/cohorts/ID, #/new, #/models,
// #/viewer?shape=ID&overlay=ID), the key button and the live event stream.

import "./style.css";
import { askKey, currentKey, forgetKey, loadAccess } from "./api.js";
import { h, replace } from "./dom.js";
import { startEvents } from "./events.js";
import { cohortsPage } from "./pages/cohorts.js";
import { cohortPage } from "./pages/cohort.js";
import { createPage } from "./pages/create.js";
import { modelsPage } from "./pages/models.js";
import { viewerPage } from "./pages/viewer.js";

const main = document.getElementById("main");
let cleanup = () => {};

/** The page for a hash: [nav section, render function(main, params) → cleanup]. */
function route(hash) {
  const [path, query = ""] = hash.replace(/^#/, "").split("?");
  const params = new URLSearchParams(query);
  const parts = path.split("/").filter(Boolean);
  if (parts[0] === "cohorts" && parts[1]) return ["cohorts", (m) => cohortPage(m, Number(parts[1]))];
  if (parts[0] === "new") return ["new", (m) => createPage(m, params)];
  if (parts[0] === "models") return ["models", (m) => modelsPage(m)];
  if (parts[0] === "viewer") return ["viewer", (m) => viewerPage(m, params)];
  return ["cohorts", (m) => cohortsPage(m, params)];
}

async function render() {
  cleanup();
  cleanup = () => {};
  const [section, page] = route(location.hash);
  for (const link of document.querySelectorAll("[data-nav]")) {
    if (link.dataset.nav === section) link.setAttribute("aria-current", "page");
    else link.removeAttribute("aria-current");
  }
  replace(main, h("p", { class: "muted" }, "Loading…"));
  try {
    cleanup = (await page(main)) ?? (() => {});
  } catch (error) {
    replace(main, h("p", { class: "error", role: "alert" }, `Could not load this page: ${error.message}`));
  }
}

function updateKeyButton() {
  const button = document.getElementById("key-button");
  button.textContent = currentKey() ? "API key ✓" : "API key";
}

document.getElementById("key-button").addEventListener("click", async () => {
  if (currentKey()) forgetKey();
  await askKey("The key is kept in this tab only and sent as a bearer token.");
  updateKeyButton();
});

// The skip link focuses the content instead of changing the route.
document.querySelector(".skip").addEventListener("click", (event) => {
  event.preventDefault();
  main.focus();
});

window.addEventListener("hashchange", () => {
  render();
  main.focus({ preventScroll: true });
});

const { readsNeedKey } = await loadAccess();
if (readsNeedKey && !currentKey()) await askKey("This service protects reads: enter an API key.");
updateKeyButton();
startEvents();
render();
