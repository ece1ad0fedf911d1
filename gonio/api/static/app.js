// The lab page: queue, live readings, scan form, job controls, results.
import { AUTH_EVENT, ApiError, RIG_EVENT, followEvents, getBlob, getFile, getJSON, getKey, send, setKey } from "./api.js";
import { clearPlot, plotPolar, plotRotation } from "./plots.js";

const $ = (sel) => document.querySelector(sel);
let selected = null;          // id of the job shown in the live/result panels
let jobs = [];
let refreshTimer = null;
let readingsTimer = null;

let messageFrom = null;        // "user" (a refused action) or "background" (a failed refresh)

function showError(err, from = "user") {
  const box = $("#message");
  if (!err) { box.hidden = true; box.textContent = ""; messageFrom = null; return; }
  // A refused key is said once, by the key prompt above (keyRefusedBy, with what to do):
  // this box repeated it under it in other words.
  if (err instanceof ApiError && (err.status === 401 || err.status === 403)) { showError(null); return; }
  // An Error's own words ("Error: " before them read as a crash to a lab).
  const text = err instanceof Error ? err.message : String(err);
  box.textContent = text;
  box.hidden = false;
  messageFrom = from;
}

// User actions clear the previous message first, and their refusal stays readable until the
// user does something else. A failed background refresh shows too, and clears itself as soon
// as a later refresh works again (the message is no longer true).
async function guarded(fn, userAction = false) {
  try {
    if (userAction) showError(null);
    const out = await fn();
    if (!userAction && messageFrom === "background") showError(null);
    return out;
  } catch (e) { showError(e, userAction ? "user" : "background"); return undefined; }
}

// ------------------------------------------------------------------ key
let keyRefused = false;       // the daemon refused this tab's key (or wants one)

// The tab's key was refused: reads with it are refused too (docs/api.md: a wrong key is
// refused even on an open read). Without a key only changes were.
function readsRefused() { return keyRefused && getKey() !== ""; }

function describeKey() {
  $("#key-state").textContent = keyRefused ? (getKey() ? "key refused by this daemon" : "no key: a change needs one")
    : getKey() ? "key set for this tab" : "no key: read only";
  $("#key-state").className = keyRefused ? "refused" : "muted";
}

// The daemon refused the key: say so at once, in a prompt that stays until a key works, and
// keep the queue from claiming there are no jobs (it could not read them).
function keyRefusedBy(err) {
  keyRefused = true;
  const prompt = $("#key-prompt");
  prompt.textContent = getKey()
    ? `This daemon does not accept the API key of this tab (${err.message}). Open the address the daemon printed at its start (the page takes the key from it) or paste the key at the top right: \`gonio serve --sim\` keeps its key across restarts on one data directory, but another data directory, \`--throwaway\` or a deleted \`sim-session.key\` gives a new one.`
    : `This daemon needs an API key (${err.message}): paste one at the top right, or open the address \`gonio serve\` printed.`;
  prompt.hidden = false;
  $("#no-jobs").hidden = true;
  // What the queue shows was read with a key that no longer works (or from a daemon that has
  // since restarted, perhaps on a throwaway data directory with none of these jobs): it says
  // so, and no countdown goes on claiming time left.
  $("#jobs-stale").hidden = jobs.length === 0 || !getKey();
  describeKey();
  renderJobs();
}

// A read that works says a key works only when there is one: without a key an open read
// works too, and the prompt of a refused change stays until a key is entered.
function keyAccepted() {
  if (!keyRefused || !getKey()) return;
  keyRefused = false;
  $("#key-prompt").hidden = true;
  $("#jobs-stale").hidden = true;
  describeKey();
}

// A new key: from the form, or from a #key= address pasted into this same tab.
function useKey(key) {
  setKey(key);
  $("#key-input").value = key;
  keyRefused = false;
  $("#key-prompt").hidden = true;
  $("#jobs-stale").hidden = true;
  describeKey();
  showError(null);
  refreshAll();
  restartEvents();
}

function keyFromAddress() {
  // `gonio serve --sim` prints the address with a one-off key in the #fragment (never sent to
  // the server); take it into sessionStorage and drop it from the address bar.
  const m = location.hash.match(/key=([^&]+)/);
  if (!m) return null;
  history.replaceState(null, "", location.pathname);
  return decodeURIComponent(m[1]);
}

function initKey() {
  const fromAddress = keyFromAddress();
  if (fromAddress !== null) setKey(fromAddress);
  const input = $("#key-input");
  input.value = getKey();
  describeKey();
  window.addEventListener(AUTH_EVENT, (e) => keyRefusedBy(e.detail));
  // Pasting the new address into this tab changes only the fragment: no reload happens.
  window.addEventListener("hashchange", () => { const key = keyFromAddress(); if (key !== null) useKey(key); });
  $("#key-form").addEventListener("submit", (e) => { e.preventDefault(); useKey(input.value.trim()); });
}

// ------------------------------------------------------------------ rig and maintenance
// A stage angle as the specimen's, 0-360°: plans and plots use it; the stage's own position
// can be several turns away (528.75° is the specimen at 168.75°).
const specimenAngle = (deg) => ((deg % 360) + 360) % 360;

async function refreshRig() {
  const rig = await getJSON("/rig");
  // Announced to the page's other modules (the stage panel): one poll serves them all, as
  // each /rig reads every device of the rig.
  window.dispatchEvent(new CustomEvent(RIG_EVENT, { detail: rig }));
  $("#rig-name").textContent = `rig: ${rig.name ?? "?"}`;
  const stage = (rig.devices ?? []).find((d) => d.name === "stage");
  const bad = (rig.devices ?? []).filter((d) => !d.ok).map((d) => d.name);
  const chip = $("#stage-chip");
  if (!rig.connected) chip.textContent = rig.error ? `rig not connected: ${rig.error}` : "rig connects at the first scan";
  else {
    const pos = stage?.detail?.position_deg;
    // The specimen's angle (0-360°, what plans and plots use); the stage's own position can
    // be several turns away (528.75° is the specimen at 168.75°): it is in the tooltip.
    const specimen = typeof pos === "number" ? specimenAngle(pos) : null;
    chip.title = typeof pos === "number" ? `stage position ${pos.toFixed(2)}° (specimen angle = position mod 360)` : "";
    chip.textContent = bad.length ? `fault: ${bad.join(", ")}`
      : `specimen at ${specimen !== null ? specimen.toFixed(1) + "°" : "?"}${stage?.detail?.moving ? " moving" : ""}`;
  }
  chip.className = bad.length || rig.error ? "chip fault" : "chip";
  if (rig.queue_held) chip.textContent += ` · queue held: ${rig.queue_held}`;
  // A halt or a failed job's stop holds the queue until it is released (not the
  // maintenance lock, which is lifted where it was set).
  $("#release-queue").hidden = !rig.queue_held || rig.queue_held.startsWith("maintenance lock");
  const m = await getJSON("/maintenance");
  const banner = $("#maintenance");
  banner.hidden = !m.locked;
  banner.textContent = m.locked ? `Locked for maintenance${m.by ? ` by ${m.by}` : ""}${m.reason ? `: ${m.reason}` : ""}. Changes are refused.` : "";
}

function showScanAngle(deg, job) {
  const chip = $("#stage-chip");
  if (chip.className !== "chip") return;  // a fault or a lost rig says more than an angle
  const specimen = specimenAngle(deg);
  chip.textContent = `specimen at ${specimen.toFixed(1)}° (job ${job}'s last angle)`;
  chip.title = `stage position ${deg.toFixed(2)}° when job ${job} measured its last angle`;
}

// The calibration the daemon applies to scans (GET /calibration), said under the form: the
// lab learnt which one (its source and exposure) only when a scan was refused for it.
async function refreshCalibration() {
  const c = await getJSON("/calibration");
  const line = $("#calibration-line");
  if (!c.pairs?.length) {
    line.textContent = "No calibration in effect: scans come out in sensor units, not 1/sr. " +
      "Run a calibration job (Kind: calibration) with the white reference on the stage first.";
    return;
  }
  const when = c.created ? `, measured ${c.created.replace("T", " ").replace(/\.\d+/, "").replace("+00:00", " UTC")}` : "";
  const at = c.exposure_s != null ? ` at exposure ${c.exposure_s} s` : "";
  line.textContent = `Calibration in effect: ${c.source}${at}${when}, ${counted(c.pairs.length, "pair")}. ` +
    "A scan reads at its exposure; at another one it is refused (counts are not rescaled).";
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

// A job that holds the rig and has readings or a result coming: the one the lab watches.
const ACTIVE = ["running", "suspended", "reconstructing"];
// A job that holds the rig, measuring or not: the one whose time left the lab plans around.
const HOLDING = [...ACTIVE, "paused"];

const SHOW_REASON = new Set(["suspended", "failed", "aborted", "halted"]);

// A count before its noun: "1 stage angle", "8 stage angles" (gonio.wording.counted).
function counted(n, noun, plural = `${noun}s`) {
  return `${n} ${n === 1 ? noun : plural}`;
}

function eta(s) {
  if (typeof s !== "number" || !Number.isFinite(s)) return "";
  if (s < 90) return `${Math.round(s)} s`;
  return s < 5400 ? `${Math.round(s / 60)} min` : `${(s / 3600).toFixed(1)} h`;
}

// A plan's time and its parts (Check plan): tenths of a second below 10 s, so the parts add
// up to the total; whole seconds rounded a 0.25 s exposure total to "0 s".
function planTime(s) {
  if (typeof s !== "number" || !Number.isFinite(s) || s >= 10) return eta(s);
  return s < 1 ? `${Number(s.toPrecision(2))} s` : `${s.toFixed(1)} s`;
}

// The selected job's detail (ETA from measured angle times, activity while reconstructing).
let selectedDetail = null;
let selectedState = null;     // the selected job's state at the last list refresh

// The detail of the job that holds the rig when another row is selected: its ETA stays in
// its row (it went blank as soon as another job was clicked or queued).
let activeDetail = null;

function etaText(d = selectedDetail, id = selected) {
  if (readsRefused()) return "";
  if (!d || d.id !== id) return "";
  if (d.state === "reconstructing") {
    // Past its estimate the daemon gives no time left (null, not 0 s): it is not done.
    const planned = (d.reconstruction_s ?? 0) + (d.basis_build_s ?? 0);
    // At least 1 s while some is left: 0.3 s left read "0 s left" while the job was not done.
    const left = d.time_left_s != null ? `; ≈ ${eta(Math.max(d.time_left_s, 1))} left (est.)`
      : d.reconstruction_s != null ? `; taking longer than the ≈ ${eta(planned)} estimated` : "";
    return `${d.activity ?? "reconstructing"}${left}`;
  }
  // An adaptive job loads (or builds) its basis before the first reading.
  if (d.state === "queued" && d.activity) return d.activity;
  if (!["running", "paused", "suspended"].includes(d.state)) return "";
  // The whole job's time: measuring, then (when due) the basis build, then reconstruction,
  // each said, so the time is not read as done when measuring ends. Reconstruction's is an
  // estimate from the last scans' measured finishing (its source in the cell's tooltip).
  // A calibration computes its factors when measured, in a moment: no reconstruction follows.
  const after = d.kind === "calibration" ? "computing the calibration" : "reconstruction";
  if (d.time_left_s == null) return eta(d.eta_s) ? `${eta(d.eta_s)} measuring, then ${after}` : "";
  const parts = [`measuring ${eta(d.eta_s)}`];
  if (d.basis_build_s != null) parts.push(`basis build ≈ ${eta(d.basis_build_s)}`);
  parts.push(`reconstruction ≈ ${eta(d.reconstruction_s)}`);
  // A paused or suspended job's time does not run out while it stands still: it is the time
  // from when it runs again (the daemon's countdown is frozen meanwhile).
  let t = d.state === "running" ? `≈ ${eta(d.time_left_s)} left in all (est.): ${parts.join(", ")}`
    : `${d.state}: ≈ ${eta(d.time_left_s)} in all once it runs again (est.): ${parts.join(", ")}`;
  if (d.eta_max_s != null && d.eta_max_s > (d.eta_s ?? 0) + 1) {
    t += `; ≤ ${eta(d.time_left_s - d.eta_s + d.eta_max_s)} if refined`;
  }
  return t;
}

// A queued job's estimated start (the daemon's starts_in_s: the time left of the job holding
// the rig plus the estimated durations of the jobs ahead), or "start unknown" when the daemon
// has none (a held queue, a paused or suspended job holding the rig): never a made-up number.
// "within" when an adaptive job is counted at its bound (it may start sooner). What the
// estimate rests on, or why there is none, is the cell's tooltip.
function startText(job) {
  if (readsRefused() || job.state !== "queued" || job.starts_in_estimate == null) return "";
  if (job.starts_in_s == null) return "start unknown";
  if (job.starts_in_s < 1) return "starts now";
  return `starts ${job.starts_in_bound ? "within" : "in"} about ${eta(job.starts_in_s)}`;
}

function fillStart(td, job) {
  const text = startText(job), title = job.starts_in_estimate ?? "";
  fillCell(td, [text, title], () => { td.textContent = text; td.title = title; });
}

// The ETA cell's tooltip: what the reconstruction estimate rests on.
function etaTitle(d = selectedDetail, id = selected) {
  return d && d.id === id && d.reconstruction_estimate
    ? `reconstruction estimate: ${d.reconstruction_estimate}` : "";
}

// Progress of a job: angles measured of those planned. An adaptive job plans round by round,
// so its bar runs against the most angles the plan can reach (max_angles, fixed): it only
// fills, never resets when a round adds angles; the round is said beside it.
function progressOf(job) {
  const done = job.done_angles ?? 0, total = job.total_angles ?? 0;
  if (job.max_angles == null) return { value: done, max: Math.max(total, 1), text: `${done}/${total}` };
  const max = Math.max(job.max_angles, total, 1);
  if (job.state === "completed") return { value: 1, max: 1, text: `${counted(done, "angle")} (adaptive)` };
  const d = selectedDetail;
  const round = d && d.id === job.id && d.round != null ? ` · round ${d.round + 1}` : "";
  return { value: done, max, text: `${done} of ≤${max} angles${round}` };
}

// What removing a job loses, asked before it is done (DELETE /jobs/{id}): its readings leave
// the job store for good, so nothing can show, export or rebuild its result again; a completed
// job's result file stays in the data directory, out of the page's reach.
function removeQuestion(job) {
  const file = job.state === "completed"
    ? ` Its result file stays in the daemon's data directory (results/job-${job.id}.h5), no longer listed here.`
    : "";
  const calibration = job.kind === "calibration" ? " The calibration in effect does not change." : "";
  return `Remove job ${job.id} (${job.specimen})? Its stored readings are deleted for good: the page, ` +
    `the API and \`gonio jobs rebuild\` can no longer show, export or rebuild its result.${file}${calibration}`;
}

// What aborting a job means, asked before it is done (POST /jobs/{id}/abort): it stops for
// good and writes no result; its readings stay in the job store, but it cannot be resumed.
function abortQuestion(job) {
  // Being finished, every reading is stored: `gonio jobs rebuild` can still finish it later.
  if (job.state === "reconstructing") {
    return `Abort job ${job.id} (${job.specimen})? Its finishing stops and writes no result; ` +
      "every reading stays in the job store, and `gonio jobs rebuild` can finish it later " +
      "(with the daemon stopped; the job's reason gives the command).";
  }
  return `Abort job ${job.id} (${job.specimen})? It stops for good and writes no result: the ` +
    "readings measured so far stay in the job store, but the job cannot be resumed or finished. " +
    "To stop it for a while instead, pause it.";
}

// The daemon's refusal of a move that puts a scan before a queued calibration, asked as a
// question: "not reordered: job 5 would then run before calibration job 4, uncalibrated (why);
// it was queued without asking ..." becomes "Job 5 would then run before ... Move it all the
// same?".
function reorderQuestion(detail) {
  const what = detail.match(/^not reordered: (.*?); it was queued/)?.[1];
  if (!what) return `${detail}. Move it all the same?`;
  return `${what[0].toUpperCase()}${what.slice(1)}: the scan would run before the calibration, ` +
    "uncalibrated, so its values would be sensor units, not 1/sr (it was queued behind the " +
    "calibration to be calibrated by it). Move it all the same? Cancel keeps the order.";
}

async function act(job, action) {
  if (action === "remove" && !window.confirm(removeQuestion(job))) return;
  if (action === "abort" && !window.confirm(abortQuestion(job))) return;
  await guarded(async () => {
    if (action === "remove") await send("DELETE", `/jobs/${job.id}`);
    else if (action === "up" || action === "down") {
      const queued = jobs.filter((j) => j.state === "queued");
      const i = queued.findIndex((j) => j.id === job.id);
      const to = Math.max(0, Math.min(queued.length - 1, i + (action === "up" ? -1 : 1)));
      try { await send("POST", `/jobs/${job.id}/reorder`, { position: to }); } catch (e) {
        // A scan queued behind a calibration (not asked then: it was to be calibrated) moved
        // ahead of it would run uncalibrated: the daemon refuses (409) unless accepted, and
        // the page asks, then sends the acceptance (docs/api.md, the reorder route).
        if (!(e instanceof ApiError && e.status === 409 && e.message.includes("accept_uncalibrated"))) throw e;
        if (!window.confirm(reorderQuestion(e.message))) return;
        await send("POST", `/jobs/${job.id}/reorder?accept_uncalibrated=true`, { position: to });
      }
    } else await send("POST", `/jobs/${job.id}/${action}`);
    await refreshJobs();
  }, true);
}

// A cell is redrawn only when what it shows changes: its signature (the text, tooltip and
// parts it is drawn from) is kept on it. Events redraw the queue several times a second while
// a job runs; a table rebuilt each time replaced the very button under the mouse, and a click
// whose press and release fell on either side of a redraw reached a detached button and was
// lost (no question, no action), for a lab user as for the browser tests beside a busy CPU.
function fillCell(td, parts, draw) {
  const sig = JSON.stringify(parts);
  if (td.dataset.sig === sig) return;
  td.dataset.sig = sig;
  td.replaceChildren();
  draw(td);
}

function fillEta(td, d, id) {
  const text = etaText(d, id), title = etaTitle(d, id);
  fillCell(td, [text, title], () => { td.textContent = text; td.title = title; });
}

function fillProgress(td, job) {
  const p = progressOf(job);
  td.className = "progress";
  fillCell(td, [p.max, p.value, p.text], () => {
    const bar = document.createElement("progress");
    bar.max = p.max; bar.value = p.value;
    const label = document.createElement("span");
    label.className = "progress-text"; label.textContent = ` ${p.text}`;
    td.append(bar, label);
  });
}

function fillRow(tr, job) {
  tr.dataset.id = job.id;
  // Reachable from the keyboard (Tab, then Enter opens it), as a click on the row is.
  tr.tabIndex = 0;
  tr.setAttribute("aria-label", `job ${job.id}, ${job.specimen ?? "unnamed"}, ${job.state}: open`);
  tr.dataset.state = job.state;
  tr.classList.toggle("selected", job.id === selected);
  while (tr.children.length < 7) tr.append(document.createElement("td"));
  const td = [...tr.children];
  for (const [i, text] of [[0, job.id], [1, job.specimen]]) {
    fillCell(td[i], [text], () => { td[i].textContent = text ?? ""; td[i].title = i === 1 ? text ?? "" : ""; });
  }
  td[1].className = "specimen";
  // The priority under the kind (a column of its own pushed the row's buttons out of a narrow
  // window): for queued jobs, whose order it decides, and for any job whose priority is not 0.
  const priority = job.state === "queued" || job.priority !== 0 ? `priority ${job.priority}` : null;
  td[2].className = "kind";
  fillCell(td[2], [job.kind, priority], (c) => {
    c.textContent = job.kind;
    if (priority) {
      const span = document.createElement("span");
      span.className = "priority muted"; span.textContent = priority;
      c.append(span);
    }
  });
  // Why a job stopped or waits, in the row itself (not only in a tooltip); for a queued job
  // why it does not start (the daemon's words, as GET /jobs/{id} and gonio jobs give them):
  // a held queue, or a paused or suspended job holding the rig.
  const why = job.reason && SHOW_REASON.has(job.state) ? job.reason
    : job.state === "queued" && job.waiting ? job.waiting : null;
  // A queued scan the worker will refuse at its start (the calibration it would start under
  // is at another exposure): said in its row while it waits, not only when it fails.
  const refusal = job.state === "queued" ? job.start_refusal ?? null : null;
  fillCell(td[3], [job.state, why, refusal], (c) => {
    c.className = `state-${job.state}`;
    c.textContent = job.state;
    for (const [text, cls] of [[why, "reason"], [refusal, "reason start-refusal"]]) {
      if (!text) continue;
      const span = document.createElement("span");
      span.className = cls; span.textContent = text;
      c.append(span);
    }
  });
  fillProgress(td[4], job);
  td[5].className = "eta";
  // A queued job that is loading its basis before its first reading says so instead.
  if (job.state === "queued" && !(job.id === selected && etaText())) fillStart(td[5], job);
  // A detail polled while the job held the rig is stale once the list says it has ended:
  // finished rows went on reading "reconstructing ... taking longer than estimated".
  else if (job.state !== "queued" && !HOLDING.includes(job.state)) fillEta(td[5], null, job.id);
  else if (job.id === selected) fillEta(td[5]); else fillEta(td[5], activeDetail, job.id);
  fillActions(td[6], ACTIONS[job.state] ?? []);
}

// The row's buttons, each carrying its action; the tbody's one listener (initQueue) finds the
// job by the row's id when clicked, so a row redrawn meanwhile still acts on the job it shows.
// A button that stays (abort, from running to paused) is kept where it is, never taken out
// and put back: a click pressed on it as the state changes still lands.
function fillActions(td, actions) {
  const sig = JSON.stringify(actions);
  if (td.dataset.sig === sig) return;
  td.dataset.sig = sig;
  const have = new Map([...td.querySelectorAll(":scope > button[data-action]")].map((b) => [b.dataset.action, b]));
  // The buttons that go are taken out first: the others then stand in order, none moved (a
  // button taken out and put back, even at once, loses the click pressed on it).
  for (const [a, b] of have) if (!actions.includes(a)) { b.remove(); have.delete(a); }
  let at = td.firstElementChild;
  for (const a of actions) {
    let b = have.get(a);
    have.delete(a);
    if (!b) {
      b = document.createElement("button");
      b.type = "button";
      b.textContent = { up: "▲", down: "▼" }[a] ?? a;
      b.title = a;
      b.dataset.action = a;
    }
    if (b !== at) td.insertBefore(b, at);
    else at = at.nextElementSibling;
  }
}

// The queue's rows, kept and patched in place (fillCell): a row is added for a new job,
// dropped for a job gone, moved when the order changes, and otherwise left as it is.
function renderJobs() {
  const body = $("#jobs");
  // "No jobs yet" only when the list was read and is empty, never when it could not be read.
  $("#no-jobs").hidden = jobs.length > 0 || readsRefused();
  const rows = new Map([...body.querySelectorAll(":scope > tr[data-id]")].map((tr) => [tr.dataset.id, tr]));
  // The rows of jobs gone are taken out first, so the rows after them are not moved (a row
  // taken out and put back loses a click pressed on it); only a job that changed places is.
  const ids = new Set(jobs.map((j) => `${j.id}`));
  for (const [id, tr] of rows) if (!ids.has(id)) { tr.remove(); rows.delete(id); }
  let at = body.firstElementChild;
  for (const job of jobs) {
    let tr = rows.get(`${job.id}`);
    if (!tr) tr = document.createElement("tr");
    fillRow(tr, job);
    if (tr !== at) body.insertBefore(tr, at);
    else at = at.nextElementSibling;
  }
}

// The queue's clicks, by delegation: a row selects its job, a button acts on it. The job is
// the one the row shows now (its state, its name), found by the id the row carries.
function initQueue() {
  $("#jobs").addEventListener("click", (e) => {
    const tr = e.target.closest("tr[data-id]");
    if (!tr) return;
    const job = jobs.find((j) => `${j.id}` === tr.dataset.id);
    if (!job) return;
    const button = e.target.closest("button[data-action]");
    if (button) act(job, button.dataset.action);
    else select(job.id);
  });
  $("#jobs").addEventListener("keydown", (e) => {
    if ((e.key !== "Enter" && e.key !== " ") || !e.target.matches("tr[data-id]")) return;
    const job = jobs.find((j) => `${j.id}` === e.target.dataset.id);
    if (!job) return;
    e.preventDefault();
    select(job.id);
  });
}

// Refreshes overlap (every job event asks for one): an older answer arriving after a newer
// one drew the queue as it was before (an adaptive job's bar went back from 3 to 2 angles).
// Only the latest refresh asked for draws; a caller of an older one waits for the latest,
// so what it reads of `jobs` afterwards is never older than what it asked for.
let jobsAsked = 0;
let latestLoad = null;

async function refreshJobs() {
  let load = loadJobs(++jobsAsked);
  latestLoad = load;
  await load;
  while (latestLoad !== load) { load = latestLoad; await load; }
}

async function loadJobs(asked) {
  const listed = await getJSON("/jobs");
  if (asked !== jobsAsked) return;
  const calibrations = (list) => list.filter((j) => j.kind === "calibration" && j.state === "completed").map((j) => j.id).join(",");
  const recalibrated = calibrations(listed) !== calibrations(jobs);
  jobs = listed;
  keyAccepted();
  if (recalibrated) guarded(refreshCalibration);
  if (selected !== null && jobs.some((j) => j.id === selected)) {
    const id = selected;
    const detail = await getJSON(`/jobs/${id}`);
    if (asked !== jobsAsked) return;
    if (selected === id) selectedDetail = detail;  // not another row's, clicked meanwhile
  }
  // A job removed (from this page, another tab or `gonio jobs remove`) leaves the panels:
  // they went on showing its readings and result and offering its exports, and every
  // control then answered "no job with id N".
  if (selected !== null && !jobs.some((j) => j.id === selected)) forgetSelected(selected);
  if (compareWith !== null && !jobs.some((j) => j.id === compareWith)) {
    $("#compare").value = "";
    await setCompare(null);
  }
  clearStaleNotes();
  // The selected job changed state (e.g. completed): its rotation plot changes kind.
  const now = jobs.find((j) => j.id === selected)?.state;
  if (now !== selectedState) { selectedState = now; scheduleReadings(); }
  renderJobs();
  refreshCompareChoices();
  if (selected === null && jobs.length) {
    const active = jobs.find((j) => ["running", "paused", "suspended", "reconstructing"].includes(j.state));
    select((active ?? jobs[jobs.length - 1]).id);
  } else if (selected !== null) guarded(() => showResult(jobs.find((j) => j.id === selected)));
}

// While the selected job measures or reconstructs, its detail is polled once a second: the
// ETA counts down between checkpoints and a long first basis build shows its progress even
// though no event arrives meanwhile.
async function pollSelected() {
  // A refused key would be refused again every second (a 403 line a second in the daemon's
  // log): the page asks for a key instead, and polls again once one works.
  if (selected === null || readsRefused()) return;
  const j = jobs.find((x) => x.id === selected);
  // A queued job that is loading its basis before the first reading is polled too.
  const starting = j?.state === "queued" && selectedDetail?.id === j.id && selectedDetail.activity;
  if (!j || !(starting || ["running", "suspended", "reconstructing", "paused"].includes(j.state))) return;
  const id = selected;
  const detail = await getJSON(`/jobs/${id}`);
  // Another row clicked meanwhile: this detail is not the selected job's (taken as its, the
  // newly selected row's ETA went blank until the next poll).
  if (selected !== id) return;
  selectedDetail = detail;
  const cell = document.querySelector(`#jobs tr[data-id="${selected}"] td.eta`);
  if (cell) fillEta(cell);
  // An adaptive job's round comes with its detail; its angles from the list as it is now
  // (a refresh during the wait may have drawn more than the row read before it).
  const prog = document.querySelector(`#jobs tr[data-id="${selected}"] td.progress`);
  const row = jobs.find((x) => x.id === selected) ?? j;
  if (prog) fillProgress(prog, row);
  if (["reconstructing", "queued"].includes(selectedDetail.state)) await showResult(jobs.find((x) => x.id === selected));
}

// The job holding the rig, when it is not the selected one: its detail is polled too (once
// a second, as the selected job's), so its row keeps its ETA.
async function pollActive() {
  if (readsRefused()) return;
  const a = jobs.find((j) => j.id !== selected && HOLDING.includes(j.state));
  if (!a) { activeDetail = null; return; }
  const detail = await getJSON(`/jobs/${a.id}`);
  // Its row clicked meanwhile: it is the selected job now, polled as such.
  if (selected === a.id) return;
  activeDetail = detail;
  const cell = document.querySelector(`#jobs tr[data-id="${a.id}"] td.eta`);
  if (cell) fillEta(cell, activeDetail, a.id);
}

function scheduleRefresh() {
  clearTimeout(refreshTimer);
  // Events can come in bursts (one per reading); one list fetch per burst is enough.
  refreshTimer = setTimeout(() => guarded(refreshJobs), 150);
}

// ------------------------------------------------------------------ live readings
async function readingsSeries(id) {
  const rows = await getJSON(`/jobs/${id}/readings`);
  const series = new Map();
  for (const r of rows) {
    const label = `${r.light}/${r.sensor}`;
    const v = r.values.reduce((a, b) => a + b, 0) / Math.max(r.values.length, 1);
    if (!series.has(label)) series.set(label, []);
    series.get(label).push([specimenAngle(r.specimen_deg), v]);
  }
  return { rows, pairs: [...series].map(([label, pts]) => ({ label, points: pts.sort((a, b) => a[0] - b[0]) })) };
}

// A completed scan shows its calibrated samples with the reconstruction's curve through
// them; a running one its raw readings as they arrive.
async function rotationData(job) {
  if (job.state === "completed" && job.kind !== "calibration") {
    const fit = await getJSON(`/jobs/${job.id}/fit`);
    return {
      pairs: fit.pairs.map((p) => ({
        label: p.label,
        points: p.stage_deg.map((a, i) => [a, p.measured[i]]).filter((q) => q[1] !== null),
        curve: fit.curve_deg.map((a, i) => [a, p.curve[i]]).filter((q) => q[1] !== null),
      })),
      yTitle: `BRDF (${fit.units}), ${fit.channels}`,
      caption: (fit.calibrated === false || /uncalibrated/.test(fit.units)
        ? "Uncalibrated: dots are the samples in sensor units (no calibration was in effect, so they are not BRDF values in 1/sr)"
        : "Dots: the calibrated samples") +
        " of each light/sensor pair; lines: the reconstructed BRDF at the same pair as the stage turns (the fit). Click a legend entry to hide a pair.",
      count: fit.pairs.reduce((n, p) => n + p.measured.length, 0),
    };
  }
  const { rows, pairs } = await readingsSeries(job.id);
  return {
    pairs, yTitle: "reading − dark (sensor counts), mean over channels",
    caption: "Each colour is one light/sensor pair: dark-subtracted readings as they arrive. When the scan completes, the calibrated samples and the reconstruction's curve replace them.",
    count: rows.length,
  };
}

async function refreshReadings() {
  if (selected === null) return;
  const id = selected;
  const job = jobs.find((j) => j.id === id);
  if (!job) return;
  const data = await rotationData(job);
  if (id !== selected) return;
  plotRotation($("#readings-plot"), data.pairs, data.yTitle);
  $("#readings-caption").textContent = data.caption;
  $("#live-job").textContent = `job ${id} · ${counted(data.count, "reading")}`;
  $("#live-rule").textContent = ruleText(id);
}

// An adaptive job's rule and its setting, shown beside the readings it has used so far.
function ruleText(id) {
  const d = selectedDetail;
  if (!d || d.id !== id || d.plan?.kind !== "adaptive") return "";
  const p = d.plan;
  const rule = p.rule ?? "posterior";
  const setting = rule === "vf" ? `threshold e ${p.threshold ?? 0.1}` : `min gain ${p.min_gain ?? 2e-5}`;
  const cap = p.max_rotations == null ? "" : ` up to ${p.max_rotations}`;
  const arc = p.arc === "auto" ? " over the arc its test chooses" : p.span_deg == null ? "" : ` over ${p.span_deg}°`;
  return ` · adaptive, ${rule} rule, ${setting}, from ${p.initial_rotations} angles${arc}${cap}`;
}

function scheduleReadings() {
  clearTimeout(readingsTimer);
  readingsTimer = setTimeout(() => guarded(refreshReadings), 150);
}

// ------------------------------------------------------------------ results
let shownResult = null;
let shownUncalibrated = false; // the shown result's values are sensor units, not 1/sr
const UNCALIBRATED_NOTE = " Uncalibrated: sensor units, not 1/sr, so brightness and contrast are not the material's.";
let compareWith = null;       // id of a second completed job shown beside the selected one
const objectUrls = {};

function setImage(img, key, blob) {
  if (objectUrls[key]) URL.revokeObjectURL(objectUrls[key]);
  objectUrls[key] = URL.createObjectURL(blob);
  img.src = objectUrls[key];
  img.hidden = false;
  return objectUrls[key];
}

function resultState(job) {
  if (job.state === "completed") return job.kind === "calibration"
    ? "Calibration completed: its factors now convert the readings of later scans to 1/sr. A calibration has no BRDF to show."
    : "";
  if (job.state === "reconstructing") return selectedDetail?.id === job.id && selectedDetail.activity
    ? `Measuring done; ${selectedDetail.activity}.` : "Measuring done; reconstructing the BRDF.";
  if (job.state === "queued" && selectedDetail?.id === job.id && selectedDetail.activity)
    return `Starting: ${selectedDetail.activity}.`;
  if (SHOW_REASON.has(job.state)) return `${job.state[0].toUpperCase()}${job.state.slice(1)}: ${job.reason ?? "no reason recorded"}`;
  return "The result appears when the scan has completed.";
}

async function showResult(job) {
  if (!job) return;
  $("#result-job").textContent = `job ${job.id} (${job.state})`;
  const state = $("#result-state");
  state.textContent = resultState(job);
  state.hidden = state.textContent === "";
  state.className = SHOW_REASON.has(job.state) ? `state-${job.state}` : "muted";
  if (job.state !== "completed" || job.kind === "calibration") {
    $("#result-body").hidden = true;
    // The comparison's readings belong beside a result: "Compare with" is in the result's
    // body, so a job without one (a calibration, a scan still measuring) hides them too.
    $("#compare-fit").hidden = true;
    shownResult = null;
    return;
  }
  $("#compare-fit").hidden = compareWith === null;
  if (shownResult === job.id) return;
  shownResult = job.id;
  $("#result-body").hidden = false;
  try {
    await loadResult(job);
  } catch (e) {
    // Loaded again at the next refresh when the daemon did not answer (stopped meanwhile):
    // the panel said "no rendering: the daemon does not answer" under a live chip, with the
    // previous job's polar curves, until the row was clicked again. An answer that refused
    // (a damaged result file) is not asked again at every refresh.
    if (shownResult === job.id && e instanceof ApiError && e.status === 0) shownResult = null;
    throw e;
  }
}

async function loadResult(job) {
  clearPolar();  // the previous job's curves must not stand under this job's heading
  const metrics = await getJSON(`/jobs/${job.id}/metrics`);
  // Another job shown while this one's answer came: its panel is not this one's to fill.
  if (shownResult !== job.id) return;
  shownUncalibrated = !metrics.calibrated;
  showMetrics(metrics);
  const link = $("#download");
  link.hidden = false;
  link.onclick = async (e) => {
    e.preventDefault();
    await guarded(async () => {
      // Named as the daemon names it: the job and its specimen (gonio-job-7-brushed-steel.h5).
      const { blob, name } = await getFile(`/jobs/${job.id}/result`, `gonio-job-${job.id}.h5`);
      const a = document.createElement("a");
      a.href = URL.createObjectURL(blob); a.download = name; a.click();
    });
  };
  const img = $("#preview");
  const preview = await getBlob(`/jobs/${job.id}/preview.png`);
  if (shownResult !== job.id) return;
  setImage(img, "preview", preview);
  $("#preview-caption").textContent = `${job.specimen}: the reconstructed table itself, log scale; the colour bar gives the brightest channel's value in the material's typical tint; ` +
    "columns φh = 0, 45, 90, 135°; rows φd = 90, 0°; in each panel θh runs down, θd right; hatched cells are below the horizon." + (shownUncalibrated ? UNCALIBRATED_NOTE : "");
  await Promise.all([refreshRender(), refreshPolar()]);
}

// What each metric means, in the words of docs/science.md (sections 4, 4.1, 7.3), shown beside
// its key in "All metrics"; keys without an entry show as they are.
const METRIC_MEANING = {
  predicted_log_rmse: "predicted error of the whole BRDF (log RMSE, the number to report)",
  predicted_error: "predicted relative error of the whole BRDF (MAPE), from leave-one-pair-out",
  design_expected_log_rmse: "the rig's design: expected log RMSE on held-out materials (compare with predicted_log_rmse)",
  design_gap: "why predicted_log_rmse is more than 2 times away from the design's expected error",
  adaptive_stop: "why the adaptive plan stopped refining: converged (its rule asked for no more angles), budget (max_rotations or max_samples) or max_rounds",
  adaptive_wanted: "at a limit of the plan: how many more stage angles its rule still asked for",
  adaptive_limit: "the adaptive plan stopped at a limit while its rule still asked for more angles",
  design_comparison: "why predicted_log_rmse could not be compared with the rig's design (a result rebuilt without the rig config it ran on)",
  predicted_log_rmse_upper: "upper end of predicted_log_rmse's interval: the true error of held-out materials was below it on 98 % of the calibration scans",
  uncovered_share: "share of the prior's weighted variance the readings leave uncovered (0 to 1): the part of the table no pair looks at, part of predicted_log_rmse",
  cv_log_error: "leave-one-pair-out error: each pair predicted by the fit to the other pairs (log)",
  cv_log_under: "the part of cv_log_error where a reading is above what the other pairs predict (log): a peak one pair reads, part of predicted_log_rmse",
  cv_sample_error: "leave-one-pair-out relative error of the readings",
  rel_sample_error: "how far the fit is from its own readings (relative)",
  estimated_error: "V&F's error estimate (0.8 × rel_sample_error), kept for comparison",
  prior_rho: "weight of the library prior the fit used (1: the prior as learnt)",
  local_prior: "the measured or imported material whose shape the fit leaned on where no pair looks (absent: the library's prior alone)",
  local_prior_gain: "how much better that material's shape explains the readings than the library's: natural-log Bayes factor per three channels, used only when at least ln(20 × the number of candidates)",
  n_samples: "readings used by the reconstruction",
  n_pairs: "light/sensor pairs", n_angles: "stage angles", pairs: "light/sensor pairs",
  angles: "stage angles", readings: "readings stored",
  calibrated: "values in 1/sr (true) or sensor units (false)",
  calibration_warning: "why the calibration does not fit this scan (measured at another exposure): its values in 1/sr are off by about the ratio",
  seconds: "reconstruction time, s",
  arc_deg: "the arc the stage angles covered, degrees (an auto-arc scan: the one its test chose)",
  arc_symmetric: "the readings at opposite stage angles agree within the noise (twofold symmetric)",
  arc_mode: "who chose the arc: auto (the first round's twofold symmetry test) or fixed (the plan; the test only reports)",
  arc_test_statistic: "twofold symmetry test: chi-square of the log differences at opposite angles",
  arc_test_dof: "twofold symmetry test: its degrees of freedom (readings compared)",
  arc_test_p_value: "twofold symmetry test: probability of so large a statistic for a symmetric specimen",
  arc_asymmetric: "a half-turn scan whose readings at opposite angles differ: not twofold symmetric",
  reconstruction_basis: "the basis the test's verdict chose: default, or asymmetric (odd harmonics along the rotation)",
  basis_switch: "why the reconstruction used the basis for specimens without twofold symmetry (or could not)",
  K: "components of the basis the fit used",
  local_prior_note: "why the fit did not lean on a measured or imported material's shape",
  basis_misfit: "the readings carry structure the basis cannot hold: why predicted_log_rmse was widened",
  misfit_chi2: "how far the fit misses its own readings, in units of their noise (chi-square per reading; about 1 for noise alone)",
  misfit_log: "the fit's miss at its own readings beyond the noise (RMS, log units)",
  misfit_persistent_pairs: "pairs the fit misses the same way at every stage angle (a shape the basis cannot hold, not noise)",
  predicted_log_rmse_unwidened: "the calibrated model's estimate before the final mapping (coverage term, misfit and peak floors)",
  worst_directional_albedo: "largest share of incident light the table reflects off the mirror direction (a physical material stays at or below 1)",
  peak_to_reading_ratio: "the table's largest f cos(theta_i) cos(theta_o) over the largest reading's (above 1000: beyond what the readings support)",
  peak_excess_log_rmse: "the error the table carries above 1000 times the largest reading (both times cos(theta_i) cos(theta_o)); predicted_log_rmse is never below it",
  physical_bounds: "why the reconstruction is outside physical bounds",
  highlight_excess: "the table's brightest f cos(theta_i) cos(theta_o) at td up to 45 degrees over the brightest reading's (above 3.4: the highlight is not read)",
  highlight_nearest_deg: "angle between the half vector of that peak and the nearest reading's, degrees",
  highlight_peak_th_deg: "where the table peaks (td up to 45 degrees): half vector polar angle th, degrees",
  highlight_peak_ph_deg: "where the table peaks: half vector azimuth ph (specimen frame), degrees",
  highlight_peak_td_deg: "where the table peaks: difference angle td, degrees",
  highlight_not_read: "why the highlight's height, width and colour are the prior's extrapolation: no reading comes near the table's peak",
  mirror_gap_deg: "the least tilt of a pair's half vector from the specimen normal, degrees (for a pair in the plane of incidence, half its sensor's angle from the light's mirror direction): no stage angle reads nearer the mirror direction; above 1, a narrower highlight is neither measured nor in predicted_log_rmse",
  mirror_gap: "what the layout's distance from the mirror direction means for a glossy specimen",
  factored_rel_mse: "relative error of the factored BRDF export fitted to this table (volume-weighted mean squared)",
  factored_psnr: "the factored export's fit as a PSNR, dB",
  principled_roughness: "roughness of the principled (glTF / MaterialX) material fitted to this table",
  principled_log_rmse: "log RMSE of that principled material against this table",
};

function showMetrics(metrics) {
  const head = $("#headline-error");
  const h = metrics.headline_error;
  head.replaceChildren();
  if (h) {
    const strong = document.createElement("strong");
    strong.textContent = `${h.key.replaceAll("_", " ")}: ${h.text}`;
    const p = document.createElement("p");
    p.textContent = h.meaning;
    head.append(strong, p);
  } else head.textContent = "No error estimate for this result (no pair could be left out).";
  // Every headline says whether the values are the material's (1/sr) or sensor units.
  const cal = document.createElement("p");
  cal.id = "headline-calibration";
  // A calibration measured at another exposure than the scan leaves every value off by the
  // ratio (counts are not rescaled): not the plain "Calibrated" line.
  const calWarning = metrics.calibration_warning;
  cal.className = metrics.calibrated && !calWarning ? "muted" : "uncalibrated";
  cal.textContent = metrics.calibrated
    ? (calWarning
      ? `Calibrated, but not for this scan: ${calWarning}.`
      : `Calibrated: values in 1/sr (${metrics.calibration_source ?? "white reference"}).`)
    : "Uncalibrated: no calibration was in effect, so the values are sensor units, not 1/sr; the rendering, exports and the error above are not those of the material. Calibrate the rig (a calibration job with the white reference) and scan again.";
  head.append(cal);
  const tbody = $("#metrics tbody");
  tbody.replaceChildren();
  for (const [k, v] of Object.entries(metrics)) {
    if (v === null || typeof v === "object" || k === "result_path") continue;
    const tr = document.createElement("tr");
    const th = document.createElement("th"), td = document.createElement("td");
    th.textContent = k;
    if (METRIC_MEANING[k]) {
      const why = document.createElement("span");
      why.className = "meaning"; why.textContent = METRIC_MEANING[k];
      th.append(why);
    }
    td.textContent = typeof v === "number" ? String(+v.toPrecision(4)) : String(v);
    tr.append(th, td);
    tbody.append(tr);
  }
}

async function refreshRender() {
  if (shownResult === null) return;
  const id = shownResult, other = compareWith;
  const caption = $("#render-caption");
  // The seconds so far, counted: "a few seconds" read as stuck on a daemon that was also
  // reconstructing a scan (39 s measured on a busy 2-core machine).
  const started = performance.now();
  const tick = () => {
    if (id !== shownResult || other !== compareWith) return;
    const s = Math.round((performance.now() - started) / 1000);
    caption.textContent = `Rendering… ${s} s so far (a few seconds on an idle daemon; longer while it reconstructs a scan or exports)`;
  };
  tick();
  const timer = setInterval(tick, 1000);
  // The picture shown is of another job (or comparison) until this one arrives: not shown.
  $("#render").hidden = true;
  $("#render-link").removeAttribute("href");
  const q = other !== null ? `?compare=${other}` : "";
  let blob;
  try { blob = await getBlob(`/jobs/${id}/render.png${q}`); } catch (e) {
    if (id === shownResult && other === compareWith) caption.textContent = `No rendering: ${e.message}`;
    throw e;
  } finally { clearInterval(timer); }
  if (id !== shownResult || other !== compareWith) return;
  const url = setImage($("#render"), "render", blob);
  $("#render-link").href = url;
  caption.textContent = other !== null
    ? `Job ${id} (top) and job ${other} (bottom), same lights and exposure per column. Click to open full size.`
    : "The reconstruction on a sphere under point lights, on a flat swatch under a flash, and in a studio environment; " +
      "on the simulated rig the true material is in the top row. Click to open full size." + (shownUncalibrated ? UNCALIBRATED_NOTE : "");
}

async function polarCurves(id) {
  const q = `theta_i=${$("#polar-ti").value}&phi_i=${$("#polar-pi").value}`;
  return getJSON(`/jobs/${id}/polar?${q}`);
}

function meanCurve(channels) {
  const arrays = Object.values(channels);
  return arrays[0].map((_, i) => {
    const vs = arrays.map((a) => a[i]);
    return vs.some((v) => v === null) ? null : vs.reduce((a, b) => a + b, 0) / vs.length;
  });
}

// The polar charts emptied, saying so, while another job's curves load.
function clearPolar() {
  for (const sel of ["#polar-in", "#polar-cross"]) clearPlot($(sel), "loading the curves…");
}

async function refreshPolar() {
  if (shownResult === null) return;
  // Said in the panel's words: the daemon's refusal named its query parameter
  // ("theta_i: Input should be less than or equal to 85").
  for (const [sel, what, lo, hi] of [["#polar-ti", "incidence θi", 0, 85], ["#polar-pi", "azimuth φi", -360, 360]]) {
    const v = $(sel).value;
    if (v.trim() === "" || !Number.isFinite(Number(v)) || Number(v) < lo || Number(v) > hi) {
      throw new Error(`Polar plots: enter the ${what} as a number from ${lo} to ${hi} degrees.`);
    }
  }
  const id = shownResult, other = compareWith;
  const [mine, theirs] = await Promise.all([polarCurves(id), other !== null ? polarCurves(other) : null]);
  if (id !== shownResult) return;
  const log = $("#polar-log").checked;
  for (const [plane, canvas, title, angleName] of [
    ["in_plane", "#polar-in", "in-plane", "from the normal"],
    ["cross_plane", "#polar-cross", "cross-plane", "from the mirror direction"],
  ]) {
    const curves = [{ label: `job ${id} reconstruction`, values: meanCurve(mine.reconstruction[plane]), color: "#0b63c5" }];
    if (mine.truth) curves.push({ label: `truth: ${mine.truth_name}`, values: meanCurve(mine.truth[plane]), color: "#1d2329", dash: [6, 4] });
    if (theirs) curves.push({ label: `job ${other} reconstruction`, values: meanCurve(theirs.reconstruction[plane]), color: "#e6194b" });
    plotPolar($(canvas), mine.angle_deg, curves, {
      log, units: mine.units, angleName,
      title: `${title} BRDF at θi = ${mine.theta_i_deg}°, φi = ${mine.phi_i_deg}° (mean of channels)`,
    });
  }
}

// The compare choice lists the other completed scans.
function refreshCompareChoices() {
  const sel = $("#compare");
  const options = jobs.filter((j) => j.state === "completed" && j.kind !== "calibration" && j.id !== selected);
  const want = options.map((j) => `${j.id}`).join(",");
  if (sel.dataset.ids === want) return;
  sel.dataset.ids = want;
  const keep = sel.value;
  sel.replaceChildren(new Option("(no comparison)", ""));
  for (const j of options) sel.append(new Option(`job ${j.id}: ${j.specimen}`, `${j.id}`));
  sel.value = options.some((j) => `${j.id}` === keep) ? keep : "";
  if (sel.value === "" && compareWith !== null) setCompare(null);
}

async function setCompare(id) {
  compareWith = id;
  const box = $("#compare-fit");
  box.hidden = id === null;
  if (id !== null) {
    const job = jobs.find((j) => j.id === id);
    const data = await rotationData(job);
    $("#compare-fit-title").textContent = `Job ${id} (${job.specimen}), for comparison`;
    plotRotation($("#compare-plot"), data.pairs, data.yTitle);
  }
  await Promise.all([refreshRender(), refreshPolar()]);
}

// The panels of a job that is gone, emptied and saying so; the queue then selects another.
function forgetSelected(id) {
  selected = null; selectedDetail = null; selectedState = null; shownResult = null;
  $("#result-job").textContent = "";
  $("#result-body").hidden = true;
  $("#compare-fit").hidden = true;
  const state = $("#result-state");
  state.textContent = `Job ${id} was removed: its readings and result are no longer served.`;
  state.hidden = false;
  state.className = "muted";
  $("#live-job").textContent = "";
  $("#live-rule").textContent = "";
  plotRotation($("#readings-plot"), [], "");
  $("#readings-caption").textContent = `Job ${id} was removed.`;
}

function select(id) {
  if (selected !== id) {
    // The job holding the rig has its detail already (its row's ETA): clicking its row kept
    // the ETA blank until the next poll, up to a second; the job left keeps its own the same
    // way while it holds the rig. Only a detail in the state the list shows: one polled
    // before a pause would show a paused job's time as running out.
    const current = (d) => d && jobs.find((j) => j.id === d.id)?.state === d.state;
    const left = selectedDetail;
    selectedDetail = activeDetail?.id === id && current(activeDetail) ? activeDetail : null;
    if (left && left.id !== id && HOLDING.includes(left.state) && current(left)) activeDetail = left;
  }
  selected = id;
  renderJobs();
  // Its detail now, not at the next tick of the poll (a row without one shows no ETA).
  guarded(pollSelected);
  guarded(refreshReadings);
  refreshCompareChoices();
  guarded(() => showResult(jobs.find((j) => j.id === id)));
}

// ------------------------------------------------------------------ scan form
function readPlan() {
  const f = new FormData($("#scan-form"));
  const kind = f.get("kind");
  const plan = {
    kind,
    // Left empty: "unnamed", the name exports give a scan without one (gonio scan does the
    // same; a calibration: "white reference", as gonio serve --sim names its own); the
    // field's old prefilled "specimen" was listed as such and exported as unnamed.
    // A calibration reads the white reference, not the specimen: the field (hidden for
    // it) would have listed it under the last scan's name while the daemon called it
    // "white reference".
    specimen: kind === "calibration" ? "white reference" : String(f.get("specimen") ?? "").trim() || "unnamed",
    exposure: { exposure_s: Number(f.get("exposure_s")), averages: Number(f.get("averages")) },
  };
  if (kind === "adaptive") {
    plan.initial_rotations = Number(f.get("initial_rotations"));
    plan.rule = f.get("rule");
    // Empty: no cap (null), the vf rule's default.
    plan.max_rotations = f.get("max_rotations") === "" ? null : Number(f.get("max_rotations"));
    if (plan.rule === "vf") plan.threshold = Number(f.get("threshold"));
    else plan.min_gain = Number(f.get("min_gain"));
  } else plan.rotations = Number(f.get("rotations"));
  if (kind !== "calibration") {
    // "auto": the first round tests twofold symmetry and the job chooses the arc itself.
    if (f.get("span_deg") === "auto") { plan.arc = "auto"; plan.span_deg = 180; }
    else plan.span_deg = Number(f.get("span_deg"));
  }
  if (kind === "calibration") plan.reference_albedo = Number(f.get("reference_albedo"));
  return plan;
}

// The note under the form: a dry run's estimate, or "Job N queued." which clears once that
// job has left the queue (it is no longer true). The dry run's warnings (the plan runs, but
// its result may be poorer than it suggests) are listed under it, and go with it.
const note = { job: null };
function setNote(text, jobId, warnings = []) {
  note.job = jobId;
  $("#dry-run-result").textContent = text;
  const list = $("#dry-run-warnings");
  list.replaceChildren(...warnings.map((w) => {
    const li = document.createElement("li");
    li.textContent = `Warning: ${w}.`;
    return li;
  }));
  list.hidden = warnings.length === 0;
}
function clearStaleNotes() {
  if (note.job === null) return;
  const j = jobs.find((x) => x.id === note.job);
  if (!j || j.state !== "queued") setNote("", null);
}

function initForm() {
  const form = $("#scan-form");
  const kindSel = form.elements.kind;
  const ruleSel = form.elements.rule;
  const showKind = () => {
    for (const l of form.querySelectorAll(".kind")) {
      // An adaptive setting of the other rule is hidden (and not sent).
      const otherRule = [...l.classList].some((c) => c.startsWith("rule-") && c !== `rule-${ruleSel.value}`);
      l.hidden = !l.classList.contains(kindSel.value) || otherRule;
    }
    markEmpty();
  };
  // A number field left empty would be sent as 0 and refused by the daemon in its own terms
  // ("rotations is 0"): each field the plan needs says at the field what to enter instead
  // (index.html's data-empty), for Check plan and Start scan alike. A field of another kind
  // or rule is hidden, not sent, and not checked.
  const markEmpty = () => {
    for (const input of form.querySelectorAll("input[data-empty]")) {
      const shown = !input.closest("label").hidden;
      input.setCustomValidity(shown && input.value === "" && !input.validity.badInput ? input.dataset.empty : "");
    }
  };
  // The job's priority (POST /jobs's "priority", -1000..1000, higher starts sooner): anything
  // but a whole number in range (2.5, 5000, empty) says so at the field, and nothing is sent.
  const priority = form.elements.priority;
  const markPriority = () => {
    const n = Number(priority.value);
    const ok = !priority.validity.badInput && priority.value.trim() !== "" && Number.isInteger(n)
      && Math.abs(n) <= 1000;
    priority.setCustomValidity(ok ? "" : priority.dataset.invalid);
  };
  form.addEventListener("input", markEmpty);
  form.addEventListener("change", markEmpty);
  form.addEventListener("input", markPriority);
  form.addEventListener("change", markPriority);
  // A click on Start scan comes before the browser checks the form (Enter in a field clicks
  // it too), so a field emptied without an input event (a script's) is caught as well.
  $("#start-scan").addEventListener("click", markEmpty);
  $("#start-scan").addEventListener("click", markPriority);
  kindSel.addEventListener("change", showKind);
  // Each rule's default first round (posterior 4, vf 8) and cap (posterior 16, vf none),
  // unless the user typed another.
  const r0 = form.elements.initial_rotations;
  const R0 = { posterior: "4", vf: "8" };
  const cap = form.elements.max_rotations;
  const CAP = { posterior: "16", vf: "" };
  // And its arc: half a turn with posterior, V&F's full turn with vf (for an adaptive plan;
  // a uniform plan keeps what is chosen).
  const arc = form.elements.span_deg;
  const ARC = { posterior: "180", vf: "360" };
  ruleSel.addEventListener("change", () => {
    if (Object.values(R0).includes(r0.value)) r0.value = R0[ruleSel.value];
    if (Object.values(CAP).includes(cap.value)) cap.value = CAP[ruleSel.value];
    if (kindSel.value === "adaptive") arc.value = ARC[ruleSel.value];
    showKind();
  });
  showKind();
  $("#dry-run").addEventListener("click", () => guarded(async () => {
    // The form's own limits first, at the field, as Start scan's submit checks them.
    markEmpty();
    if (!form.reportValidity()) { setNote("", null); return; }
    // At the form's priority: it decides whether a queued calibration job runs first.
    const r = await send("POST", "/jobs/dry-run",
      { plan: readPlan(), priority: Number(form.elements.priority.value) });
    // The specimen's angle, as the stage chip gives it; the stage's own position beside it
    // when it is turns away (517.5° is the specimen at 157.5°).
    const specimenDeg = specimenAngle(r.from_deg);
    const from = !r.from_known ? "assuming the stage at 0° (position not known yet)"
      : `from the specimen at ${specimenDeg.toFixed(1)}°` +
        (Math.abs(specimenDeg - r.from_deg) > 1e-6 ? ` (stage position ${r.from_deg.toFixed(1)}°)` : "");
    // A plan the calibration covers only in part does not run: Start is refused (422).
    // So is one whose calibration (in effect, or queued before it) is at another exposure.
    const refused = (r.warnings || []).some((w) => w.startsWith("not calibrated:") ||
      w.startsWith("exposure:"));
    const verdict = refused ? "Start would be refused: read the warning below"
      : (r.warnings || []).length ? "Runs, but read the warnings below" : "OK";
    // estimated_s = motion_s + settle_s + exposure_s (docs/api.md): all three are said.
    let text = `${verdict}: ${counted(r.readings, "reading")} at ${counted(r.angles_deg.length, "stage angle")}, about ${planTime(r.estimated_s)} ${from}` +
      `: moves ${planTime(r.motion_s)}, settling ${planTime(r.settle_s)}, exposures ${planTime(r.exposure_s)}.`;
    // estimated_s is the measuring alone (docs/api.md); a scan then reconstructs, which can
    // take longer than the measuring (20 s after an 8 s default scan on a busy 2-core machine).
    if (r.finishing_s != null) text += ` That is the measuring; then about ${eta(r.finishing_s)} to reconstruct and fit the exports (${r.finishing_source}).`;
    else if (r.kind !== "calibration") text += " That is the measuring; the reconstruction follows and is not counted in it (the job's ETA gives it once the scan runs).";
    if (r.max_estimated_s != null && r.kind === "adaptive") text += ` Adaptive refinement can add up to ${counted(r.max_angles - r.angles_deg.length, "angle")}: at most ${eta(r.max_estimated_s)} in all.`;
    for (const b of r.arc_branches || []) {
      text += ` If the first round finds the specimen ${b.arc_deg === 180 ? "twofold symmetric, it goes on over half a turn" : "not twofold symmetric, it goes on over a full turn"}: at most ${counted(b.angles, "angle")} (${counted(b.readings, "reading")}), ${eta(b.estimated_s)} in all${b.basis === "asymmetric" ? ", reconstructed with the basis for specimens without twofold symmetry" : ""}.`;
      if (b.basis_build_s != null) text += ` Then about ${eta(b.basis_build_s)} more: that basis is not built on this install yet, so the job builds it before reconstructing (once).`;
    }
    if (r.basis_build_s != null) text += ` First, about ${eta(r.basis_build_s)} more: the reconstruction basis is not built on this install yet and the adaptive rule needs it, so the job builds it before its first reading (once).`;
    // A fact of the rig's layout (docs/api.md mirror_gap), not a warning: the verdict stays.
    if (r.mirror_gap) text += ` Note: ${r.mirror_gap}.`;
    setNote(text, null, r.warnings || []);
  }, true));
  // A checked plan's estimate no longer holds once the form changes.
  form.addEventListener("input", () => { if (note.job === null) setNote("", null); });
  form.addEventListener("submit", (e) => {
    e.preventDefault();
    guarded(async () => {
      const plan = readPlan();
      const priority = Number(form.elements.priority.value);
      let job;
      try { job = await send("POST", "/jobs", { plan, priority }); } catch (e) {
        // An uncalibrated scan of a rig that was calibrated is most likely a mistake (the
        // daemon on another data directory): it runs only once the user has accepted it.
        if (!(e instanceof ApiError && e.status === 409 && e.message.includes("accept_uncalibrated"))) throw e;
        if (!window.confirm(`${e.message.replace(/, or send accept_uncalibrated=true to/, ". OK:")}?`)) {
          setNote("Not started: the scan would be uncalibrated.", null);
          return;
        }
        job = await send("POST", "/jobs?accept_uncalibrated=true", { plan, priority });
      }
      // A scan queued behind one that is measuring (or finishing) leaves that one on screen:
      // its readings, ETA and result are what the lab is waiting for, and the new job has
      // nothing to show until it starts. Its row is a click away.
      setNote(`Job ${job.id} queued.`, job.id);
      await refreshJobs();
      const active = jobs.find((j) => j.id !== job.id && ACTIVE.includes(j.state));
      if (active && jobs.find((j) => j.id === job.id)?.state === "queued") {
        // Nothing here that turns false as the queue moves ("it starts after job 4" stood while
        // two jobs of higher priority went first and one was paused): its row says when it
        // starts and what it waits for, and keeps saying it.
        setNote(`Job ${job.id} queued: its row says when it starts and what it waits for. ` +
          `The page goes on showing job ${active.id} (${active.specimen}), which held the rig ` +
          `when job ${job.id} was queued; click job ${job.id}'s row to see it.`, job.id);
        if (selected !== active.id) select(active.id);
        return;
      }
      select(job.id);
    }, true);
  });
}

// ------------------------------------------------------------------ start
async function refreshAll() {
  await guarded(async () => { await refreshRig(); await refreshJobs(); await refreshCalibration(); });
}

function onEvent(ev) {
  scheduleRefresh();
  // Each angle measured says where the specimen stood: the chip follows the scan between
  // the rig's slow polls (it read "specimen at 22.9° moving" while the stage went to 155°).
  if (ev.type === "progress" && typeof ev.data?.actual_deg === "number") showScanAngle(ev.data.actual_deg, ev.job_id);
  if (ev.job_id !== null && ev.job_id === selected) scheduleReadings();
  if (["maintenance", "rig", "queue_held", "queue_released"].includes(ev.type)) guarded(refreshRig);
}

let stopEvents = null;
// (Re)open the event stream, e.g. with a new key: a stream opened with a refused key keeps
// retrying with that key.
function restartEvents() {
  if (stopEvents) stopEvents();
  stopEvents = followEvents(onEvent, (live) => {
    const chip = $("#live-chip");
    chip.textContent = live ? "live" : readsRefused() ? "no valid key" : "reconnecting";
    chip.className = live ? "chip" : "chip off";
    if (live) scheduleRefresh();
  });
}

// A page the browser keeps in its back/forward cache after the lab navigates away keeps its
// fetch of /events open, and a browser opens only six connections to one host: after six
// such pages in one tab the seventh load waited about a minute for one to free. Close the
// stream on leaving; a page shown again from that cache opens it anew and reads the state.
window.addEventListener("pagehide", () => {
  if (stopEvents) stopEvents();
  stopEvents = null;
});
window.addEventListener("pageshow", (e) => {
  if (!e.persisted) return;
  restartEvents();
  refreshAll();
});

window.addEventListener("DOMContentLoaded", async () => {
  initKey();
  initForm();
  initQueue();
  // The page had "release queue" after a halt but no halt: a lab reaching for a stage that
  // moved wrongly had to find the CLI. No question first: it is an emergency stop.
  $("#halt-rig").addEventListener("click", () => guarded(async () => {
    await send("POST", "/rig/halt");
    await refreshRig();
    await refreshJobs();
  }, true));
  $("#release-queue").addEventListener("click", () => guarded(async () => {
    await send("POST", "/rig/release");
    await refreshRig();
    await refreshJobs();
  }, true));
  for (const id of ["#polar-ti", "#polar-pi", "#polar-log"]) $(id).addEventListener("change", () => guarded(refreshPolar, true));
  $("#compare").addEventListener("change", (e) => guarded(() => setCompare(e.target.value ? Number(e.target.value) : null), true));
  setInterval(() => guarded(pollSelected), 1000);
  setInterval(() => guarded(pollActive), 1000);
  // Reconstruction sends no events, so a queued job's "starts in about 7 s" stood still
  // while the job ahead finished: the list is read again while one holds the rig and a
  // queued job has an estimated start.
  setInterval(() => {
    if (readsRefused()) return;
    const waiting = jobs.some((j) => j.state === "queued" && j.starts_in_s != null);
    if (waiting && jobs.some((j) => HOLDING.includes(j.state))) scheduleRefresh();
  }, 2000);
  await refreshAll();
  restartEvents();
  // Stage position changes without events while idle; a slow poll keeps the chip honest.
  setInterval(() => guarded(refreshRig), 5000);
});
