// The stage panel: GET /api/v1/rig/stage and POST /api/v1/rig/stage (move, home, stop,
// clear_faults), as `gonio stage --daemon URL` does. A lab loading a specimen or setting the
// zero at the holder's mark had the command line alone. The daemon refuses a command while
// a job is active (409, its words shown here); stop is always accepted.
import { RIG_EVENT, clock, send } from "./api.js";

const $ = (sel) => document.querySelector(sel);

function describe(st) {
  const faults = st.faults?.length ? `; faults: ${st.faults.join(", ")}` : "";
  return `position ${Number(st.position_deg).toFixed(2)}°${st.moving ? ", moving" : ""}, ` +
    `${st.homed ? "homed" : "not homed (no zero set since the stage powered up)"}${faults}`;
}

// From the page's own GET /rig answers (app.js announces each one: one poll for the header's
// chip and this panel), which never connect the rig (GET /rig/stage would, at page load):
// before the first scan or command the panel says so.
function show(rig) {
  const stage = (rig.devices ?? []).find((d) => d.name === "stage");
  const d = stage?.detail;
  $("#stage-state").textContent = !rig.connected
    ? "not connected yet: the first scan or command connects it"
    : typeof d?.position_deg === "number"
      ? describe({ position_deg: d.position_deg, moving: d.moving, homed: d.homed, faults: d.faults ?? [] })
      : `position unknown${d?.error ? `: ${d.error}` : ""}`;
}

// Listened for at once (not at DOMContentLoaded): app.js reads /rig as the page loads.
window.addEventListener(RIG_EVENT, (e) => show(e.detail));

async function command(body, what) {
  const said = $("#stage-said");
  // Its time first: the line stays until the next command, across jobs and restarts, and
  // "refused: job 13 is running" read as today's state long after job 13 had ended.
  what = `${clock()} ${what}`;
  said.textContent = `${what}…`;
  try {
    const st = await send("POST", "/rig/stage", body);
    $("#stage-state").textContent = describe(st);
    // A move cut short by Stop ends as asked, saying where (the driver's stall is not a fault).
    said.textContent = st.note ? `${what}: ${st.note}` : `${what}: done`;
  } catch (e) {
    said.textContent = `${what} refused: ${e.message}`;
  }
}

window.addEventListener("DOMContentLoaded", () => {
  const form = $("#stage-form");
  const angle = form.elements.angle_deg;
  const markEmpty = () => angle.setCustomValidity(
    angle.value === "" && !angle.validity.badInput ? angle.dataset.empty : "");
  angle.addEventListener("input", markEmpty);
  $("#stage-move").addEventListener("click", markEmpty);
  form.addEventListener("submit", (e) => {
    e.preventDefault();
    const deg = Number(angle.value);
    command({ action: "move", angle_deg: deg }, `moving to ${deg}°`);
  });
  $("#stage-home").addEventListener("click", () => {
    // It moves every later scan's angles: asked first.
    if (!window.confirm("Make the stage's present position 0°? Every later scan's angles " +
      "count from here: do it at the holder's reference mark.")) return;
    command({ action: "home" }, "setting the zero here");
  });
  $("#stage-stop").addEventListener("click", () => command({ action: "stop" }, "stopping"));
  $("#stage-clear").addEventListener("click", () => command({ action: "clear_faults" }, "clearing faults"));
});
