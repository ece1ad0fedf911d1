// The daemon's REST API and its event stream, as used by the lab page.
// The key lives in sessionStorage: it survives reloads of this tab, not closing it.

const KEY_STORAGE = "gonio.apiKey";
export const API = "/api/v1";

export function getKey() { return sessionStorage.getItem(KEY_STORAGE) ?? ""; }
export function setKey(key) {
  if (key) sessionStorage.setItem(KEY_STORAGE, key); else sessionStorage.removeItem(KEY_STORAGE);
}

function headers(extra = {}) {
  const h = { ...extra };
  const key = getKey();
  if (key) h["X-API-Key"] = key;
  return h;
}

// The time of day as HH:MM (24 h, the lab's clock), before a status line that stays until
// the next action: it tells a line from an hour ago from one about now.
export function clock(d = new Date()) {
  return `${String(d.getHours()).padStart(2, "0")}:${String(d.getMinutes()).padStart(2, "0")}`;
}

export class ApiError extends Error {
  constructor(status, detail) {
    super(typeof detail === "string" ? detail : JSON.stringify(detail));
    this.status = status;
  }
}

// Every refusal of the key (401: none given where one is needed, 403: not valid here, e.g. a
// key from before a `gonio serve --sim` restart) is announced to the page, whichever request
// met it, so the page can ask for a key at once instead of showing an empty queue.
export const AUTH_EVENT = "gonio:auth";

// Each GET /rig answer the page reads (app.js, every 5 s and on rig events), announced with
// the answer as its detail, so that other panels (the stage panel) need no poll of their own.
export const RIG_EVENT = "gonio:rig";

async function check(resp) {
  if (resp.ok) return resp;
  let detail = resp.statusText;
  try {
    const body = await resp.json();
    detail = body.detail ?? body;
    // Validation errors arrive as a list of {loc, msg}: show them as one readable line.
    if (Array.isArray(detail)) detail = detail.map((d) => `${(d.loc ?? []).slice(1).join(".")}: ${d.msg}`).join("; ");
  } catch { /* not JSON: keep the status text */ }
  const err = new ApiError(resp.status, detail);
  if (resp.status === 401 || resp.status === 403) window.dispatchEvent(new CustomEvent(AUTH_EVENT, { detail: err }));
  throw err;
}

// A request that got no answer at all (the daemon stopped, restarting, or out of reach):
// fetch rejects with a bare "TypeError: Failed to fetch", which told a lab nothing. Status 0:
// no HTTP status came back.
export class DaemonGone extends ApiError {
  constructor() {
    super(0, `The daemon at ${location.origin} does not answer: it is stopped, restarting or ` +
      "out of reach. What the page shows is what it last reported; the page reconnects by " +
      "itself once the daemon is back (a scan it was running resumes from its checkpoint " +
      "when it starts again on the same data directory).");
  }
}

export async function request(path, init) {
  try { return await fetch(API + path, init); } catch (e) {
    if (e?.name === "AbortError") throw e;
    throw new DaemonGone();
  }
}

export async function getJSON(path) {
  return (await check(await request(path, { headers: headers() }))).json();
}

export async function send(method, path, body = undefined) {
  const init = { method, headers: headers(body === undefined ? {} : { "Content-Type": "application/json" }) };
  if (body !== undefined) init.body = JSON.stringify(body);
  const resp = await check(await request(path, init));
  return resp.status === 204 ? null : resp.json();
}

// A body that is not JSON (a colour CSV stored as a standard), sent as it is.
export async function sendText(method, path, text, type = "text/plain") {
  const resp = await check(await request(path, { method, headers: headers({ "Content-Type": type }), body: text }));
  return resp.status === 204 ? null : resp.json();
}

export async function getBlob(path) {
  return (await check(await request(path, { headers: headers() }))).blob();
}

// A download: its body and the file name the daemon gives it (Content-Disposition), else
// `fallback`.
export async function getFile(path, fallback) {
  const resp = await check(await request(path, { headers: headers() }));
  const name = (resp.headers.get("content-disposition") || "").match(/filename="?([^";]+)"?/)?.[1];
  return { blob: await resp.blob(), name: name ?? fallback };
}

/**
 * Follow the server-sent event stream, resuming after the last seen seq on every reconnect.
 * EventSource cannot send the X-API-Key header, so this reads the stream with fetch.
 * @param {(ev: {seq: number, type: string, job_id: number|null, data: object}) => void} onEvent
 * @param {(live: boolean) => void} onState
 * @returns {() => void} stop function
 */
export function followEvents(onEvent, onState, since = null) {
  let stopped = false, last = since, controller = null;
  async function once() {
    controller = new AbortController();
    const q = last === null ? "" : `?since=${last}`;
    const resp = await check(await fetch(`${API}/events${q}`, { headers: headers(), signal: controller.signal }));
    onState(true);
    const reader = resp.body.pipeThrough(new TextDecoderStream()).getReader();
    let buf = "";
    for (;;) {
      const { value, done } = await reader.read();
      if (done) return;
      buf += value;
      let cut;
      while ((cut = buf.indexOf("\n\n")) >= 0) {
        const block = buf.slice(0, cut); buf = buf.slice(cut + 2);
        let id = null, data = "";
        for (const line of block.split("\n")) {
          if (line.startsWith("id:")) id = Number(line.slice(3).trim());
          else if (line.startsWith("data:")) data += line.slice(5).trim();
        }
        if (!data) continue; // keep-alive comment
        const ev = JSON.parse(data);
        if (id !== null) last = id;
        onEvent(ev);
      }
    }
  }
  (async () => {
    let delay = 500;
    while (!stopped) {
      try { await once(); delay = 500; } catch (e) { if (stopped) return; }
      onState(false);
      await new Promise((r) => setTimeout(r, delay));
      delay = Math.min(delay * 2, 10000);
    }
  })();
  return () => { stopped = true; controller?.abort(); };
}
