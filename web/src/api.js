// The API client of the page: JSON and problem+json handling, the API key (asked for before
// a write when the service has keys, and for reads when they are protected) sent as a
// bearer token, and object URLs for pictures and downloads when reads need the key.

const KEY_STORAGE = "aortagen.apiKey";

/** What the service says needs a key (GET /v1/access). */
export const access = { writesNeedKey: false, readsNeedKey: false };

/** An error answer of the API: its status and problem document. */
export class ApiProblem extends Error {
  constructor(status, problem) {
    super(problem?.detail ?? `HTTP ${status}`);
    this.status = status;
    this.problem = problem ?? {};
  }
  /** The field the problem names, if any. */
  get field() {
    return this.problem.field;
  }
}

export function currentKey() {
  return sessionStorage.getItem(KEY_STORAGE);
}

export function forgetKey() {
  sessionStorage.removeItem(KEY_STORAGE);
}

/** Asks for a key in the page's dialog; resolves to the key, or null when cancelled. */
export function askKey(reason) {
  const dialog = document.getElementById("key-dialog");
  const form = document.getElementById("key-form");
  const input = document.getElementById("key-input");
  document.getElementById("key-reason").textContent = reason;
  input.value = "";
  return new Promise((resolve) => {
    const done = (key) => {
      form.removeEventListener("submit", submit);
      cancel.removeEventListener("click", close);
      dialog.removeEventListener("cancel", close);
      if (dialog.open) dialog.close();
      if (key) sessionStorage.setItem(KEY_STORAGE, key);
      resolve(key);
    };
    const submit = (event) => {
      event.preventDefault();
      done(input.value.trim() || null);
    };
    const close = (event) => {
      event.preventDefault();
      done(null);
    };
    const cancel = document.getElementById("key-cancel");
    form.addEventListener("submit", submit);
    cancel.addEventListener("click", close);
    dialog.addEventListener("cancel", close);
    dialog.showModal();
    input.focus();
  });
}

/** Reads GET /v1/access once at start. */
export async function loadAccess() {
  const response = await fetch("/v1/access");
  if (response.ok) {
    const info = await response.json();
    access.writesNeedKey = info.writes_need_key;
    access.readsNeedKey = info.reads_need_key;
  }
  return access;
}

const WRITES = new Set(["POST", "PUT", "PATCH", "DELETE"]);

/** Headers with the bearer token when a key is known. */
export function authHeaders(extra = {}) {
  const key = currentKey();
  return key ? { ...extra, authorization: `Bearer ${key}` } : { ...extra };
}

/**
 * Calls the API. `json` is sent as a JSON body, `body` as is (FormData, Blob). Resolves to
 * { status, headers, data } (data parsed as JSON when it is JSON); rejects with ApiProblem.
 */
export async function api(path, { method = "GET", json, body, headers = {} } = {}) {
  const write = WRITES.has(method);
  if ((write ? access.writesNeedKey : access.readsNeedKey) && !currentKey()) {
    const key = await askKey(write ? "Changes need an API key." : "Reads need an API key.");
    if (!key) throw new ApiProblem(401, { detail: "no API key given" });
  }
  for (let attempt = 0; ; attempt++) {
    const init = { method, headers: authHeaders(headers) };
    if (json !== undefined) {
      init.body = JSON.stringify(json);
      init.headers["content-type"] = "application/json";
    } else if (body !== undefined) init.body = body;
    const response = await fetch(path, init);
    if ((response.status === 401 || (await isWrongKey(response))) && attempt === 0) {
      forgetKey();
      const reason =
        response.status === 401 ? "This request needs an API key." : "That key is not valid.";
      const key = await askKey(reason);
      if (key) continue;
    }
    return settle(response);
  }
}

async function isWrongKey(response) {
  if (response.status !== 403 || currentKey() === null) return false;
  const problem = await response.clone().json().catch(() => ({}));
  return problem.type === "/problems/forbidden";
}

async function settle(response) {
  const type = response.headers.get("content-type") ?? "";
  const isJson = type.includes("json");
  const data = response.status === 204 ? null : isJson ? await response.json() : await response.text();
  if (!response.ok) throw new ApiProblem(response.status, isJson ? data : { detail: data });
  return { status: response.status, headers: response.headers, data };
}

const objectUrls = new Map();

/**
 * A URL an <img> or link can use for `path`: the path itself when reads are public, else an
 * object URL of the bytes fetched with the key (kept, so each path is fetched once).
 */
export async function readableUrl(path) {
  if (!access.readsNeedKey) return path;
  if (objectUrls.has(path)) return objectUrls.get(path);
  const response = await fetch(path, { headers: authHeaders() });
  if (!response.ok) throw new ApiProblem(response.status, { detail: await response.text() });
  const url = URL.createObjectURL(await response.blob());
  objectUrls.set(path, url);
  return url;
}

/** The bytes at `path` (with the key when one is known). */
export async function fetchBytes(path) {
  const response = await fetch(path, { headers: authHeaders() });
  if (!response.ok) throw new ApiProblem(response.status, { detail: await response.text() });
  return response.arrayBuffer();
}
