// The form that creates a cohort with every field of the request. Nothing is checked here:
// the server's problem+json answer is shown beside the field it names.

import { api } from "../api.js";
import { h, replace } from "../dom.js";

const TARGETS = [
  ["annulus_mm", "Annulus"],
  ["sinus_mm", "Sinus"],
  ["stj_mm", "STJ"],
  ["sinus_height_mm", "Sinus height"],
  ["ascending_mm", "Ascending"],
  ["length_mm", "Length"],
  ["max_diameter_mm", "Max diameter"],
];

/** A labelled control with its hint and its error slot. */
function field(name, label, control, hint) {
  control.id = `f-${name.replaceAll(".", "-")}`;
  control.name = name;
  const error = h("p", { class: "field-error", id: `${control.id}-error`, "aria-live": "polite" });
  control.setAttribute("aria-describedby", `${control.id}-error${hint ? ` ${control.id}-hint` : ""}`);
  return h("div", { class: "field", dataset: { field: name } },
    h("label", { for: control.id }, label), control,
    hint && h("p", { class: "hint", id: `${control.id}-hint` }, hint), error);
}

const input = (props) => h("input", { autocomplete: "off", ...props });

/** The request body from the form's filled-in controls (empty ones are left out). */
function requestFrom(form) {
  const v = (name) => form.elements[name]?.value.trim() ?? "";
  const number = (name) => (v(name) === "" ? undefined : Number(v(name)));
  const body = { model_id: v("model_id"), count: number("count"), arity: number("arity") };
  const optional = {
    weighting: v("weighting") || undefined,
    seed: number("seed"),
    resolution: number("resolution"),
    latent_noise: number("latent_noise"),
    selection: v("selection") || undefined,
    min_novelty: number("min_novelty"),
    max_candidates: number("max_candidates"),
  };
  if (v("weights")) optional.weights = v("weights").split(/[\s,]+/).filter(Boolean).map(Number);
  const targets = {};
  for (const [name] of TARGETS) {
    const range = { min: number(`targets.${name}.min`), max: number(`targets.${name}.max`) };
    if (range.min !== undefined || range.max !== undefined) targets[name] = range;
  }
  if (Object.keys(targets).length) optional.targets = targets;
  const anchors = [...form.querySelectorAll("input[name=anchors]:checked")].map((c) => Number(c.value));
  if (anchors.length) optional.anchors = anchors;
  for (const [k, x] of Object.entries(optional)) if (x !== undefined) body[k] = x;
  return body;
}

/** The form's slot for a problem's field: the field itself or its nearest named parent. */
function slotFor(form, name) {
  for (let n = name; n; n = n.includes(".") ? n.slice(0, n.lastIndexOf(".")) : "") {
    const slot = form.querySelector(`[data-field="${CSS.escape(n)}"]`);
    if (slot) return slot;
  }
  return null;
}

function clearErrors(form) {
  for (const el of form.querySelectorAll(".field-error")) el.textContent = "";
  for (const el of form.querySelectorAll("[aria-invalid]")) el.removeAttribute("aria-invalid");
  form.querySelector("#form-error").textContent = "";
}

function showProblem(form, error) {
  const slot = error.field ? slotFor(form, error.field) : null;
  const text = `${error.message}${error.problem.rule ? ` (${error.problem.rule})` : ""}`;
  if (!slot) {
    form.querySelector("#form-error").textContent = error.field ? `${error.field}: ${text}` : text;
    return;
  }
  slot.querySelector(".field-error").textContent = text;
  const control = slot.querySelector("input, select");
  control?.setAttribute("aria-invalid", "true");
  control?.focus();
}

async function anchorChoices(box, modelId) {
  const anchors = modelId ? (await api(`/v1/models/${encodeURIComponent(modelId)}/anchors`)).data : [];
  const ready = anchors.filter((a) => a.status === "ready");
  replace(box, ready.length
    ? ready.map((a) => h("label", { class: "check" }, h("input", { type: "checkbox", name: "anchors", value: a.id }), ` #${a.id} ${a.name}`))
    : h("span", { class: "muted" }, "No fitted anchors for this model."));
}

export async function createPage(main, params) {
  const models = ((await api("/v1/models")).data).filter((m) => m.status === "ready");
  const model = h("select", {}, models.map((m) =>
    h("option", { value: m.id, selected: m.id === (params.get("model") ?? "default") }, `${m.id} (${m.training_shapes} training shapes)`)));
  const anchorsBox = h("div", { class: "checks", role: "group", "aria-label": "Anchors" });
  model.addEventListener("change", () => anchorChoices(anchorsBox, model.value));
  const targetRows = TARGETS.map(([name, label]) =>
    h("div", { class: "target", dataset: { field: `targets.${name}` } },
      field(`targets.${name}.min`, `${label} min`, input({ type: "number", step: "any", inputMode: "decimal" })),
      field(`targets.${name}.max`, `${label} max`, input({ type: "number", step: "any", inputMode: "decimal" })),
      h("p", { class: "field-error", "aria-live": "polite" })));
  const submit = h("button", { type: "submit" }, "Create cohort");
  const form = h("form", { class: "create", noValidate: true },
    h("fieldset", {}, h("legend", {}, "Cohort"),
      field("model_id", "Model", model),
      field("count", "Shapes", input({ type: "number", value: "10", inputMode: "numeric" }), "1 to the service's maximum"),
      field("arity", "Arity", input({ type: "number", value: "4", inputMode: "numeric" }), "training shapes mixed per shape, ≥ 2"),
      field("resolution", "Resolution", input({ type: "number", value: "128", inputMode: "numeric" }), "marching-cubes grid per axis, 32–1024"),
      field("seed", "Seed", input({ type: "number", inputMode: "numeric" }), "empty: drawn and recorded")),
    h("fieldset", {}, h("legend", {}, "Mixture"),
      field("weighting", "Weighting", h("select", {}, h("option", { value: "" }, "default (dirichlet)"), h("option", { value: "dirichlet" }, "dirichlet"), h("option", { value: "equal" }, "equal"))),
      field("weights", "Weights", input({ type: "text", placeholder: "e.g. 0.4, 0.3, 0.2, 0.1" }), "explicit weights, one per mixed shape, summing to 1"),
      field("selection", "Selection", h("select", {}, h("option", { value: "" }, "default (uniform)"), h("option", { value: "uniform" }, "uniform"), h("option", { value: "spread" }, "spread"))),
      field("latent_noise", "Latent noise", input({ type: "number", step: "any" }), "in training standard deviations, ≥ 0"),
      field("min_novelty", "Minimum novelty", input({ type: "number", step: "any" }), "Chamfer distance to the nearest training shape (unit ball)"),
      h("div", { class: "field", dataset: { field: "anchors" } }, h("span", { class: "label" }, "Anchors"), anchorsBox, h("p", { class: "field-error", "aria-live": "polite" }))),
    h("fieldset", { class: "targets", dataset: { field: "targets" } }, h("legend", {}, "Anatomical targets (mm)"), targetRows,
      h("p", { class: "field-error", "aria-live": "polite" }),
      field("max_candidates", "Max candidates", input({ type: "number", inputMode: "numeric" }), "1–100 per shape, default 20")),
    h("p", { id: "form-error", class: "error", role: "alert" }),
    h("div", { class: "actions" }, submit));

  form.addEventListener("submit", async (event) => {
    event.preventDefault();
    clearErrors(form);
    submit.disabled = true;
    try {
      const { data } = await api("/v1/cohorts", { method: "POST", json: requestFrom(form) });
      location.hash = `#/cohorts/${data.id}`;
    } catch (error) {
      if (error.problem) showProblem(form, error);
      else form.querySelector("#form-error").textContent = error.message;
    } finally {
      submit.disabled = false;
    }
  });

  replace(main, h("h1", {}, "New cohort"), models.length ? form : h("p", {}, "No ready model: train one on the Models page."));
  await anchorChoices(anchorsBox, model.value);
}
