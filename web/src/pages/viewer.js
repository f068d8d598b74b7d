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

/** Face ids of caps lie between the wall (0) and the flow-extension walls (100 and up). */
const EXTENSION_BASE = 100;

/**
 * The labelled openings of a shape's simulation mesh ({name, centroid_mm, equivalent_diameter_mm}),
 * from the shape's face table once the service has made it, else null.
 */
function openingsOf(faces) {
  return Array.isArray(faces) ? faces.filter((f) => f.id > 0 && f.id < EXTENSION_BASE && Array.isArray(f.centroid_mm)) : null;
}

function openingList(openings) {
  return h("ul", { id: "openings" }, openings.map((o) =>
    h("li", { dataset: { face: o.id } }, `${o.name}: ⌀ ${num(o.equivalent_diameter_mm, 3)} mm`)));
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

  /** Markers and a list for known openings, else a button that asks the service for them. */
  function showOpenings(panel, openings) {
    if (openings) {
      scene.setMarkers(openings.map((o) => o.centroid_mm));
      stage.dataset.markers = String(openings.length);
      replace(panel, openings.length ? openingList(openings) : h("p", { class: "muted" }, "No openings found."));
      return;
    }
    scene.setMarkers([]);
    stage.dataset.markers = "0";
    if (shape.faces_error) {
      replace(panel, h("p", { class: "muted", id: "openings-error" }, shape.faces_error));
      return;
    }
    const find = h("button", { type: "button", class: "small", id: "find-openings" }, "Find openings");
    const note = h("p", { class: "muted" }, "Cuts the inlet and outlets and labels them (a few seconds).");
    find.addEventListener("click", async () => {
      const forShape = shapeId;
      find.disabled = true;
      find.textContent = "Finding openings…";
      try {
        const table = (await api(`/v1/shapes/${forShape}/faces`)).data;
        if (forShape === shapeId) showOpenings(panel, openingsOf(table.openings));
      } catch (error) {
        if (forShape !== shapeId) return;
        replace(panel, h("p", { class: "muted", id: "openings-error" }, error.message));
      }
    });
    replace(panel, find, note);
  }

  async function showShape() {
    stage.dataset.state = "loading";
    status.textContent = `Loading shape ${shapeId}…`;
    shape = shapes.find((s) => s.id === shapeId) ?? (await api(`/v1/shapes/${shapeId}`)).data;
    await scene.setShape(await fetchBytes(`/v1/shapes/${shapeId}/mesh`));
    const openingsPanel = h("div", { class: "openings" });
    replace(info, h("h2", {}, "Measurements"), measurementFacts(shape), h("h3", {}, "Openings"), openingsPanel);
    showOpenings(openingsPanel, openingsOf(shape.faces));
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
