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
