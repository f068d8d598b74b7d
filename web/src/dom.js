// Small DOM helpers: elements are built with properties and children, never from HTML
// strings, so server data is always text.

/** Creates an element: h("a", { href: "#/x", class: "btn" }, "text", child). */
export function h(tag, props = {}, ...children) {
  const el = document.createElement(tag);
  for (const [key, value] of Object.entries(props ?? {})) {
    if (value === undefined || value === null || value === false) continue;
    if (key === "class") el.className = value;
    else if (key === "dataset") Object.assign(el.dataset, value);
    else if (key.startsWith("on") && typeof value === "function") {
      el.addEventListener(key.slice(2).toLowerCase(), value);
    } else if (key in el && typeof value !== "string") el[key] = value;
    else el.setAttribute(key, value === true ? "" : String(value));
  }
  append(el, children);
  return el;
}

function append(el, children) {
  for (const child of children.flat(Infinity)) {
    if (child === undefined || child === null || child === false) continue;
    el.append(child instanceof Node ? child : document.createTextNode(String(child)));
  }
}

/** Replaces the children of `el`. */
export function replace(el, ...children) {
  el.replaceChildren();
  append(el, children);
  return el;
}

/** A number with `digits` significant digits, or an en dash. */
export function num(value, digits = 4) {
  if (value === undefined || value === null || Number.isNaN(value)) return "–";
  if (value === 0) return "0";
  const abs = Math.abs(value);
  if (abs >= 1e5 || abs < 1e-3) return value.toExponential(digits - 1);
  return Number(value.toPrecision(digits)).toString();
}

/** A definition list of [term, value] pairs. */
export function facts(pairs) {
  return h(
    "dl",
    { class: "facts" },
    pairs.filter(Boolean).map(([term, value]) => [h("dt", {}, term), h("dd", {}, value)]),
  );
}

/** A progress bar with its percentage as text. */
export function progressBar(done, total, label) {
  const pct = total > 0 ? Math.round((100 * done) / total) : 0;
  return h(
    "div",
    { class: "progress" },
    h("progress", { max: 100, value: pct, "aria-label": label ?? "progress" }),
    h("span", { class: "pct" }, `${pct} %`),
    h("span", { class: "muted" }, ` ${done} / ${total}`),
  );
}

/** A status badge. */
export function badge(status) {
  return h("span", { class: `badge ${status}` }, status);
}
