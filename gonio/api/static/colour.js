// The result panel's colour table: GET /api/v1/jobs/{id}/colour, beside the renderings.
// CIELAB at the chosen instrument's aspecular geometries (D65/10), the flop index, and with a
// comparison job chosen above, the CIEDE2000 against it. A result without colour (uncalibrated
// sensor RGB) shows its channel values under that label, never as a colour space. The "source"
// column says which geometries a pair of the scan read directly ("pair", the report's
// `measured` flags) and which came from the reconstructed table ("table").
// "against standard" compares with a stored standard instead (GET /api/v1/colour-standards;
// the data directory's standards/ CSVs), and "Save" stores the table shown as one (PUT
// /api/v1/colour-standards/{name}): a lab measures its master once and compares each batch
// with it by name; "Delete standard" removes the one chosen (DELETE
// /api/v1/colour-standards/{name}), after asking. "Download CSV" saves the table shown
// (format=csv), as gonio colour --csv.
// The instrument menu starts on the rig's design instrument (GET /api/v1/rig/config, its
// [design] colour_instrument, written by `gonio design --colour`) when the rig has one, until
// the user picks another.
import { getBlob, getFile, getJSON, send, sendText } from "./api.js";

const $ = (sel) => document.querySelector(sel);
let shown = null;
let shownSpace = null;  // the colour space of the table shown (CIELAB, or channel values)
// The rig's design instrument: undefined until the rig config was read, null when it has none.
let designInstrument;
let userChose = false;

// Read once, when a result is first shown (by then the page has a key that works); a refused
// read (no key yet) is tried again at the next result.
async function useDesignInstrument() {
  if (designInstrument !== undefined) return;
  let cfg;
  try { cfg = await getJSON("/rig/config"); } catch { return; }
  designInstrument = cfg?.design?.colour_instrument ?? null;
  const option = [...$("#colour-instrument").options].find((o) => o.value === designInstrument);
  if (!option) return;
  option.textContent = `${designInstrument} (rig design)`;
  if (!userChose) $("#colour-instrument").value = designInstrument;
}

function shownJob() {
  const m = ($("#result-job").textContent || "").match(/^job (\d+) \(completed\)/);
  return m ? Number(m[1]) : null;
}

function cell(tr, text, tag = "td") {
  const el = document.createElement(tag);
  el.textContent = text;
  tr.append(el);
}

// The stored standards in the menu, keeping the one chosen (or ``choose``) while it exists.
async function refreshStandards(choose = undefined) {
  let names;
  try { names = (await getJSON("/colour-standards")).standards; } catch { return; }
  const sel = $("#colour-standard");
  const want = choose ?? sel.value;
  const listed = names.join("\n");
  if (sel.dataset.names !== listed) {
    sel.dataset.names = listed;
    sel.replaceChildren(new Option("(none)", ""), ...names.map((n) => new Option(n, n)));
  }
  sel.value = names.includes(want) ? want : "";
  $("#colour-delete-standard").disabled = !sel.value;
}

async function deleteStandard() {
  const name = $("#colour-standard").value, state = $("#colour-standard-state");
  if (!name) return;
  if (!window.confirm(`Delete the stored standard ${name}? Its colour CSV is removed from ` +
    "the daemon's standards folder, for every client: nothing can be compared with it by " +
    "name afterwards (save a result's colour again to restore it).")) return;
  try {
    await send("DELETE", `/colour-standards/${encodeURIComponent(name)}`);
    state.textContent = `Deleted standard ${name}.`;
  } catch (e) {
    state.textContent = `Not deleted: ${e.message}`;
  }
  await refreshStandards();
}

function tableQuery(format = undefined) {
  const q = new URLSearchParams({ instrument: $("#colour-instrument").value,
    azimuth: String(Number($("#colour-azimuth").value) || 0) });
  if (format) q.set("format", format);
  return q;
}

async function saveStandard() {
  const id = shownJob(), state = $("#colour-standard-state"), field = $("#colour-standard-name");
  if (id === null) return;
  const name = field.value.trim();
  if (!name) { state.textContent = "Name the standard first."; field.focus(); return; }
  state.textContent = "Saving…";
  try {
    const csv = await (await getBlob(`/jobs/${id}/colour?${tableQuery("csv")}`)).text();
    const r = await sendText("PUT", `/colour-standards/${encodeURIComponent(name)}`, csv, "text/csv");
    state.textContent = `${r.replaced ? "Replaced" : "Saved"} standard ${r.name}: job ${id} at ` +
      `${r.geometries} ${$("#colour-instrument").value} geometries, ${r.illuminant}/${r.observer}°.`;
    await refreshStandards();
  } catch (e) {
    state.textContent = `Not saved: ${e.message}`;
  }
}

async function downloadCsv() {
  const id = shownJob(), state = $("#colour-standard-state");
  if (id === null) return;
  try {
    const q = tableQuery("csv");
    const standard = $("#colour-standard").value;
    // Channel values (no CIELAB) cannot be compared: their table alone.
    if (standard && shownSpace === "CIELAB") q.set("against", standard);
    // Named as the daemon names it, after the job and its specimen as the result and the
    // exports are ("gonio-job-7-blue-panel-colour.csv"), with the instrument shown.
    const instrument = $("#colour-instrument").value;
    const { blob, name } = await getFile(`/jobs/${id}/colour?${q}`, `gonio-job-${id}-colour.csv`);
    const a = document.createElement("a");
    a.href = URL.createObjectURL(blob);
    a.download = name.replace(/\.csv$/, `-${instrument}.csv`);
    a.click();
    state.textContent = `saved ${a.download}`;
  } catch (e) {
    state.textContent = `Not saved: ${e.message}`;
  }
}


function fmt(v, digits = 2) { return typeof v === "number" ? v.toFixed(digits) : "–"; }

async function refresh() {
  const id = shownJob();
  const box = $("#colour");
  // A calibration job's result has no BRDF (the panel hides its body): no colour to ask for.
  if (id === null || $("#result-body").hidden) { box.hidden = true; shown = null; return; }
  await useDesignInstrument();
  const instrument = $("#colour-instrument").value;
  const azimuth = Number($("#colour-azimuth").value) || 0;
  const against = $("#compare").value;
  const standard = $("#colour-standard").value;
  const key = `${id}/${instrument}/${azimuth}/${against}/${standard}`;
  if (key === shown) return;  // every job-list event comes here: nothing more to ask then
  // Another job: the standards line spoke of the last one ("Saved standard blue std: job 12"
  // stood under job 13's colour).
  if (shown === null || !shown.startsWith(`${id}/`)) $("#colour-standard-state").textContent = "";
  shown = key;
  // The stored standards, read when the table changes (and when the menu is opened), not at
  // every event; a standard another client stored shows up then.
  await refreshStandards();
  // The standard chosen is gone from the folder: the menu fell back to none; ask again.
  if ($("#colour-standard").value !== standard) { shown = null; return refresh(); }
  // Another refresh (another job chosen) started meanwhile and may have finished: this one
  // must not write "Computing colour…" over its caption and then leave it standing.
  if (key !== shown) return;
  box.hidden = false;
  const caption = $("#colour-caption");
  caption.textContent = "Computing colour…";
  const q = new URLSearchParams({ instrument, azimuth: String(azimuth) });
  let body;
  // A comparison asked for that cannot be made: which, and why (the answer's no_colour: an
  // uncalibrated result, and what to do), said in the caption instead of a missing column.
  let noDiff = null;
  const compared = standard ? `standard ${standard}` : against ? `job ${against}` : null;
  try {
    body = await getJSON(`/jobs/${id}/colour?${q}`);
    // A difference only between two results with CIELAB (the server refuses the others):
    // the compared job's space is asked first, so no request is made that must fail.
    if (compared && body.colour.space !== "CIELAB") {
      noDiff = `No ΔE00 against ${compared}: ${body.no_colour ?? "this result has no CIELAB"}`;
    } else if (standard) {
      // A stored standard chosen: compared with it, not with the job chosen above.
      q.set("against", standard);
      body = await getJSON(`/jobs/${id}/colour?${q}`);
    } else if (against) {
      const other = await getJSON(`/jobs/${against}/colour?${q}`);
      if (other.colour.space === "CIELAB") {
        q.set("against", against);
        body = await getJSON(`/jobs/${id}/colour?${q}`);
      } else noDiff = `No ΔE00 against ${compared}: ${other.no_colour ?? `job ${against} has no CIELAB`}`;
    }
  } catch (e) {
    if (key !== shown) return;
    $("#colour-table thead").replaceChildren();
    $("#colour-table tbody").replaceChildren();
    caption.textContent = `No colour: ${e.message}`;
    return;
  }
  if (key !== shown) return;
  const rep = body.colour, diff = body.difference;
  shownSpace = rep.space;
  const head = document.createElement("tr");
  const lab = rep.space === "CIELAB";
  const cols = lab ? ["geometry", "L*", "a*", "b*", "C*", "h°"]
    // One column per channel, headed by its name: the caption says they are reflectance
    // factors ("R R, R G, R B" read as three channels named R).
    : ["geometry", ...rep.channels.slice(0, 6)];
  cols.push("source");
  if (diff) cols.push("ΔE00");
  for (const c of cols) cell(head, c, "th");
  $("#colour-table thead").replaceChildren(head);
  const measured = rep.measured || [];
  const rows = rep.rows.map((r, i) => {
    const tr = document.createElement("tr");
    cell(tr, `${r.incidence_deg}as${r.aspecular_deg}`);
    if (lab) for (const k of ["L", "a", "b", "C"]) cell(tr, fmt(r[k]));
    if (lab) cell(tr, fmt(r.h_deg, 0));
    else for (const c of rep.channels.slice(0, 6)) cell(tr, fmt(r[`R_${c}`], 3));
    cell(tr, measured[i] ? "pair" : "table");
    // The difference's rows are the geometries both reports hold, not every row shown: each
    // is found by its geometry (a standard without 45as-15 must not shift the column).
    if (diff) cell(tr, fmt(diff.rows.find((d) => d.instrument === r.instrument &&
      d.incidence_deg === r.incidence_deg && d.aspecular_deg === r.aspecular_deg &&
      d.azimuth_deg === r.azimuth_deg)?.dE00));
    return tr;
  });
  $("#colour-table tbody").replaceChildren(...rows);
  const read = measured.filter(Boolean).length;
  const source = read
    ? `; source "pair": ${read} of ${measured.length} geometries read directly by a pair of the scan, the others from the reconstructed table`
    : "; every geometry read from the reconstructed table";
  const flop = Object.values(rep.flop_index)[0];
  caption.textContent = lab
    ? `${rep.space}, ${rep.conditions.illuminant}/${rep.conditions.observer}°, ${instrument} geometries at azimuth ${azimuth}° (${rep.conversion})` +
      (flop !== undefined ? `; flop index ${flop.toFixed(2)}` : "") +
      // Max and mean, as a lab quotes an instrument's difference (the page shows one
      // instrument, so the mean is over its geometries, each once).
      (diff ? `; ΔE00 against ${standard ? `standard ${standard}` : `job ${against}`}: max ${diff.max_dE00.toFixed(2)}, mean ${diff.mean_dE00.toFixed(2)}` : "") + source
    : channelCaption(rep, body, noDiff);
  if (noDiff && lab) caption.textContent += `. ${noDiff}.`;
  // The "source" column is explained whatever the space (it was said only beside CIELAB).
  if (!lab) {
    caption.textContent += read
      ? ` Source "pair": ${read} of ${measured.length} geometries read directly by a pair of the scan; "table": read from the reconstructed table.`
      : ' Source "table": every geometry read from the reconstructed table (no pair of the scan reads one directly).';
  }
  // What must travel with the numbers (a calibration from another exposure): said first.
  if (body.warnings?.length) caption.textContent = `Warning: ${body.warnings.join("; ")}. ${caption.textContent}`;
  // Which near-specular geometries no pair read (their rows say "table"), and what that means.
  if (body.notes?.length) caption.textContent += `. Note: ${body.notes.join("; ")}.`;
}

// A table of channel values (no CIELAB): what its values are, and why there is no CIELAB
// (and so no ΔE00) said once, in the daemon's words (no_colour, or the refused comparison's
// reason, which holds it). "no CIELAB" was said by this caption and again by no_colour.
function channelCaption(rep, body, noDiff) {
  const n = rep.channels.length;
  const why = noDiff ?? body.no_colour;
  // In sensor units (no white reference in effect) the values are no reflectance factors.
  if (body.calibrated === false) {
    return `${rep.space}: values per channel in sensor units (${n} channels). ${why ?? "No CIELAB: calibrate the rig on the white reference, then scan again"}.`;
  }
  // "Uncalibrated" is the colour, not the values: the result's own calibration (1/sr) is
  // said under the headline.
  const what = `${rep.space}: reflectance factors per channel (${n} channels). Uncalibrated here is the colour`;
  return why ? `${what}, not the values. ${why}.`
    : `${what}: no spectral bands or chart calibration tie the sensors' channels to a colour space, so there is no CIELAB. ` +
      "Give the sensors spectral bands or a chart colour calibration (docs/colour.md).";
}

window.addEventListener("DOMContentLoaded", () => {
  const go = () => { refresh().catch(() => {}); };
  new MutationObserver(go).observe($("#result-job"), { childList: true, characterData: true, subtree: true });
  $("#colour-instrument").addEventListener("change", () => { userChose = true; });
  for (const id of ["#colour-instrument", "#colour-azimuth", "#compare", "#colour-standard"]) $(id).addEventListener("change", go);
  $("#colour-save-standard").addEventListener("click", () => { saveStandard().then(go); });
  $("#colour-csv").addEventListener("click", () => { downloadCsv(); });
  $("#colour-delete-standard").addEventListener("click", () => { deleteStandard().then(go); });
  $("#colour-standard").addEventListener("change", (e) => {
    $("#colour-delete-standard").disabled = !e.target.value;
  });
  $("#colour-standard").addEventListener("focus", () => { refreshStandards(); });
  go();
});
