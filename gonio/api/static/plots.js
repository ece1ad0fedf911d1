// Small SVG plots for the lab page: no libraries, no build step.

const SVG = "http://www.w3.org/2000/svg";
const COLORS = ["#0b63c5", "#d1495b", "#2a9d8f", "#e9a03b", "#6f42c1", "#3d5a80", "#8c564b", "#17becf"];

function el(name, attrs = {}, text = null) {
  const node = document.createElementNS(SVG, name);
  for (const [k, v] of Object.entries(attrs)) node.setAttribute(k, String(v));
  if (text !== null) node.textContent = text;
  return node;
}

function niceTicks(lo, hi, count = 5) {
  if (!(hi > lo)) { hi = lo + 1; }
  const raw = (hi - lo) / count;
  const mag = 10 ** Math.floor(Math.log10(raw));
  const step = [1, 2, 5, 10].map((m) => m * mag).find((s) => s >= raw) ?? raw;
  const out = [];
  for (let v = Math.ceil(lo / step) * step; v <= hi + step * 1e-9; v += step) out.push(+v.toPrecision(12));
  return out;
}

function fmt(v) {
  const a = Math.abs(v);
  return a !== 0 && (a < 1e-3 || a >= 1e4) ? v.toExponential(1) : String(+v.toPrecision(4));
}

/**
 * Line plot of readings against stage angle, one series per light/sensor pair.
 * @param {HTMLElement} host  container; its content is replaced
 * @param {Map<string, Array<[number, number]>>} series  label -> [angle_deg, value] points
 */
export function plotReadings(host, series) {
  const W = 720, H = 280, L = 60, R = 130, T = 10, B = 36;
  const svg = el("svg", { viewBox: `0 0 ${W} ${H}`, role: "img" });
  const all = [...series.values()].flat();
  const ys = all.map((p) => p[1]).filter(Number.isFinite);
  const yMin = Math.min(0, ...ys), yMax = ys.length ? Math.max(...ys) : 1;
  const x = (a) => L + (a / 360) * (W - L - R);
  const y = (v) => T + (1 - (v - yMin) / ((yMax - yMin) || 1)) * (H - T - B);
  svg.append(el("rect", { x: L, y: T, width: W - L - R, height: H - T - B, fill: "none", stroke: "#d0d7de" }));
  for (const a of [0, 45, 90, 135, 180, 225, 270, 315, 360]) {
    svg.append(el("line", { x1: x(a), x2: x(a), y1: T, y2: H - B, stroke: "#eef1f4" }));
    svg.append(el("text", { x: x(a), y: H - B + 14, "text-anchor": "middle", "font-size": 11 }, `${a}°`));
  }
  for (const v of niceTicks(yMin, yMax)) {
    svg.append(el("line", { x1: L, x2: W - R, y1: y(v), y2: y(v), stroke: "#eef1f4" }));
    svg.append(el("text", { x: L - 4, y: y(v) + 4, "text-anchor": "end", "font-size": 11 }, fmt(v)));
  }
  svg.append(el("text", { x: (L + W - R) / 2, y: H - 4, "text-anchor": "middle", "font-size": 12 }, "stage angle"));
  let k = 0;
  for (const [label, points] of series) {
    const color = COLORS[k % COLORS.length];
    const pts = [...points].sort((p, q) => p[0] - q[0]);
    if (pts.length > 1) {
      svg.append(el("polyline", {
        points: pts.map(([a, v]) => `${x(a).toFixed(1)},${y(v).toFixed(1)}`).join(" "),
        fill: "none", stroke: color, "stroke-width": 1.5,
      }));
    }
    for (const [a, v] of pts) svg.append(el("circle", { cx: x(a), cy: y(v), r: 2.5, fill: color, class: "reading" }));
    svg.append(el("text", { x: W - R + 8, y: T + 14 + 16 * k, "font-size": 11, fill: color }, label));
    k += 1;
  }
  host.replaceChildren(svg);
}

/**
 * Polar plot of a BRDF slice: value against azimuth phi_h, one curve per channel.
 * @param {HTMLElement} host
 * @param {number[]} phiDeg  azimuths, degrees
 * @param {Object<string, number[]>} channels  channel name -> values (same length as phiDeg)
 */
export function plotPolar(host, phiDeg, channels) {
  const S = 320, C = S / 2, Rmax = S / 2 - 24;
  const svg = el("svg", { viewBox: `0 0 ${S} ${S}`, role: "img" });
  const vals = Object.values(channels).flat().filter(Number.isFinite);
  const vMax = vals.length ? Math.max(...vals) : 1;
  const ticks = niceTicks(0, vMax, 3).filter((v) => v > 0);
  const top = Math.max(vMax, ticks.at(-1) ?? vMax) || 1;
  for (const v of ticks) {
    svg.append(el("circle", { cx: C, cy: C, r: (v / top) * Rmax, fill: "none", stroke: "#e1e5ea" }));
    svg.append(el("text", { x: C + 3, y: C - (v / top) * Rmax - 2, "font-size": 10, fill: "#6a737d" }, fmt(v)));
  }
  for (let a = 0; a < 360; a += 45) {
    const r = (a * Math.PI) / 180;
    svg.append(el("line", { x1: C, y1: C, x2: C + Rmax * Math.cos(r), y2: C - Rmax * Math.sin(r), stroke: "#eef1f4" }));
    svg.append(el("text", {
      x: C + (Rmax + 12) * Math.cos(r), y: C - (Rmax + 12) * Math.sin(r) + 4,
      "text-anchor": "middle", "font-size": 10,
    }, `${a}°`));
  }
  const colors = { R: "#d1495b", G: "#2a9d8f", B: "#0b63c5" };
  let k = 0;
  for (const [name, values] of Object.entries(channels)) {
    const pts = phiDeg.map((p, i) => {
      const r = (Math.max(0, values[i]) / top) * Rmax, t = (p * Math.PI) / 180;
      return `${(C + r * Math.cos(t)).toFixed(1)},${(C - r * Math.sin(t)).toFixed(1)}`;
    });
    svg.append(el("polygon", {
      points: pts.join(" "), fill: "none", stroke: colors[name] ?? COLORS[k % COLORS.length], "stroke-width": 1.5,
    }));
    k += 1;
  }
  host.replaceChildren(svg);
}
