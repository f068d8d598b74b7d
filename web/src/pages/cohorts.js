// The cohorts list: filters by model and status, status and progress updated live from the
// event stream, cancel and delete.

import { api } from "../api.js";
import { badge, h, progressBar, replace } from "../dom.js";
import { onJob } from "../events.js";

const STATES = ["queued", "running", "succeeded", "failed", "cancelled"];

/** Cancel and delete buttons of a cohort; `after` runs once the call succeeded. */
export function cohortActions(cohort, after, report) {
  const busy = cohort.status === "queued" || cohort.status === "running";
  const act = (method, path, what) => async () => {
    try {
      await api(path, { method });
      after();
    } catch (error) {
      report(`${what} cohort ${cohort.id}: ${error.message}`);
    }
  };
  return [
    busy &&
      h("button", { type: "button", class: "small", onClick: act("POST", `/v1/cohorts/${cohort.id}/cancel`, "Cancel") },
        "Cancel"),
    !busy &&
      h("button", { type: "button", class: "small danger", onClick: act("DELETE", `/v1/cohorts/${cohort.id}`, "Delete") },
        "Delete"),
  ];
}

export async function cohortsPage(main, params) {
  const models = (await api("/v1/models")).data;
  const filter = { model_id: params.get("model_id") ?? "", status: params.get("status") ?? "" };
  const message = h("p", { class: "error", role: "alert" });
  const body = h("tbody");
  const more = h("button", { type: "button", class: "ghost", hidden: true }, "Show more");
  const rows = new Map();
  let nextOffset = 0;

  const select = (name, label, options) =>
    h("label", {}, label,
      h("select", {
        name,
        onChange: (e) => {
          filter[name] = e.target.value;
          const q = new URLSearchParams(Object.entries(filter).filter(([, v]) => v));
          history.replaceState(null, "", `#/cohorts${q.size ? `?${q}` : ""}`);
          load(true);
        },
      }, h("option", { value: "" }, "all"), options.map((o) => h("option", { value: o, selected: filter[name] === o }, o))));

  function row(c) {
    const tr = h("tr", { dataset: { cohort: c.id } },
      h("td", {}, h("a", { href: `#/cohorts/${c.id}` }, `#${c.id}`)),
      h("td", {}, c.model_id),
      h("td", { class: "status" }, badge(c.status)),
      h("td", { class: "progress-cell" }, progressBar(c.progress.done, c.progress.total, `cohort ${c.id} progress`)),
      h("td", { class: "num" }, c.count),
      h("td", { class: "num wide-only" }, `${c.resolution}³`),
      h("td", { class: "num wide-only" }, c.arity),
      h("td", { class: "muted wide-only" }, c.created_at.replace("T", " ").slice(0, 19)),
      h("td", { class: "row-actions" }, cohortActions(c, () => load(true), (m) => (message.textContent = m))));
    rows.set(c.id, { tr, cohort: c });
    return tr;
  }

  async function load(reset) {
    if (reset) {
      nextOffset = 0;
      rows.clear();
      body.replaceChildren();
    }
    const q = new URLSearchParams({ limit: "50", offset: String(nextOffset) });
    for (const [k, v] of Object.entries(filter)) if (v) q.set(k, v);
    const page = (await api(`/v1/cohorts?${q}`)).data;
    for (const c of page.items) body.append(row(c));
    nextOffset = page.next_offset ?? 0;
    more.hidden = page.next_offset == null;
    if (!rows.size) body.append(h("tr", {}, h("td", { colspan: 9, class: "muted" }, "No cohorts yet. ", h("a", { href: "#/new" }, "Create one."))));
  }
  more.addEventListener("click", () => load(false));

  let reloading = null;
  const stop = onJob((job) => {
    const id = Number(job.subject?.match(/^\/v1\/cohorts\/(\d+)$/)?.[1]);
    if (!id) return;
    const entry = rows.get(id);
    if (!entry) {
      // A cohort created elsewhere: show it (once per burst of events).
      reloading ??= setTimeout(() => ((reloading = null), load(true)), 300);
      return;
    }
    const c = { ...entry.cohort, status: job.status, progress: job.progress };
    if (filter.status && filter.status !== c.status) return;
    const fresh = row(c);
    entry.tr.replaceWith(fresh);
  });

  replace(main,
    h("h1", {}, "Cohorts"),
    h("form", { class: "filters", onSubmit: (e) => e.preventDefault() },
      select("model_id", "Model ", models.map((m) => m.id)),
      select("status", "Status ", STATES),
      h("a", { class: "button", href: "#/new" }, "New cohort")),
    message,
    h("div", { class: "table-wrap" },
      h("table", { class: "list" },
        h("caption", { class: "sr-only" }, "Cohorts, newest first"),
        h("thead", {}, h("tr", {}, ["Cohort", "Model", "Status", "Progress", "Shapes", "Grid", "Arity", "Created (UTC)", "Actions"].map((t, i) =>
          h("th", { scope: "col", class: i >= 5 && i <= 7 ? "wide-only" : undefined }, t)))),
        body)),
    more);
  await load(true);
  return stop;
}
