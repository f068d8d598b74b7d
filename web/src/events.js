// Live job changes from GET /v1/events (server-sent events), read with fetch so the API
// key can be sent as a bearer token (EventSource cannot send headers). Reconnects when the
// stream ends (the service closes it every few minutes) or fails.

import { authHeaders } from "./api.js";

const listeners = new Set();
const jobs = new Map();
let connected = false;

/** Calls `fn(job)` for every job change; returns the function that stops it. */
export function onJob(fn) {
  listeners.add(fn);
  return () => listeners.delete(fn);
}

/** The latest state of a job seen on the stream. */
export function lastJob(id) {
  return jobs.get(id);
}

/** Whether the stream is open. */
export function isLive() {
  return connected;
}

function setLive(live) {
  connected = live;
  const el = document.getElementById("live");
  if (el) {
    el.textContent = live ? "live" : "reconnecting";
    el.classList.toggle("on", live);
  }
}

function dispatch(name, data) {
  if (name === "open") {
    setLive(true);
    return;
  }
  if (name !== "job") return;
  const job = JSON.parse(data);
  jobs.set(job.id, job);
  for (const fn of listeners) fn(job);
}

/** Parses SSE text: blocks separated by blank lines, `event:` and `data:` fields. */
function parseBlocks(buffer, emit) {
  let end;
  while ((end = buffer.search(/\r?\n\r?\n/)) >= 0) {
    const block = buffer.slice(0, end);
    buffer = buffer.slice(buffer.slice(end).match(/^\r?\n\r?\n/)[0].length + end);
    let name = "message";
    const data = [];
    for (const line of block.split(/\r?\n/)) {
      if (line.startsWith(":")) continue;
      const colon = line.indexOf(":");
      const field = colon < 0 ? line : line.slice(0, colon);
      const value = colon < 0 ? "" : line.slice(colon + 1).replace(/^ /, "");
      if (field === "event") name = value;
      else if (field === "data") data.push(value);
    }
    if (data.length) emit(name, data.join("\n"));
  }
  return buffer;
}

async function readStream() {
  const response = await fetch("/v1/events", {
    headers: authHeaders({ accept: "text/event-stream" }),
    cache: "no-store",
  });
  if (!response.ok || !response.body) throw new Error(`events: HTTP ${response.status}`);
  const reader = response.body.pipeThrough(new TextDecoderStream()).getReader();
  let buffer = "";
  for (;;) {
    const { value, done } = await reader.read();
    if (done) return;
    buffer = parseBlocks(buffer + value, dispatch);
  }
}

/** Keeps the stream open for the life of the page. */
export async function startEvents() {
  let delay = 500;
  for (;;) {
    try {
      await readStream();
      delay = 500;
    } catch {
      delay = Math.min(delay * 2, 10000);
    }
    setLive(false);
    await new Promise((resolve) => setTimeout(resolve, delay));
  }
}
