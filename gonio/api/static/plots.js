// Plots of the lab page, drawn with the vendored Chart.js (window.Chart, static/vendor/).
// Each function (re)draws one <canvas>; the Chart object is kept on the canvas
// (Chart.getChart(canvas)), so the page and its tests can read what is shown.

/* global Chart */

// 20 colours that stay distinct side by side (a qualitative set without white and the light
// greys), so 20 light/sensor pairs each get their own.
export const PALETTE = [
  "#e6194b", "#3cb44b", "#4363d8", "#f58231", "#911eb4", "#42d4f4", "#f032e6", "#9a6324",
  "#800000", "#469990", "#000075", "#bfef45", "#808000", "#dcbeff", "#ffd8b1", "#aaffc3",
  "#fabed4", "#ffe119", "#a9a9a9", "#000000",
];
// Colour alone does not tell 12 pairs apart for everyone: under a simulated red or green
// deficiency several of the palette's colours nearly coincide (blue and magenta, red and
// brown). Each pair also gets a marker for its readings and a dash for its curve, cycling
// with period 5: pairs that share a marker and dash are 5 apart in the palette, and the 12
// pairs of the default rig then differ by a CIEDE2000 of at least 17 with normal vision and
// under each simulated deficiency (tests/system/api/test_browser_plots.py).
export const POINT_STYLES = ["circle", "triangle", "rect", "rectRot", "star"];
export const DASHES = [[], [8, 4], [2, 3], [10, 3, 2, 3], [4, 2]];

/** The colour, marker and dash of the k-th light/sensor pair. */
export function pairStyle(k) {
  return { color: PALETTE[k % PALETTE.length], point: POINT_STYLES[k % POINT_STYLES.length],
           dash: DASHES[k % DASHES.length] };
}

/**
 * Empty a chart's curves and put `note` in its title, keeping its size and axes: while
 * another job's curves load, the previous job's must not stand under the new heading.
 * @param {HTMLCanvasElement} canvas
 * @param {string} note
 */
export function clearPlot(canvas, note) {
  const chart = Chart.getChart(canvas);
  if (!chart) return;
  chart.data.datasets = [];
  if (chart.options.plugins?.title) {
    chart.options.plugins.title.display = true;
    chart.options.plugins.title.text = note;
  }
  chart.update("none");
}

function fresh(canvas, config) {
  Chart.getChart(canvas)?.destroy();
  return new Chart(canvas, config);
}

function fmt(v) {
  const a = Math.abs(v);
  return a !== 0 && (a < 1e-3 || a >= 1e4) ? v.toExponential(2) : String(+v.toPrecision(4));
}

/**
 * Readings against stage angle, one colour per light/sensor pair; with curves, the
 * reconstruction's curve through each pair's readings in the same colour.
 * @param {HTMLCanvasElement} canvas
 * @param {Array<{label: string, points: Array<[number, number]>, curve?: Array<[number, number]>}>} pairs
 * @param {string} yTitle  axis title with units
 * @param {string} [title]
 */
export function plotRotation(canvas, pairs, yTitle, title = "") {
  // A half-turn scan's readings lie in [0, 180): its axis ends at 180°, not at 360°.
  const xs = pairs.flatMap((p) => p.points.map(([x]) => x));
  const xMax = xs.length && Math.max(...xs) < 180 ? 180 : 360;
  pairs = pairs.map((p) => (p.curve ? { ...p, curve: p.curve.filter(([x]) => x <= xMax) } : p));
  const datasets = [];
  pairs.forEach((p, k) => {
    const { color, point, dash } = pairStyle(k);
    datasets.push({
      label: p.label, type: "scatter", data: p.points.map(([x, y]) => ({ x, y })),
      backgroundColor: color, borderColor: color, pointRadius: 4, pointStyle: point,
      showLine: !p.curve, borderDash: p.curve ? [] : dash, borderWidth: 1, order: 1,
    });
    if (p.curve) {
      datasets.push({
        label: `${p.label} reconstruction`, type: "line", data: p.curve.map(([x, y]) => ({ x, y })),
        borderColor: color, backgroundColor: color, pointRadius: 0, borderWidth: 1.5, order: 2,
        borderDash: dash, isCurve: true,
      });
    }
  });
  return fresh(canvas, {
    type: "scatter",
    data: { datasets },
    options: {
      animation: false, responsive: true, maintainAspectRatio: false, parsing: false,
      plugins: {
        title: { display: Boolean(title), text: title },
        legend: {
          position: "right",
          // The legend shows each pair's marker in its colour.
          labels: { boxWidth: 12, usePointStyle: true, filter: (item, data) => !data.datasets[item.datasetIndex].isCurve },
          // One legend entry per pair: toggling it hides the readings and their curve.
          onClick: (e, item, legend) => {
            const chart = legend.chart, label = chart.data.datasets[item.datasetIndex].label;
            chart.data.datasets.forEach((d, i) => {
              if (d.label === label || d.label === `${label} reconstruction`) {
                chart.setDatasetVisibility(i, !chart.isDatasetVisible(i));
              }
            });
            chart.update();
          },
        },
        tooltip: { callbacks: { label: (c) => `${c.dataset.label}: ${fmt(c.parsed.y)} at ${c.parsed.x.toFixed(1)}°` } },
      },
      scales: {
        x: { type: "linear", min: 0, max: xMax, ticks: { stepSize: xMax === 180 ? 30 : 45, callback: (v) => `${v}°` },
             title: { display: true, text: "specimen angle (degrees)" } },
        y: { type: "linear", beginAtZero: true, grace: "8%", title: { display: true, text: yTitle } },
      },
    },
  });
}

// ------------------------------------------------------------------ polar
const LOG_DECADES = 3;

function niceStep(span) {
  const raw = span / 4, mag = 10 ** Math.floor(Math.log10(raw));
  return [1, 2, 2.5, 5, 10].map((m) => m * mag).find((s) => s >= raw) ?? raw;
}

/**
 * Polar plot of BRDF curves over a half plane: angle from "up", radius the BRDF.
 * @param {HTMLCanvasElement} canvas
 * @param {number[]} angleDeg  -89..89
 * @param {Array<{label: string, values: Array<number|null>, color: string, dash?: number[]}>} curves
 * @param {{log: boolean, units: string, title: string, angleName: string}} opts
 */
export function plotPolar(canvas, angleDeg, curves, opts) {
  const all = curves.flatMap((c) => c.values).filter((v) => Number.isFinite(v) && v > 0);
  const vmax = all.length ? Math.max(...all) : 1;
  const vmin = vmax / 10 ** LOG_DECADES;
  const radius = opts.log
    ? (v) => Math.max(0, Math.log10(Math.max(v, vmin) / vmin))
    : (v) => Math.max(0, v);
  const rings = [];
  if (opts.log) {
    for (let k = Math.ceil(Math.log10(vmin)); k <= Math.floor(Math.log10(vmax)); k++) rings.push(10 ** k);
  } else {
    const step = niceStep(vmax);
    for (let v = step; v <= vmax * 1.0001; v += step) rings.push(+v.toPrecision(10));
  }
  const rmax = Math.max(radius(vmax), ...rings.map(radius)) * 1.05 || 1;
  const datasets = curves.map((c) => ({
    label: c.label, borderColor: c.color, backgroundColor: c.color, borderDash: c.dash ?? [],
    pointRadius: 0, borderWidth: 1.8, showLine: true,
    data: angleDeg.map((a, i) => {
      const v = c.values[i];
      if (!Number.isFinite(v)) return { x: NaN, y: NaN, a, f: null };
      const r = radius(v), t = (a * Math.PI) / 180;
      return { x: r * Math.sin(t), y: r * Math.cos(t), a, f: v };
    }),
  }));
  // The grid's own labels: the angle ticks outside the rim, the ring values along the
  // vertical. Their boxes are kept on the chart ($polarLabels, canvas pixels) so the page's
  // tests can check that no label covers another or the titles.
  const FONT_PX = 11;
  const grid = {
    id: "polarGrid",
    beforeDatasetsDraw(chart) {
      const { ctx, scales: { x, y } } = chart;
      const cx = x.getPixelForValue(0), cy = y.getPixelForValue(0);
      const px = (r) => x.getPixelForValue(r) - cx;
      ctx.save();
      ctx.strokeStyle = "#dde2e8"; ctx.fillStyle = "#6a737d"; ctx.lineWidth = 1;
      ctx.font = `${FONT_PX}px system-ui, sans-serif`;
      ctx.textBaseline = "alphabetic";
      const boxes = [];
      const box = (text, left, baseline) => {
        const m = ctx.measureText(text);
        return { text, left, right: left + m.width, top: baseline - FONT_PX, bottom: baseline + 3 };
      };
      const R = px(rmax);
      const angles = [];
      for (let a = -90; a <= 90; a += 30) {
        const t = (a * Math.PI) / 180;
        ctx.beginPath(); ctx.moveTo(cx, cy); ctx.lineTo(cx + R * Math.sin(t), cy - R * Math.cos(t)); ctx.stroke();
        const text = `${a}°`, w = ctx.measureText(text).width;
        // (±90° sit on the chart area's bottom edge: lifted clear of the legend below it.)
        angles.push(box(text, cx + (R + 10) * Math.sin(t) - w / 2, cy - (R + 4) * Math.cos(t) - (Math.abs(a) === 90 ? 3 : 0)));
      }
      // Each ring's value just above it, beside the vertical: right of the "0°" tick's
      // half-width, as the outermost ring can come within a label's height of the rim.
      const beside = cx + ctx.measureText("0°").width / 2 + 4;
      for (const v of rings) {
        const r = px(radius(v));
        ctx.beginPath(); ctx.arc(cx, cy, r, Math.PI, 2 * Math.PI); ctx.stroke();
        boxes.push(box(fmt(v), beside, cy - r - 3));
      }
      boxes.push(...angles);
      for (const b of boxes) {
        ctx.textAlign = "left";
        ctx.fillText(b.text, b.left, b.bottom - 3);
      }
      chart.$polarLabels = boxes;
      ctx.restore();
    },
  };
  // Equal units per pixel on both axes, or circles would be ellipses: fit the ranges to the
  // chart area once it is laid out (the axes are hidden, so this does not move the layout).
  // The angle ticks are drawn outside the rim, so the rim keeps clear of the area's edges by
  // a tick label's height at the top and its width at the sides: drawn at the very edge, the
  // "0°" tick landed on the subtitle above the chart area.
  const TOP_ROOM = FONT_PX + 8, SIDE_ROOM = 40;
  const square = (chart) => {
    const a = chart.chartArea;
    if (!a || a.right <= a.left || a.bottom <= a.top) return;
    const w = a.right - a.left, h = a.bottom - a.top;
    const rimPx = Math.max(Math.min(w / 2 - SIDE_ROOM, h - TOP_ROOM), 1);
    const perPx = rmax / rimPx;
    const xr = (perPx * w) / 2, yr = perPx * h;
    const sx = chart.options.scales.x, sy = chart.options.scales.y;
    if (Math.abs(sx.max - xr) > 1e-9 * rmax || Math.abs(sy.max - yr) > 1e-9 * rmax) {
      sx.min = -xr; sx.max = xr; sy.max = yr;
      chart.update("none");
    }
  };
  const chart = fresh(canvas, {
    type: "scatter",
    data: { datasets },
    plugins: [grid, { id: "square", afterLayout: (c) => queueMicrotask(() => square(c)) }],
    options: {
      animation: false, responsive: true, maintainAspectRatio: false, parsing: false,
      layout: { padding: 8 },
      plugins: {
        title: { display: true, text: opts.title },
        subtitle: { display: true, text: `radius: BRDF in ${opts.units}${opts.log ? `, log scale over ${LOG_DECADES} decades` : ", linear"}` },
        legend: { position: "bottom", labels: { boxWidth: 14 } },
        tooltip: { callbacks: { label: (c) => `${c.dataset.label}: ${fmt(c.raw.f)} ${opts.units} at ${c.raw.a}° ${opts.angleName}` } },
      },
      scales: {
        x: { type: "linear", min: -rmax, max: rmax, display: false },
        y: { type: "linear", min: 0, max: rmax, display: false },
      },
    },
  });
  return chart;
}
