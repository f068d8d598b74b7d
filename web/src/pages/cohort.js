// One cohort: its request and provenance, live status, statistics plots, a grid of shape
// thumbnails, the shapes' measurements in a sortable table, and every download.

import { api, access, readableUrl } from "../api.js";
import { badge, facts, h, num, progressBar, replace } from "../dom.js";
import { onJob } from "../events.js";
import { cohortActions } from "./cohorts.js";
import { validationsSection } from "./validations.js";

const PLOTS = [
  ["pairwise-cd", "Pairwise Chamfer distance"],
  ["novelty-cd", "Novelty (CD to the nearest training shape)"],
  ["annulus", "Annulus diameter"],
  ["sinus", "Sinus diameter"],
  ["stj", "Sinotubular junction diameter"],
  ["sinus-height", "Sinus height"],
  ["length", "Centreline length"],
  ["area", "Surface area"],
  ["volume", "Volume"],
];

export const FORMATS = ["glb", "gltf", "stl", "obj", "ply"];

/** Table columns: [heading, value of a shape, formatter]. */
const COLUMNS = [
  ["#", (s) => s.index, String],
  ["Area mm²", (s) => s.area_mm2, (v) => num(v, 5)],
  ["Volume mm³", (s) => s.volume_mm3, (v) => num(v, 5)],
  ["Novelty CD", (s) => s.novelty_cd, num],
  ["Nearest", (s) => s.nearest_training_index, (v) => v ?? "–"],
  ["Annulus mm", (s) => s.anatomy?.annulus_mm, (v) => num(v, 3)],
  ["Sinus mm", (s) => s.anatomy?.sinus_mm, (v) => num(v, 3)],
  ["STJ mm", (s) => s.anatomy?.stj_mm, (v) => num(v, 3)],
  ["Sinus height mm", (s) => s.anatomy?.sinus_height_mm, (v) => num(v, 3)],
  ["Ascending mm", (s) => s.anatomy?.ascending_mm, (v) => num(v, 3)],
  ["Length mm", (s) => s.anatomy?.length_mm, (v) => num(v, 3)],
  ["Max diameter mm", (s) => s.anatomy?.max_diameter_mm, (v) => num(v, 3)],
];

/** Every shape of a cohort, page by page. */
export async function allShapes(cohortId) {
  const shapes = [];
  let offset = 0;
  for (;;) {
    const page = (await api(`/v1/cohorts/${cohortId}/shapes?limit=100&offset=${offset}`)).data;
    shapes.push(...page.items);
    if (page.next_offset == null) return shapes;
    offset = page.next_offset;
  }
}

/** An <img> whose source may need the key (set once the bytes are fetched). */
export function picture(path, alt, props = {}) {
  const img = h("img", { alt, loading: "lazy", decoding: "async", ...props });
  readableUrl(path).then((url) => (img.src = url), () => (img.alt = `${alt} (not available)`));
  return img;
}

/** A link that downloads `path`; fetched with the key when reads need one. */
export function downloadLink(path, filename, label) {
  const a = h("a", { href: path, download: filename, class: "download" }, label);
  if (access.readsNeedKey) {
    a.addEventListener("click", async (event) => {
      if (a.dataset.ready) return;
      event.preventDefault();
      a.href = await readableUrl(path);
      a.dataset.ready = "1";
      a.click();
    });
  }
  return a;
}

function requestFacts(c) {
  const targets = c.targets
    ? Object.entries(c.targets).map(([k, r]) => `${k} ${r.min ?? "…"}–${r.max ?? "…"}`).join(", ")
    : null;
  return facts([
    ["Model", h("a", { href: "#/models" }, c.model_id)],
    ["Shapes", c.count],
    ["Arity", c.arity],
    ["Weights", c.weights ? c.weights.map((w) => num(w, 3)).join(", ") : c.weighting],
    ["Selection", c.selection],
    ["Latent noise", c.latent_noise],
    ["Seed", String(c.seed)],
    ["Resolution", `${c.resolution}³`],
    c.min_novelty != null && ["Minimum novelty", num(c.min_novelty)],
    c.anchors && ["Anchors", c.anchors.join(", ")],
    targets && ["Targets", targets],
    c.max_candidates != null && ["Max candidates", c.max_candidates],
    ["Redraws", c.redraws_total],
    targets && ["Candidates / targets missed", `${c.candidates_total} / ${c.targets_not_met}`],
    ["Job", h("a", { href: c.links.job }, `#${c.job_id}`)],
    ["Created", c.created_at],
    c.started_at && ["Started", c.started_at],
    c.finished_at && ["Finished", c.finished_at],
    c.error && ["Error", h("span", { class: "error" }, c.error)],
  ]);
}

function summaryFacts(c, metrics) {
  const s = c.summary ?? {};
  const range = (r, unit) => (r ? `${num(r.mean, 5)} ${unit} (${num(r.min, 5)}–${num(r.max, 5)})` : "–");
  const nov = metrics?.novelty?.summary;
  return facts([
    ["Area", range(s.area_mm2, "mm²")],
    ["Volume", range(s.volume_mm3, "mm³")],
    ["Pairwise CD (mean)", s.pairwise_chamfer ? num(s.pairwise_chamfer.mean) : "–"],
    nov && ["Novelty CD (median)", num(nov.quantiles.p50)],
    metrics && ["Measured shapes", `${metrics.anatomy.measured} (roots ${metrics.anatomy.roots}, failed ${metrics.anatomy.failed})`],
    ["Units", "Chamfer distances are squared, in unit-ball coordinates; sizes in mm"],
  ]);
}

function sortableTable(shapes) {
  let sortBy = 0;
  let ascending = true;
  const body = h("tbody");
  const heads = COLUMNS.map(([title], i) =>
    h("th", { scope: "col", "aria-sort": i === 0 ? "ascending" : "none" },
      h("button", { type: "button", class: "sort", onClick: () => sort(i) }, title)));
  function draw() {
    const value = COLUMNS[sortBy][1];
    const sorted = [...shapes].sort((a, b) => {
      const [x, y] = [value(a), value(b)];
      if (x == null) return 1;
      if (y == null) return -1;
      return ascending ? x - y : y - x;
    });
    body.replaceChildren(...sorted.map((s) =>
      h("tr", {},
        COLUMNS.map(([, v, f], i) => h(i === 0 ? "th" : "td", { class: "num", scope: i === 0 ? "row" : undefined }, f(v(s)))),
        h("td", { class: "links" },
          h("a", { href: `#/viewer?shape=${s.id}` }, "view"), " ",
          FORMATS.map((f) => [downloadLink(`/v1/shapes/${s.id}/mesh?format=${f}`, `shape-${s.id}.${f}`, f), " "])))));
  }
  function sort(i) {
    ascending = sortBy === i ? !ascending : true;
    sortBy = i;
    heads.forEach((th, k) => th.setAttribute("aria-sort", k === i ? (ascending ? "ascending" : "descending") : "none"));
    draw();
  }
  draw();
  return h("div", { class: "table-wrap" },
    h("table", { class: "list", id: "measurements" },
      h("caption", { class: "sr-only" }, "Shapes and their measurements; sort by a column heading"),
      h("thead", {}, h("tr", {}, heads, h("th", { scope: "col" }, "Downloads"))), body));
}

export async function cohortPage(main, id) {
  let cohort = (await api(`/v1/cohorts/${id}`)).data;
  const head = h("div", { class: "cohort-head" });
  const content = h("div");
  const message = h("p", { class: "error", role: "alert" });
  let shownShapes = -1;
  let validations = null;
  let stopValidations = () => {};

  function drawHead() {
    replace(head,
      h("h1", {}, `Cohort #${cohort.id} `, badge(cohort.status)),
      h("div", { id: "cohort-progress" }, progressBar(cohort.progress.done, cohort.progress.total, "cohort progress")),
      h("div", { class: "actions" },
        cohortActions(cohort, () => (location.hash = "#/cohorts"), (m) => (message.textContent = m)),
        h("a", { class: "button ghost", href: `/v1/cohorts/${id}/report`, target: "_blank", rel: "noopener" }, "HTML report")));
  }

  async function drawContent() {
    const shapes = await allShapes(id);
    shownShapes = shapes.length;
    const done = cohort.status === "succeeded";
    const metrics = done ? (await api(`/v1/cohorts/${id}/metrics`)).data : null;
    if (done && !validations) [validations, stopValidations] = validationsSection(cohort);
    replace(content,
      h("div", { class: "columns" },
        h("section", {}, h("h2", {}, "Request and provenance"), requestFacts(cohort)),
        h("section", {}, h("h2", {}, "Summary"), summaryFacts(cohort, metrics),
          h("h3", {}, "Downloads"),
          h("p", { class: "links" },
            downloadLink(`/v1/cohorts/${id}/metrics`, `cohort-${id}-metrics.json`, "metrics JSON"), " ",
            downloadLink(`/v1/cohorts/${id}/metrics?format=csv`, `cohort-${id}-metrics.csv`, "metrics CSV"), " ",
            downloadLink(`/v1/cohorts/${id}/report`, `cohort-${id}.html`, "report HTML")),
          h("p", { class: "muted" }, "Each shape downloads as GLB, glTF, STL, OBJ or PLY (mm) from the table below."))),
      validations,
      h("section", {}, h("h2", {}, `Shapes (${shapes.length} of ${cohort.count})`),
        h("ul", { class: "thumbs" }, shapes.map((s) =>
          h("li", {}, h("a", { href: `#/viewer?shape=${s.id}`, title: `Open shape ${s.id} in the viewer` },
            picture(`/v1/shapes/${s.id}/thumbnail.png`, `shape ${s.index}`, { width: 128, height: 128 }),
            h("span", {}, `#${s.index}`)))))),
      shapes.length > 0 && h("section", {}, h("h2", {}, "Measurements"), sortableTable(shapes)),
      done && h("section", {}, h("h2", {}, "Statistics"),
        h("div", { class: "plots" }, PLOTS.map(([name, title]) =>
          h("figure", {}, picture(`/v1/cohorts/${id}/plots/${name}`, title), h("figcaption", {}, title))))));
  }

  drawHead();
  replace(main, head, message, content);
  await drawContent();

  let refreshing = false;
  const stopCohort = onJob(async (job) => {
    if (job.subject !== `/v1/cohorts/${id}`) return;
    const finished = job.status !== cohort.status && !["queued", "running"].includes(job.status);
    cohort = { ...cohort, status: job.status, progress: job.progress, error: job.error };
    drawHead();
    if (refreshing || (!finished && job.progress.done === shownShapes)) return;
    refreshing = true;
    try {
      cohort = (await api(`/v1/cohorts/${id}`)).data;
      drawHead();
      await drawContent();
    } finally {
      refreshing = false;
    }
  });
  return () => {
    stopCohort();
    stopValidations();
  };
}
