// The lab page: queue, live readings, scan form, job controls, results.
import { ApiError, followEvents, getBlob, getJSON, getKey, send, setKey } from "./api.js";
import { plotPolar, plotReadings } from "./plots.js";

const $ = (sel) => document.querySelector(sel);
let selected = null;          // id of the job shown in the live/result panels
let selectedEta = null;       // its estimated seconds left (only the job detail has it)
let jobs = [];
let refreshTimer = null;
let readingsTimer = null;

function showError(err) {
  const box = $("#message");
  if (!err) { box.hidden = true; return; }
  let text = err instanceof ApiError ? err.message : String(err);
  if (err instanceof ApiError && (err.status === 401 || err.status === 403)) text += " (enter a valid API key at the top right)";
  box.textContent = text;
  box.hidden = false;
}

// User actions clear the previous message first; background refreshes leave it standing, so
// a refusal stays readable until the user does something else.
async function guarded(fn, userAction = false) {
  try { if (userAction) showError(null); return await fn(); } catch (e) { showError(e); return undefined; }
}

// ------------------------------------------------------------------ key
function initKey() {
  // `gonio serve --sim` prints the address with a one-off key in the #fragment (never sent to
  // the server); take it into sessionStorage and drop it from the address bar.
  const m = location.hash.match(/key=([^&]+)/);
  if (m) { setKey(decodeURIComponent(m[1])); history.replaceState(null, "", location.pathname); }
  const input = $("#key-input");
  input.value = getKey();
  const describe = () => { $("#key-state").textContent = getKey() ? "key set for this tab" : "no key: read only"; };
  describe();
  $("#key-form").addEventListener("submit", (e) => { e.preventDefault(); setKey(input.value.trim()); describe(); showError(null); refreshAll(); });
}

// ------------------------------------------------------------------ rig and maintenance
async function refreshRig() {
  const rig = await getJSON("/rig");
  $("#rig-name").textContent = `rig: ${rig.name ?? "?"}`;
  const stage = (rig.devices ?? []).find((d) => d.name === "stage");
  const bad = (rig.devices ?? []).filter((d) => !d.ok).map((d) => d.name);
  const chip = $("#stage-chip");
  if (!rig.connected) chip.textContent = rig.error ? `rig not connected: ${rig.error}` : "rig connects at the first scan";
  else {
    const pos = stage?.detail?.position_deg;
    chip.textContent = bad.length ? `fault: ${bad.join(", ")}`
      : `stage ${typeof pos === "number" ? pos.toFixed(2) + "°" : "?"}${stage?.detail?.moving ? " moving" : ""}`;
  }
  chip.className = bad.length || rig.error ? "chip fault" : "chip";
  if (rig.queue_held) chip.textContent += ` · queue held: ${rig.queue_held}`;
  const m = await getJSON("/maintenance");
  const banner = $("#maintenance");
  banner.hidden = !m.locked;
  banner.textContent = m.locked ? `Locked for maintenance${m.by ? ` by ${m.by}` : ""}${m.reason ? `: ${m.reason}` : ""}. Changes are refused.` : "";
}

// ------------------------------------------------------------------ queue
const ACTIONS = {
  queued: ["cancel", "up", "down"],
  running: ["pause", "abort"],
  suspended: ["pause", "abort"],
  paused: ["resume", "abort"],
  reconstructing: ["abort"],
  completed: ["remove"], failed: ["remove"], aborted: ["remove"], halted: ["remove"],
};

function eta(s) {
  if (typeof s !== "number" || !Number.isFinite(s)) return "";
  if (s < 90) return `${Math.round(s)} s`;
  return s < 5400 ? `${Math.round(s / 60)} min` : `${(s / 3600).toFixed(1)} h`;
}

async function act(job, action) {
  await guarded(async () => {
    if (action === "remove") await send("DELETE", `/jobs/${job.id}`);
    else if (action === "up" || action === "down") {
      const queued = jobs.filter((j) => j.state === "queued");
      const i = queued.findIndex((j) => j.id === job.id);
      const to = Math.max(0, Math.min(queued.length - 1, i + (action === "up" ? -1 : 1)));
      await send("POST", `/jobs/${job.id}/reorder`, { position: to });
    } else await send("POST", `/jobs/${job.id}/${action}`);
    await refreshJobs();
  }, true);
}

function renderJobs() {
  const body = $("#jobs");
  body.replaceChildren();
  $("#no-jobs").hidden = jobs.length > 0;
  for (const job of jobs) {
    const tr = document.createElement("tr");
    tr.dataset.id = job.id;
    tr.dataset.state = job.state;
    if (job.id === selected) tr.classList.add("selected");
    const done = job.done_angles ?? 0, total = job.total_angles ?? 0;
    const cells = [job.id, job.specimen, job.kind, job.state, null, job.id === selected ? eta(selectedEta) : ""];
    cells.forEach((c, i) => {
      const td = document.createElement("td");
      if (i === 4) {
        const bar = document.createElement("progress");
        bar.max = Math.max(total, 1); bar.value = done;
        td.append(bar, ` ${done}/${total}`);
      } else td.textContent = c ?? "";
      if (i === 3) { td.className = `state-${job.state}`; if (job.reason) td.title = job.reason; }
      tr.append(td);
    });
    const td = document.createElement("td");
    for (const a of ACTIONS[job.state] ?? []) {
      const b = document.createElement("button");
      b.textContent = { up: "▲", down: "▼" }[a] ?? a;
      b.title = a;
      b.dataset.action = a;
      b.addEventListener("click", (e) => { e.stopPropagation(); act(job, a); });
      td.append(b);
    }
    tr.append(td);
    tr.addEventListener("click", () => select(job.id));
    body.append(tr);
  }
}

async function refreshJobs() {
  jobs = await getJSON("/jobs");
  if (selected !== null && jobs.some((j) => j.id === selected)) {
    selectedEta = (await getJSON(`/jobs/${selected}`)).eta_s;
  }
  renderJobs();
  if (selected === null && jobs.length) {
    const active = jobs.find((j) => ["running", "paused", "suspended", "reconstructing"].includes(j.state));
    select((active ?? jobs[jobs.length - 1]).id);
  } else if (selected !== null) showResult(jobs.find((j) => j.id === selected));
}

function scheduleRefresh() {
  clearTimeout(refreshTimer);
  // Events can come in bursts (one per reading); one list fetch per burst is enough.
  refreshTimer = setTimeout(() => guarded(refreshJobs), 150);
}

// ------------------------------------------------------------------ live readings
async function refreshReadings() {
  if (selected === null) return;
  const id = selected;
  const rows = await getJSON(`/jobs/${id}/readings`);
  if (id !== selected) return;
  const series = new Map();
  for (const r of rows) {
    const label = `${r.light}/${r.sensor}`;
    const v = r.values.reduce((a, b) => a + b, 0) / Math.max(r.values.length, 1);
    if (!series.has(label)) series.set(label, []);
    series.get(label).push([((r.specimen_deg % 360) + 360) % 360, v]);
  }
  plotReadings($("#readings-plot"), series);
  $("#live-job").textContent = `job ${id} · ${rows.length} readings`;
}

function scheduleReadings() {
  clearTimeout(readingsTimer);
  readingsTimer = setTimeout(() => guarded(refreshReadings), 150);
}

// ------------------------------------------------------------------ results
let shownResult = null;
async function showResult(job) {
  if (!job) return;
  $("#result-job").textContent = `job ${job.id} (${job.state})`;
  if (job.state !== "completed") {
    $("#preview").hidden = true;
    $("#preview-caption").textContent = job.state === "failed" ? `failed: ${job.reason ?? ""}` : "The result appears when the scan has completed.";
    $("#download").hidden = true;
    $("#metrics tbody").replaceChildren();
    $("#polar-plot").replaceChildren();
    shownResult = null;
    return;
  }
  if (shownResult === job.id) return;
  shownResult = job.id;
  const img = $("#preview");
  const blob = await getBlob(`/jobs/${job.id}/preview.png`);
  img.src = URL.createObjectURL(blob);
  img.hidden = false;
  $("#preview-caption").textContent = `${job.specimen}: reconstructed BRDF, log scale. ` +
    "Columns: phi_h 0, 45, 90, 135 deg; rows: phi_d 90, 0 deg; in each panel theta_h runs down, theta_d right.";
  const metrics = await getJSON(`/jobs/${job.id}/metrics`);
  const tbody = $("#metrics tbody");
  tbody.replaceChildren();
  for (const [k, v] of Object.entries(metrics)) {
    if (v === null || typeof v === "object") continue;
    const tr = document.createElement("tr");
    tr.innerHTML = "<th></th><td></td>";
    tr.children[0].textContent = k;
    tr.children[1].textContent = typeof v === "number" ? String(+v.toPrecision(4)) : String(v);
    tbody.append(tr);
  }
  const link = $("#download");
  link.hidden = false;
  link.onclick = async (e) => {
    e.preventDefault();
    await guarded(async () => {
      const file = await getBlob(`/jobs/${job.id}/result`);
      const a = document.createElement("a");
      a.href = URL.createObjectURL(file); a.download = `gonio-job-${job.id}.h5`; a.click();
    });
  };
  await refreshSlice();
}

async function refreshSlice() {
  if (shownResult === null) return;
  const q = `theta_h=${$("#slice-th").value}&theta_d=${$("#slice-td").value}&phi_d=${$("#slice-pd").value}`;
  const s = await getJSON(`/jobs/${shownResult}/slice?${q}`);
  plotPolar($("#polar-plot"), s.phi_h_deg, s.values);
}

function select(id) {
  selected = id;
  renderJobs();
  guarded(refreshReadings);
  showResult(jobs.find((j) => j.id === id))?.catch(showError);
}

// ------------------------------------------------------------------ scan form
function readPlan() {
  const f = new FormData($("#scan-form"));
  const kind = f.get("kind");
  const plan = {
    kind,
    specimen: f.get("specimen"),
    exposure: { exposure_s: Number(f.get("exposure_s")), averages: Number(f.get("averages")) },
  };
  if (kind === "adaptive") {
    plan.initial_rotations = Number(f.get("initial_rotations"));
    plan.threshold = Number(f.get("threshold"));
  } else plan.rotations = Number(f.get("rotations"));
  if (kind === "calibration") plan.reference_albedo = Number(f.get("reference_albedo"));
  return plan;
}

function initForm() {
  const form = $("#scan-form");
  const kindSel = form.elements.kind;
  const showKind = () => {
    for (const l of form.querySelectorAll("label.kind")) l.hidden = !l.classList.contains(kindSel.value);
  };
  kindSel.addEventListener("change", showKind);
  showKind();
  $("#dry-run").addEventListener("click", () => guarded(async () => {
    const r = await send("POST", "/jobs/dry-run", { plan: readPlan() });
    $("#dry-run-result").textContent = `OK: ${r.readings} readings at ${r.angles_deg.length} stage angles, about ${eta(r.estimated_s)}.`;
  }, true));
  form.addEventListener("submit", (e) => {
    e.preventDefault();
    guarded(async () => {
      const job = await send("POST", "/jobs", { plan: readPlan() });
      $("#dry-run-result").textContent = `Job ${job.id} queued.`;
      selected = job.id;
      await refreshJobs();
      select(job.id);
    }, true);
  });
}

// ------------------------------------------------------------------ start
async function refreshAll() {
  await guarded(async () => { await refreshRig(); await refreshJobs(); });
}

function onEvent(ev) {
  scheduleRefresh();
  if (ev.job_id !== null && ev.job_id === selected) scheduleReadings();
  if (ev.type === "maintenance" || ev.type === "rig") guarded(refreshRig);
}

window.addEventListener("DOMContentLoaded", async () => {
  initKey();
  initForm();
  for (const id of ["#slice-th", "#slice-td", "#slice-pd"]) $(id).addEventListener("change", () => guarded(refreshSlice));
  await refreshAll();
  followEvents(onEvent, (live) => {
    const chip = $("#live-chip");
    chip.textContent = live ? "live" : "reconnecting";
    chip.className = live ? "chip" : "chip off";
    if (live) scheduleRefresh();
  });
  // Stage position changes without events while idle; a slow poll keeps the chip honest.
  setInterval(() => guarded(refreshRig), 5000);
});
