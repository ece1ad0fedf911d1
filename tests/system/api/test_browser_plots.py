"""The lab page's plots in headless Chromium (issue 27 item 6): what they draw must be readable.
The plots are drawn by gonio/api/static/plots.js into a canvas of the page served by the real
daemon (tests/system/api/conftest.py), with data given here."""

from __future__ import annotations

from typing import Any

import pytest

from tests.system.api.conftest import Daemon
from tests.system.api.test_browser import _severe, browser, open_live  # noqa: F401 (fixture)

pytestmark = pytest.mark.system

# Draws a polar plot into a fresh canvas of the given CSS size, as the page does, and returns
# the grid's label boxes with the title, subtitle and legend boxes (canvas pixels).
_DRAW_POLAR = """
const [width, height, log, vmax, done] = arguments;
import('/static/plots.js').then((plots) => {
  const box = document.createElement('div');
  box.style.cssText = `position: relative; width: ${width}px; height: ${height}px`;
  const canvas = document.createElement('canvas');
  box.append(canvas); document.body.append(box);
  const angles = [...Array(179).keys()].map((i) => i - 89);
  // A lobe whose maximum is a ring value (vmax), so the outermost ring lies nearest the rim.
  const values = angles.map((a) => vmax * (0.05 + 0.95 * Math.exp(-(((a - 30) / 12) ** 2))));
  const curves = [{label: 'reconstruction', values, color: '#0b63c5'}];
  const chart = plots.plotPolar(canvas, angles, curves, {log, units: '1/sr',
     angleName: 'from the normal', title: 'in-plane BRDF at θi = 30°, φi = 0° (mean of channels)'});
  // The plot squares itself after its first layout: wait for its labels to settle.
  setTimeout(() => {
    const titled = chart.boxes.filter((b) => b.options && typeof b.options.text === 'string'
      && b.options.display).map((b) => ({text: b.options.text, left: b.left, right: b.right,
      top: b.top, bottom: b.bottom}));
    const legend = chart.legend.legendHitBoxes.map((h) => ({text: 'legend entry',
      left: h.left, right: h.left + h.width, top: h.top, bottom: h.top + h.height}));
    const out = {labels: chart.$polarLabels, titles: titled, legend,
      canvas: [chart.width, chart.height]};
    box.remove();
    done(out);
  }, 300);
});
"""


def _overlap(a: dict[str, Any], b: dict[str, Any]) -> bool:
    return bool(a["left"] < b["right"] and b["left"] < a["right"]
                and a["top"] < b["bottom"] and b["top"] < a["bottom"])


@pytest.mark.parametrize(("width", "height", "log", "vmax"), [
    (600, 360, False, 1.0),   # the page at 1280 px: each polar plot half the width
    (600, 360, True, 100.0),
    (320, 360, False, 0.02),  # the narrowest column of the page's polar grid
    (900, 360, False, 5.0),   # one column on a wide window
])
def test_the_polar_plots_labels_cover_neither_each_other_nor_the_titles(
    daemon: Daemon, browser: Any, width: int, height: int, log: bool, vmax: float,  # noqa: F811
) -> None:
    """The "0°" tick sat on the subtitle ("radius: BRDF in 1/sr"), the radius axis' title,
    and the outermost ring's value on the "0°" tick."""
    open_live(browser, daemon, 60)
    browser.set_script_timeout(30)
    got = browser.execute_async_script(_DRAW_POLAR, width, height, log, vmax)
    labels, titles = got["labels"], got["titles"]
    texts = [lab["text"] for lab in labels]
    assert "0°" in texts and "-90°" in texts and "90°" in texts, texts
    assert len(labels) > 7, texts  # the ring values too
    assert any(t["text"].startswith("radius: BRDF in 1/sr") for t in titles), titles
    assert got["legend"], "no legend entry drawn"
    cw, ch = got["canvas"]
    for lab in labels:
        inside = lab["left"] >= 0 and lab["top"] >= 0
        assert inside and lab["right"] <= cw and lab["bottom"] <= ch, (lab, cw, ch)
        for other in [*titles, *got["legend"]]:
            assert not _overlap(lab, other), (lab, other)
    for i, a in enumerate(labels):
        for b in labels[i + 1:]:
            assert not _overlap(a, b), (a, b)
    assert _severe(browser) == []


# Draws the rotation plot of a finished scan with ``n`` pairs (each with its samples and the
# reconstruction's curve) as the page does; returns what each dataset is drawn with.
_DRAW_ROTATION = """
const [n, done] = arguments;
import('/static/plots.js').then((plots) => {
  const box = document.createElement('div');
  box.style.cssText = 'position: relative; width: 900px; height: 340px';
  const canvas = document.createElement('canvas');
  box.append(canvas); document.body.append(box);
  const pairs = [...Array(n).keys()].map((k) => ({
    label: `L${1 + Math.floor(k / 4)}/S${1 + (k % 4)}`,
    points: [0, 22.5, 45, 67.5, 90, 112.5, 135, 157.5].map((a) => [a, 1 + k + Math.sin(a / 30)]),
    curve: [...Array(91).keys()].map((i) => [2 * i, 1 + k + Math.sin(2 * i / 30)]),
  }));
  const chart = plots.plotRotation(canvas, pairs, 'BRDF (1/sr), mean of R, G, B');
  const out = chart.data.datasets.map((d) => ({label: d.label, curve: !!d.isCurve,
    color: d.borderColor, point: d.pointStyle ?? 'circle', dash: d.borderDash ?? [],
    legendPoint: chart.options.plugins.legend.labels.usePointStyle === true}));
  box.remove();
  done(out);
});
"""


def _linear_rgb(hex_colour: str) -> Any:
    import numpy as np

    srgb = np.array([int(hex_colour[i:i + 2], 16) for i in (1, 3, 5)]) / 255.0
    # IEC 61966-2-1 decoding.
    return np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)


def _worst_delta_e(a: str, b: str) -> float:
    """CIEDE2000 between two sRGB colours, the smallest of normal vision and the simulated
    protan, deutan and tritan dichromat (Machado et al. 2009, severity 1)."""
    import warnings

    import numpy as np

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour

        def lab(rgb: Any) -> Any:
            return colour.XYZ_to_Lab(colour.RGB_to_XYZ(
                rgb, colour.RGB_COLOURSPACES["sRGB"], apply_cctf_decoding=False))

        ra, rb = _linear_rgb(a), _linear_rgb(b)
        out = [float(colour.delta_E(lab(ra), lab(rb), method="CIE 2000"))]
        for kind in ("Protanomaly", "Deuteranomaly", "Tritanomaly"):
            m = colour.matrix_cvd_Machado2009(kind, 1.0)
            out.append(float(colour.delta_E(lab(np.clip(m @ ra, 0, 1)),
                                            lab(np.clip(m @ rb, 0, 1)), method="CIE 2000")))
    return min(out)


def test_twelve_pairs_in_the_fit_plot_can_be_told_apart(
    daemon: Daemon, browser: Any,  # noqa: F811
) -> None:
    """The default simulated rig has 3 lights x 4 sensors: 12 pairs in the fit plot. Any two
    pairs' readings differ in marker or in a colour difference a viewer sees (CIEDE2000 of
    10 or more, with normal vision and with a red, green or blue deficiency); so do any two
    curves, in dash or colour. With colour alone, blue and magenta nearly coincide for a red
    or green deficient viewer (CIEDE2000 under 4)."""
    from itertools import combinations

    open_live(browser, daemon, 60)
    browser.set_script_timeout(30)
    sets = browser.execute_async_script(_DRAW_ROTATION, 12)
    dots = [d for d in sets if not d["curve"]]
    curves = [d for d in sets if d["curve"]]
    assert len(dots) == len(curves) == 12
    for a, b in combinations(dots, 2):
        assert a["point"] != b["point"] or _worst_delta_e(a["color"], b["color"]) >= 10, (a, b)
    for a, b in combinations(curves, 2):
        assert a["dash"] != b["dash"] or _worst_delta_e(a["color"], b["color"]) >= 10, (a, b)
    # Each curve goes with its readings: same colour and label.
    for d, c in zip(dots, curves, strict=True):
        assert c["label"] == f"{d['label']} reconstruction" and c["color"] == d["color"]
    # The legend shows the markers, not plain colour boxes.
    assert all(d["legendPoint"] for d in sets)
    assert _severe(browser) == []
