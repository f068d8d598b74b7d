// The models: status, training shapes, the reconstruction-CD distribution, training
// progress live; forms to train a new model from meshes or a zip and to fit a patient mesh.

import { api } from "../api.js";
import { badge, facts, h, num, progressBar, replace } from "../dom.js";
import { onJob } from "../events.js";
import { picture } from "./cohort.js";

function uploadForm(after) {
  const status = h("p", { role: "status", class: "muted" });
  const form = h("form", { class: "stacked", noValidate: true },
    h("h2", {}, "Train a new model"),
    h("p", { class: "muted" }, "Meshes (STL, OBJ, PLY, GLB, glTF; at least two) or one zip archive of them."),
    h("label", { for: "up-id" }, "Model id"), h("input", { id: "up-id", name: "id", required: true, autocomplete: "off" }),
    h("label", { for: "up-epochs" }, "Epochs"), h("input", { id: "up-epochs", name: "epochs", type: "number", value: "240" }),
    h("label", { for: "up-files" }, "Files"), h("input", { id: "up-files", name: "files", type: "file", multiple: true, accept: ".stl,.obj,.ply,.glb,.gltf,.zip" }),
    h("button", { type: "submit" }, "Upload and train"), status);
  form.addEventListener("submit", async (event) => {
    event.preventDefault();
    status.textContent = "Uploading…";
    try {
      const body = new FormData();
      body.set("id", form.elements.id.value.trim());
      if (form.elements.epochs.value) body.set("epochs", form.elements.epochs.value);
      for (const file of form.elements.files.files) body.append("files", file, file.name);
      await api("/v1/models", { method: "POST", body });
      status.textContent = "Training queued.";
      after();
    } catch (error) {
      status.textContent = `${error.field ? `${error.field}: ` : ""}${error.message}`;
    }
  });
  return form;
}

function fitForm(models, after) {
  const status = h("p", { role: "status", class: "muted" });
  const form = h("form", { class: "stacked", noValidate: true },
    h("h2", {}, "Fit a patient mesh"),
    h("p", { class: "muted" }, "Adds the mesh to a ready model as an anchor (latent optimisation, network frozen)."),
    h("label", { for: "fit-model" }, "Model"),
    h("select", { id: "fit-model", name: "model" }, models.filter((m) => m.status === "ready").map((m) => h("option", { value: m.id }, m.id))),
    h("label", { for: "fit-name" }, "Name"), h("input", { id: "fit-name", name: "name", autocomplete: "off" }),
    h("label", { for: "fit-iterations" }, "Iterations"), h("input", { id: "fit-iterations", name: "iterations", type: "number", value: "800" }),
    h("label", { for: "fit-seed" }, "Seed"), h("input", { id: "fit-seed", name: "seed", type: "number", value: "0" }),
    h("label", { for: "fit-file" }, "Mesh"), h("input", { id: "fit-file", name: "file", type: "file", accept: ".stl,.obj,.ply,.glb,.gltf" }),
    h("button", { type: "submit" }, "Fit"), status);
  form.addEventListener("submit", async (event) => {
    event.preventDefault();
    status.textContent = "Uploading…";
    try {
      const body = new FormData();
      for (const name of ["name", "iterations", "seed"]) {
        if (form.elements[name].value) body.set(name, form.elements[name].value);
      }
      const file = form.elements.file.files[0];
      if (file) body.set("file", file, file.name);
      await api(`/v1/models/${encodeURIComponent(form.elements.model.value)}/fit`, { method: "POST", body });
      status.textContent = "Fit queued.";
      after();
    } catch (error) {
      status.textContent = `${error.field ? `${error.field}: ` : ""}${error.message}`;
    }
  });
  return form;
}

async function modelCard(model, refresh) {
  const [shapes, anchors] = await Promise.all([
    api(`/v1/models/${encodeURIComponent(model.id)}/shapes`).then((r) => r.data, () => []),
    api(`/v1/models/${encodeURIComponent(model.id)}/anchors`).then((r) => r.data, () => []),
  ]);
  const live = h("div", { class: "training", dataset: { model: model.id } });
  const cd = model.reconstruction_cd;
  const card = h("article", { class: "card" },
    h("h2", {}, `${model.id} `, badge(model.status)),
    live,
    facts([
      ["Training shapes", model.training_shapes],
      ["Latent dimension", model.latent_dim ?? "–"],
      ["Architecture", Object.entries(model.architecture ?? {}).map(([k, v]) => `${k} ${typeof v === "object" ? JSON.stringify(v) : v}`).join(", ") || "–"],
      cd && ["Reconstruction CD", `median ${num(cd.median)}, mean ${num(cd.mean)}, max ${num(cd.max)} (${cd.count} shapes, unit ball)`],
      ["Registered", model.created_at],
    ]),
    model.status === "ready" && h("figure", {},
      picture(`/v1/models/${encodeURIComponent(model.id)}/plots/reconstruction-cd`, `Reconstruction CD of ${model.id}`),
      h("figcaption", {}, "Reconstruction Chamfer distance per training shape")),
    shapes.length > 0 && h("details", {}, h("summary", {}, `Training shapes (${shapes.length})`),
      h("table", { class: "list compact" },
        h("thead", {}, h("tr", {}, h("th", { scope: "col" }, "Index"), h("th", { scope: "col" }, "Name"), h("th", { scope: "col" }, "Reconstruction CD"))),
        h("tbody", {}, shapes.map((s) => h("tr", {}, h("td", { class: "num" }, s.index), h("td", {}, s.name), h("td", { class: "num" }, num(s.reconstruction_cd))))))),
    anchors.length > 0 && h("details", {}, h("summary", {}, `Anchors (${anchors.length})`),
      h("ul", {}, anchors.map((a) => h("li", {}, `#${a.id} ${a.name} `, badge(a.status), a.chamfer != null ? ` CD ${num(a.chamfer)}` : "")))),
    h("div", { class: "actions" },
      h("a", { class: "button ghost", href: `#/new?model=${encodeURIComponent(model.id)}` }, "New cohort"),
      h("a", { class: "button ghost", href: `/v1/models/${encodeURIComponent(model.id)}/report`, target: "_blank", rel: "noopener" }, "Report"),
      h("button", { type: "button", class: "danger small", onClick: async () => {
        try { await api(`/v1/models/${encodeURIComponent(model.id)}`, { method: "DELETE" }); refresh(); }
        catch (error) { replace(live, h("p", { class: "error", role: "alert" }, error.message)); }
      } }, "Delete")));
  return { card, live };
}

export async function modelsPage(main) {
  const list = h("div", { class: "cards" });
  const lives = new Map();
  async function load() {
    const models = (await api("/v1/models")).data;
    lives.clear();
    const cards = await Promise.all(models.map((m) => modelCard(m, load)));
    cards.forEach(({ live }, i) => lives.set(models[i].id, live));
    replace(list, cards.map((c) => c.card));
    replace(forms, uploadForm(load), fitForm(models, load));
  }
  const forms = h("div", { class: "columns" });
  replace(main, h("h1", {}, "Models"), list, forms);
  await load();
  const show = (job) => {
    if (job.subject?.startsWith("/v1/anchors/") && !["queued", "running"].includes(job.status)) {
      load();
      return;
    }
    const id = job.subject?.match(/^\/v1\/models\/(.+)$/)?.[1];
    const live = id && lives.get(decodeURIComponent(id));
    if (!live) return;
    if (job.status === "running" || job.status === "queued") {
      replace(live, h("p", {}, `Training ${job.status}, epochs done:`), progressBar(job.progress.done, job.progress.total, `training ${id}`));
    } else load();
  };
  return onJob(show);
}
