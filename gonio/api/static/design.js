// The rig design panel: POST /api/v1/design (pairs chosen for the daemon's basis) and
// GET /api/v1/design/presets[/{name}] (an industrial geometry evaluated the same way), shown
// as the lab mounts them, with the rig-config fragment to download. It shares no state with
// the rest of the page; a refused key raises the page's key prompt through api.js.
import { clock, getJSON, send } from "./api.js";

const $ = (sel) => document.querySelector(sel);

const deg = (x) => (x === null || x === undefined ? "–" : `${Number(x).toFixed(1)}`);

function setState(text, failed = false) {
  const state = $("#design-state");
  state.textContent = text;
  state.classList.toggle("failed", failed);
}

// The words `gonio design` prints for the same numbers (gonio/cli/design_command.py), so the
// page and the shell say one thing.
function summaryLines(d) {
  const lines = [];
  const how = d.objective === "posterior" ? " (chosen by the joint fit's expected error)"
    : d.objective === "kappa" ? " (chosen by the condition-number search)" : "";
  lines.push(`, ${d.n_pairs} pair${d.n_pairs === 1 ? "" : "s"}${how}`);  // after the name
  const r = d.roughness;
  const arc = `${r.rotations} stage angles over ${r.span_deg}°`;
  if (d.expected_log_rmse !== null && d.expected_log_rmse !== undefined) {
    // Issue 27: a design's own number is inside the basis; a scan's predicted_log_rmse on a
    // new specimen reads higher, and the page must not promise the best case.
    lines.push(`expected log_rmse ${d.expected_log_rmse.toFixed(4)} at ${arc} — inside the ` +
      "basis: on the materials it was learnt from, a best case, not a prediction for a new specimen");
  }
  lines.push(`condition number ${d.condition_number === null ? "singular (the pairs cannot separate the basis' components)" : Number(d.condition_number).toPrecision(4)}` +
    `; closest two devices ${deg(d.min_device_distance_deg)}°` +
    // A preset lists one light per pair; several at one place are one lamp on the instrument.
    (d.min_device_distance_deg < 0.05 ? " (devices at one place: one device serves those pairs)" : ""));
  lines.push(`mirror gap ${deg(d.mirror_gap_deg)}° (no stage angle reads nearer the mirror direction)`);
  if (r.alpha_min !== null) {
    lines.push(`roughness bound at ${arc}: α' = ${Number(r.alpha_min).toPrecision(3)} ` +
      `(${Math.round(r.n_effective)} effective samples within ${r.cap_deg}° of the normal)`);
  }
  if (d.colour_pairs) {
    lines.push(`colour: pairs 1-${d.colour_pairs} sit at the instrument's near-specular ` +
      "geometries; the colour report reads those from the scan (docs/colour.md)");
  }
  const notes = [];
  if (d.fallback) notes.push(`note: ${d.fallback}`);
  if (d.mirror_gap) notes.push(`glossy specimens: ${d.mirror_gap}`);
  return { lines, notes };
}

function text(tag, content, cls = null) {
  const el = document.createElement(tag);
  el.textContent = content;
  if (cls) el.className = cls;
  return el;
}

function show(d) {
  const box = $("#design-summary");
  box.replaceChildren();
  const { lines, notes } = summaryLines(d);
  const first = document.createElement("div");
  first.append(text("strong", d.name), lines[0]);
  box.append(first, ...lines.slice(1).map((l) => text("p", l)), ...notes.map((n) => text("p", n, "note")));
  const lights = new Map(d.lights.map((x) => [x.name, x]));
  const sensors = new Map(d.sensors.map((x) => [x.name, x]));
  const body = $("#design-pairs tbody");
  body.replaceChildren(...d.pairs.map((p, k) => {
    const tr = document.createElement("tr");
    const l = lights.get(p.light) ?? {}, s = sensors.get(p.sensor) ?? {};
    for (const v of [String(k + 1), p.light, deg(l.theta_deg), deg(l.phi_deg), p.sensor,
      deg(s.theta_deg), deg(s.phi_deg), deg(p.theta_h_deg), deg(p.theta_d_deg), deg(p.phi_d_deg)]) {
      tr.append(text("td", v));
    }
    return tr;
  }));
  $("#design-fragment").textContent = d.rig_config_toml;
  const file = fragmentName(d);
  $("#design-merge").textContent = `Save it as ${file} and merge it into the rig config with ` +
    `'gonio rig apply-design ${file} rig.toml' (docs/rig-config.md); restart the daemon on the new config.`;
  $("#design-download").onclick = () => {
    const a = document.createElement("a");
    a.href = URL.createObjectURL(new Blob([d.rig_config_toml], { type: "application/toml" }));
    a.download = file;
    a.click();
  };
  $("#design-result").hidden = false;
}

function fragmentName(d) {
  const name = String(d.name).replace(/[^A-Za-z0-9_.-]+/g, "-").replace(/^-+|-+$/g, "") || "design";
  return `gonio-design-${name}-${d.n_pairs}-pairs.toml`;
}

// The seconds so far, counted: a design searches for up to its time limit, and a bare
// "designing…" read as stuck.
async function running(what, fn) {
  const started = performance.now();
  const tick = () => setState(`${what}… ${Math.round((performance.now() - started) / 1000)} s so far`);
  tick();
  const timer = setInterval(tick, 1000);
  const buttons = [$("#design-run"), $("#design-evaluate")];
  for (const b of buttons) b.disabled = true;
  try {
    const d = await fn();
    show(d);
    setState(`${what}: done in ${Math.round((performance.now() - started) / 1000)} s`);
  } catch (e) {
    // Its time, and whose the pairs below are: the failure stood above an older design as if
    // it were about it, long after the form had changed.
    const older = $("#design-result").hidden ? "" : " (the pairs below are the last design that worked)";
    setState(`${clock()} ${what} failed: ${e.message}${older}`, true);
  } finally {
    clearInterval(timer);
    for (const b of buttons) b.disabled = false;
  }
}

function numberOrNull(input) {
  return input.value.trim() === "" ? null : Number(input.value);
}

async function designPairs(ev) {
  ev.preventDefault();
  const f = $("#design-form").elements;
  const body = {
    pairs: numberOrNull(f.pairs), rotations: numberOrNull(f.rotations),
    span_deg: Number(f.span_deg.value), max_elevation_deg: numberOrNull(f.max_elevation_deg),
    min_separation_deg: numberOrNull(f.min_separation_deg),
    // The API's list, from the field's ';'-separated regions (the daemon says what is wrong
    // with one it cannot read).
    exclusions: f.exclusions.value.split(";").map((x) => x.trim()).filter((x) => x),
  };
  if (f.colour_instrument.value) body.colour_instrument = f.colour_instrument.value;
  const limit = numberOrNull(f.time_limit_s);
  if (limit !== null) body.time_limit_s = limit;
  await running(`designing ${body.pairs} pairs`, () => send("POST", "/design", body));
}

async function evaluatePreset() {
  const name = $("#design-preset").value;
  if (!name) { setState("no industrial geometry to evaluate: the daemon listed none", true); return; }
  const f = $("#design-form").elements;
  const q = new URLSearchParams({ rotations: f.rotations.value || "8", span_deg: f.span_deg.value });
  await running(`evaluating ${name}`, () => getJSON(`/design/presets/${encodeURIComponent(name)}?${q}`));
}

async function loadPresets() {
  const sel = $("#design-preset");
  if (sel.options.length) return;
  try {
    const presets = await getJSON("/design/presets");
    sel.replaceChildren(...presets.map((p) => {
      const o = document.createElement("option");
      o.value = p.name;
      o.textContent = `${p.name} (${p.n_pairs} pairs)`;
      o.title = p.description;
      return o;
    }));
  } catch (e) {
    setState(`could not list the industrial geometries: ${e.message}`, true);
  }
}

window.addEventListener("DOMContentLoaded", () => {
  const form = $("#design-form");
  // An empty number field says at the field what to enter, as the scan form does.
  const markEmpty = () => {
    for (const input of form.querySelectorAll("input[data-empty]")) {
      input.setCustomValidity(input.value === "" && !input.validity.badInput ? input.dataset.empty : "");
    }
  };
  form.addEventListener("input", markEmpty);
  $("#design-run").addEventListener("click", markEmpty);
  form.addEventListener("submit", designPairs);
  $("#design-evaluate").addEventListener("click", evaluatePreset);
  // Listed again when the menu is opened, should the first read have been refused (a key
  // entered since).
  $("#design-preset").addEventListener("focus", loadPresets);
  loadPresets();
});
