// A cohort's validations against real patients: the list with live progress, verdicts and
// report links, and a form that starts one against a reference of the cohort's model (its
// training or held-out shapes, or an uploaded population).

import { api, ApiProblem } from "../api.js";
import { badge, h, num, progressBar, replace } from "../dom.js";
import { onJob } from "../events.js";

/** The reference's name as the list shows it. */
function referenceName(reference, references) {
  const known = references.find((r) => r.id === reference);
  if (known) return `${known.name} (${known.shapes} ${known.has_surfaces ? "shapes" : "rows"})`;
  return String(reference);
}

/** The checks of a finished validation, one line each. */
function checkList(report) {
  const checks = report?.checks ?? [];
  if (checks.length === 0) return null;
  const outcome = (c) => (c.passed === true ? "pass" : c.passed === false ? "fail" : "inconclusive");
  return h("ul", { class: "checks" }, checks.map((c) =>
    h("li", {}, badge(outcome(c)), ` ${c.criterion}${c.feature ? ` (${c.feature})` : ""}: `,
      `${num(c.value)} ${c.requirement}`, c.note ? h("span", { class: "muted" }, ` ${c.note}`) : null)));
}

function row(v, references, onDelete) {
  const live = ["queued", "running"].includes(v.status);
  return h("tr", { dataset: { validation: String(v.id) } },
    h("th", { scope: "row", class: "num" }, `#${v.id}`),
    h("td", {}, referenceName(v.reference, references)),
    h("td", {}, badge(v.status), v.error ? h("div", { class: "error" }, v.error) : null),
    h("td", {}, live ? progressBar(v.progress.done, v.progress.total, `validation ${v.id} progress`)
      : v.verdict ? badge(v.verdict) : "–"),
    h("td", { class: "links" },
      v.status === "succeeded" && h("a", { href: v.links.report_html, target: "_blank", rel: "noopener" }, "report"), " ",
      h("a", { href: v.links.self, target: "_blank", rel: "noopener" }, "JSON"), " ",
      h("button", { type: "button", class: "ghost", onClick: () => onDelete(v) }, "delete")));
}

/**
 * The section of cohort `cohort` (once it has succeeded): returns [element, stop], where
 * stop ends its live updates.
 */
export function validationsSection(cohort) {
  const section = h("section", { id: "validations" }, h("h2", {}, "Validations against real patients"));
  const body = h("div");
  const message = h("p", { class: "error", role: "alert" });
  section.append(body, message);
  let references = [];
  let validations = [];
  let detail = null;

  async function load() {
    [references, validations] = await Promise.all([
      api(`/v1/models/${cohort.model_id}/references`).then((r) => r.data),
      api(`/v1/cohorts/${cohort.id}/validations`).then((r) => r.data),
    ]);
    draw();
  }

  async function remove(v) {
    message.textContent = "";
    try {
      await api(v.links.self, { method: "DELETE" });
      await load();
    } catch (e) {
      message.textContent = e.message;
    }
  }

  async function showChecks(v) {
    if (v.status !== "succeeded") return;
    const full = (await api(v.links.self)).data;
    detail = { id: v.id, checks: checkList(full.report) };
    draw();
  }

  function form() {
    const select = h("select", { id: "validation-reference", name: "reference" },
      references.map((r) => h("option", { value: String(r.id) }, referenceName(r.id, references))));
    const points = h("input", { id: "validation-points", name: "points", type: "number", min: 100, step: 100, placeholder: "10000" });
    const criteria = h("input", { id: "validation-criteria", name: "criteria", placeholder: '{"nna_max": 0.6, "ks_p_min": 0.05}' });
    const submit = async (event) => {
      event.preventDefault();
      message.textContent = "";
      const chosen = references.find((r) => String(r.id) === select.value);
      const json = { reference: chosen ? chosen.id : select.value };
      if (points.value) json.points = Number(points.value);
      if (criteria.value.trim()) {
        try {
          json.criteria = JSON.parse(criteria.value);
        } catch {
          message.textContent = "criteria: not valid JSON";
          criteria.setAttribute("aria-invalid", "true");
          return;
        }
      }
      try {
        await api(`/v1/cohorts/${cohort.id}/validations`, { method: "POST", json });
        await load();
      } catch (e) {
        const field = e instanceof ApiProblem ? e.field : null;
        message.textContent = field ? `${field}: ${e.message}` : e.message;
        const input = { reference: select, points, criteria }[field?.split(/[.[]/)[0]];
        input?.setAttribute("aria-invalid", "true");
      }
    };
    return h("form", { class: "inline-form", id: "validation-form", onSubmit: submit },
      h("label", {}, "Reference ", select), " ",
      h("label", {}, "Points per shape ", points), " ",
      h("label", {}, "Criteria (JSON) ", criteria), " ",
      h("button", { type: "submit" }, "Validate"));
  }

  function draw() {
    const table = validations.length === 0
      ? h("p", { class: "muted" }, "No validations yet.")
      : h("div", { class: "table-wrap" }, h("table", { class: "list", id: "validation-list" },
        h("thead", {}, h("tr", {}, ["#", "Reference", "Status", "Verdict", ""].map((t) => h("th", { scope: "col" }, t)))),
        h("tbody", {}, validations.map((v) => {
          const tr = row(v, references, remove);
          tr.addEventListener("click", (event) => {
            if (event.target.closest("a, button")) return;
            showChecks(v).catch((e) => (message.textContent = e.message));
          });
          return tr;
        }))));
    replace(body,
      h("p", { class: "muted" }, "Compares the cohort with real shapes: MMD, COV, 1-NNA and distance to the closest training shape, and every anatomical measurement (KS, Wasserstein, bootstrap bands, TOST). Select a finished row for its checks."),
      form(), table,
      detail && h("div", { id: "validation-checks" }, h("h3", {}, `Checks of validation #${detail.id}`), detail.checks ?? h("p", { class: "muted" }, "No criteria were given.")));
  }

  const stop = onJob((job) => {
    const v = validations.find((x) => job.subject === `/v1/validations/${x.id}`);
    if (!v) return;
    const finished = !["queued", "running"].includes(job.status);
    Object.assign(v, { status: job.status, progress: job.progress, error: job.error });
    if (finished) load().catch((e) => (message.textContent = e.message));
    else draw();
  });
  load().catch((e) => (message.textContent = e.message));
  return [section, stop];
}

