// The result panel's export control: GET /api/v1/jobs/{id}/export?format=... as a download.
// It follows the job shown in the result panel ("job N (completed)") and needs no other state.
import { ApiError, getKey, request } from "./api.js";

const $ = (sel) => document.querySelector(sel);

function shownJob() {
  const m = ($("#result-job").textContent || "").match(/^job (\d+) \(completed\)/);
  return m ? Number(m[1]) : null;
}

// The status line and the job it speaks of: shown under that job's result only (it said
// "saved gonio-job-9-....npz" under job 12's), and again when that job is shown again.
let stateJob = null;
let stateText = "";

function say(id, text) {
  stateJob = id;
  stateText = text;
  sync();
}

function sync() {
  $("#export").hidden = shownJob() === null;
  $("#export-state").textContent = shownJob() === stateJob ? stateText : "";
}

// One download: the response saved under the name the daemon gives; returns that name and
// the export's warnings.
async function download(id, query, fallback) {
  const headers = getKey() ? { "X-API-Key": getKey() } : {};
  const resp = await request(`/jobs/${id}/export?${new URLSearchParams(query)}`, { headers });
  if (!resp.ok) {
    let detail = resp.statusText;
    try { detail = (await resp.json()).detail ?? detail; } catch { /* not JSON */ }
    throw new ApiError(resp.status, detail);
  }
  const name = (resp.headers.get("content-disposition") || "").match(/filename="?([^";]+)"?/)?.[1]
    ?? fallback;
  // What `gonio export` would print as warnings (e.g. a MERL file holds only the azimuthal
  // average): the download cannot say it, so the daemon sends them in a header.
  let warnings = [];
  try { warnings = JSON.parse(resp.headers.get("x-gonio-export-warnings") || "[]"); } catch { /* none */ }
  const a = document.createElement("a");
  a.href = URL.createObjectURL(await resp.blob());
  a.download = name;
  a.click();
  return { name, warnings };
}

async function exportShown() {
  const id = shownJob();
  if (id === null) return;
  const choice = $("#export-format").value;
  // The glTF file alone holds no mesh, and a viewer opened on it shows an empty scene; the
  // preview sphere (with_mesh) is what a lab that wants to look at its material asks for.
  // "gltf-mesh" and "glb-mesh" are the format with the sphere.
  const withMesh = choice.endsWith("-mesh");
  const fmt = withMesh ? choice.slice(0, -"-mesh".length) : choice;
  const query = withMesh ? { format: fmt, with_mesh: "true" } : { format: fmt };
  // The seconds so far, counted: a fit-backed format can take a minute on a busy machine
  // (MERL with its sidecar: 61 s measured beside a reconstruction), and a bare "exporting…"
  // read as stuck.
  const started = performance.now();
  const tick = () => say(id, `exporting… ${Math.round((performance.now() - started) / 1000)} s so far`);
  tick();
  const timer = setInterval(tick, 1000);
  try {
    const { name, warnings } = await download(id, query, `gonio-job-${id}-${choice}`);
    const saved = [name];
    // MERL's layout has no room for the provenance: it comes as a JSON sidecar, saved beside
    // it as `gonio export` writes it.
    if (fmt === "merl") {
      saved.push((await download(id, { format: fmt, part: "sidecar" }, `${name}.json`)).name);
    }
    say(id, [`saved ${saved.join(" and ")}`, ...warnings.map((w) => `warning: ${w}`)].join("\n"));
  } catch (e) {
    say(id, `export failed: ${e.message}`);
  } finally { clearInterval(timer); }
}

window.addEventListener("DOMContentLoaded", () => {
  $("#export-button").addEventListener("click", exportShown);
  new MutationObserver(sync).observe($("#result-job"), { childList: true, characterData: true, subtree: true });
  sync();
});
