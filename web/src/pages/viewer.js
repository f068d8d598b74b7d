// The 3-D viewer: pick a cohort and a shape, orbit/zoom/pan, overlay a second shape with a
// distance colour map, and read the shape's measurements and labelled openings.

import { api, fetchBytes } from "../api.js";
import { facts, h, num, replace } from "../dom.js";
import { legendGradient } from "../viewer/distance.js";
import { BACKGROUND, ShapeScene } from "../viewer/scene.js";
import { allShapes } from "./cohort.js";

const ANATOMY = [
  ["annulus_mm", "Annulus"],
  ["sinus_mm", "Sinus"],
  ["stj_mm", "STJ"],
  ["sinus_height_mm", "Sinus height"],
  ["ascending_mm", "Ascending"],
  ["length_mm", "Centreline length"],
  ["max_diameter_mm", "Max diameter"],
];

function measurementFacts(s) {
  const a = s.anatomy;
  return facts([
    ["Shape", `#${s.id} (cohort #${s.cohort_id}, index ${s.index})`],
    ["Mixed training shapes", s.provenance.training_indices.map((t, i) => `${t} × ${num(s.provenance.weights[i], 3)}`).join(", ")],
    ["Area", `${num(s.area_mm2, 5)} mm²`],
    ["Volume", `${num(s.volume_mm3, 5)} mm³`],
    ["Vertices / triangles", `${s.vertex_count} / ${s.triangle_count}`],
    ["Novelty CD", s.novelty_cd != null ? `${num(s.novelty_cd)} (nearest training shape ${s.nearest_training_index})` : "–"],
    ...(a ? ANATOMY.filter(([k]) => a[k] != null).map(([k, label]) => [label, `${num(a[k], 3)} mm`]) : []),
    !a && ["Anatomy", s.anatomy_error ?? "not measured"],
    a && ["Measured as", a.method],
  ]);
}

/** Labelled openings when the shape lists them ({name, centre: [x, y, z]} in mm). */
function openingsOf(shape) {
  return Array.isArray(shape.openings) ? shape.openings.filter((o) => Array.isArray(o.centre)) : [];
}

export async function viewerPage(main, params) {
  const cohorts = (await api("/v1/cohorts?limit=100&status=succeeded")).data.items;
  let shapeId = Number(params.get("shape")) || null;
  let overlayId = Number(params.get("overlay")) || null;
  let shape = shapeId ? (await api(`/v1/shapes/${shapeId}`)).data : null;
  let cohortId = shape?.cohort_id ?? cohorts[0]?.id ?? null;
  let shapes = cohortId ? await allShapes(cohortId) : [];
  if (!shape && shapes.length) {
    shape = shapes[0];
    shapeId = shape.id;
  }

  const canvas = h("canvas", { tabindex: 0, "aria-label": "3-D view: drag to orbit, wheel to zoom, right-drag or arrow keys to pan", dataset: { background: BACKGROUND } });
  const stage = h("div", { class: "stage", id: "viewer-stage" }, canvas);
  const info = h("div", { class: "measurements" });
  const legend = h("div", { class: "legend", hidden: true });
  const status = h("p", { class: "muted", role: "status" });
  const cohortSelect = h("select", { id: "v-cohort" }, cohorts.map((c) => h("option", { value: c.id, selected: c.id === cohortId }, `#${c.id} · ${c.model_id} · ${c.count} shapes`)));
  const shapeSelect = h("select", { id: "v-shape" });
  const overlaySelect = h("select", { id: "v-overlay" });
  const wire = h("button", { type: "button", class: "small ghost", "aria-pressed": "false" }, "Wireframe");

  function fillShapeSelects() {
    replace(shapeSelect, shapes.map((s) => h("option", { value: s.id, selected: s.id === shapeId }, `#${s.index} (shape ${s.id})`)));
    replace(overlaySelect, h("option", { value: "" }, "none"),
      shapes.filter((s) => s.id !== shapeId).map((s) => h("option", { value: s.id, selected: s.id === overlayId }, `#${s.index} (shape ${s.id})`)));
  }

  const controls = h("form", { class: "viewer-controls", onSubmit: (e) => e.preventDefault() },
    h("label", { for: "v-cohort" }, "Cohort"), cohortSelect,
    h("label", { for: "v-shape" }, "Shape"), shapeSelect,
    h("label", { for: "v-overlay" }, "Overlay"), overlaySelect,
    h("div", { class: "buttons" },
      h("button", { type: "button", class: "small ghost", onClick: () => scene.rotate(-15), "aria-label": "Rotate left" }, "⟲"),
      h("button", { type: "button", class: "small ghost", onClick: () => scene.rotate(15), "aria-label": "Rotate right" }, "⟳"),
      h("button", { type: "button", class: "small ghost", onClick: () => scene.zoom(0.8), "aria-label": "Zoom in" }, "+"),
      h("button", { type: "button", class: "small ghost", onClick: () => scene.zoom(1.25), "aria-label": "Zoom out" }, "−"),
      h("button", { type: "button", class: "small ghost", onClick: () => scene.frame() }, "Reset view"),
      wire));

  replace(main,
    h("h1", {}, "Viewer"),
    cohorts.length ? h("div", { class: "viewer" }, h("div", { class: "side" }, controls, status, legend), stage, info)
      : h("p", {}, "No finished cohort yet: ", h("a", { href: "#/new" }, "create one"), "."));
  if (!cohorts.length) return () => {};

  const scene = new ShapeScene(canvas);
  wire.addEventListener("click", () => wire.setAttribute("aria-pressed", String(scene.toggleWireframe())));

  const remember = () => {
    const q = new URLSearchParams({ shape: shapeId });
    if (overlayId) q.set("overlay", overlayId);
    history.replaceState(null, "", `#/viewer?${q}`);
  };

  async function showOverlay() {
    stage.dataset.overlay = "loading";
    legend.hidden = true;
    const bytes = overlayId ? await fetchBytes(`/v1/shapes/${overlayId}/mesh`) : null;
    const range = await scene.setOverlay(bytes);
    if (range) {
      replace(legend,
        h("p", {}, `Distance to shape ${overlayId} (nearest vertex, mm)`),
        h("div", { class: "ramp", id: "ramp" }),
        h("p", { class: "ramp-labels" }, h("span", {}, "0"), h("span", {}, `mean ${num(range.mean, 3)}`), h("span", {}, num(range.max, 3))));
      legend.querySelector("#ramp").style.background = `linear-gradient(to right, ${legendGradient()})`;
      legend.hidden = false;
    }
    stage.dataset.overlay = overlayId ? "ready" : "none";
  }

  async function showShape() {
    stage.dataset.state = "loading";
    status.textContent = `Loading shape ${shapeId}…`;
    shape = shapes.find((s) => s.id === shapeId) ?? (await api(`/v1/shapes/${shapeId}`)).data;
    await scene.setShape(await fetchBytes(`/v1/shapes/${shapeId}/mesh`));
    const openings = openingsOf(shape);
    scene.setMarkers(openings.map((o) => o.centre));
    replace(info, h("h2", {}, "Measurements"), measurementFacts(shape),
      openings.length > 0 && [h("h3", {}, "Openings"), h("ul", {}, openings.map((o) => h("li", {}, o.name)))]);
    status.textContent = "Drag to orbit, wheel to zoom, right-drag or arrow keys (canvas focused) to pan.";
    stage.dataset.state = "ready";
    await showOverlay();
    remember();
  }

  cohortSelect.addEventListener("change", async () => {
    cohortId = Number(cohortSelect.value);
    shapes = await allShapes(cohortId);
    shapeId = shapes[0]?.id ?? null;
    overlayId = null;
    fillShapeSelects();
    if (shapeId) await showShape();
  });
  shapeSelect.addEventListener("change", async () => {
    shapeId = Number(shapeSelect.value);
    if (overlayId === shapeId) overlayId = null;
    fillShapeSelects();
    await showShape();
  });
  overlaySelect.addEventListener("change", async () => {
    overlayId = Number(overlaySelect.value) || null;
    await showOverlay();
    remember();
  });

  fillShapeSelects();
  if (shapeId) await showShape();
  return () => scene.dispose();
}
