"""The README's "typical session on a real rig", run as written against ``gonio sim``.

The commands are read from README.md (the ```bash block after "A typical session on a real
rig:"), so the README and this test cannot drift apart. Every line runs verbatim in ``bash``
in a fresh folder, with only the substitutions the README itself documents below the block:

* the line copying ``deploy/rig.example.toml`` to the rig config starts
  ``gonio sim --geometry geometry.toml -o <that rig config>`` instead (in the background, for
  the rest of the session; with ``--time-scale 5`` so the simulated motion and exposures take
  a fifth of the time): a simulated rig with the designed devices;
* before a line whose comment says something goes "on the stage", ``gonio sim-place white``
  (the comment names the white reference) or ``gonio sim-place specimen`` does what hands do;
* a line running ``gonio serve`` starts in the background with ``--port 0`` appended (tests
  use free ports); the test waits for its address, checks ``/health`` and stops it.

Then the calibrated scan's values are checked against the simulated material's true BRDF,
computed here from the model (not from gonio's reading path).
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import httpx
import numpy as np
import pytest

from gonio.brdf.tables.geometry import lab_to_specimen
from gonio.calibration import Calibration
from gonio.results import read_result
from gonio.sim.rig import default_material

pytestmark = [pytest.mark.system, pytest.mark.timeout(600)]

README = Path(__file__).resolve().parents[2] / "README.md"
SIM_TIME_SCALE = "5"  # the simulated rig runs 5x faster than real time; nothing else changes


def session_lines(text: str) -> list[str]:
    """The command lines of the README's rig session block."""
    start = text.index("A typical session on a real rig:")
    block = re.search(r"```bash\n(.*?)```", text[start:], re.S)
    assert block is not None, "no ```bash block after 'A typical session on a real rig:'"
    return [line for line in block.group(1).splitlines() if line.strip()]


def split_comment(line: str) -> tuple[str, str]:
    """(command, comment): the comment starts at the first whitespace-'#'-whitespace."""
    m = re.search(r"\s+#\s", line)
    return (line[: m.start()], line[m.end():]) if m else (line, "")


class Background:
    """A background process started here, its output collected by a thread."""

    def __init__(self, argv: list[str], cwd: Path, env: dict[str, str]) -> None:
        self.proc = subprocess.Popen(argv, cwd=cwd, env=env, stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True,
                                     start_new_session=True)
        self.lines: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.append(line.rstrip("\n"))

    def wait_for(self, pattern: str, timeout: float = 120) -> re.Match[str]:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for line in list(self.lines):
                if m := re.search(pattern, line):
                    return m
            if self.proc.poll() is not None:
                time.sleep(0.2)  # let the reader catch the last lines
                break
            time.sleep(0.05)
        raise AssertionError(f"no line matching {pattern!r}:\n" + "\n".join(self.lines))

    def stop(self) -> int | None:
        """SIGTERM to the process group this test started; returns the exit code."""
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGTERM)
            try:
                self.proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait(timeout=10)
        return self.proc.returncode


def test_readme_rig_session_runs_verbatim_against_gonio_sim(tmp_path: Path) -> None:
    lines = session_lines(README.read_text(encoding="utf-8"))
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    sim: Background | None = None
    served = False
    log: list[str] = []
    scan_dirs: list[Path] = []  # the data directories `gonio scan` printed

    def run(command: str) -> str:
        done = subprocess.run(["bash", "-c", command], cwd=tmp_path, env=env, text=True,
                              capture_output=True, timeout=400)
        log.append(f"$ {command}\n{done.stdout}{done.stderr}")
        assert done.returncode == 0, "\n".join(log)
        return done.stdout + done.stderr

    try:
        for line in lines:
            command, comment = split_comment(line)
            cp = re.fullmatch(r"cp \S*rig\.example\.toml (\S+)", command.strip())
            if cp:
                rig = cp.group(1)
                assert sim is None, "the block copies the example rig config twice"
                sim = Background(["gonio", "sim", "--geometry", "geometry.toml",
                                  "--time-scale", SIM_TIME_SCALE, "-o", rig], tmp_path, env)
                sim.wait_for(r"simulated rig running")
                continue
            if "on the stage" in comment:
                assert sim is not None, "a stage step before the rig exists"
                what = "white" if "white reference" in comment else "specimen"
                run(f"gonio sim-place {what} --rig rig.toml")
            if re.search(r"(^|[\s;&|])gonio serve\b", command):
                daemon = Background(["bash", "-c", f"{command} --port 0"], tmp_path, env)
                try:
                    url = daemon.wait_for(r"gonio serving on (http://\S+)").group(1)
                    health = httpx.get(url + "health", timeout=30)
                    assert health.status_code == 200, health.text
                    # The calibration made with `gonio scan --white-reference` in the morning
                    # is the one the daemon applies: one data directory per rig.
                    cal = httpx.get(url + "api/v1/calibration", timeout=30).json()
                    assert "white reference" in cal["source"] and cal["pairs"], cal
                finally:
                    daemon.stop()
                # The signal also reaches the wrapping bash; what matters is the daemon's own
                # clean shutdown.
                out = "\n".join(daemon.lines)
                assert "Traceback" not in out and "Application shutdown complete" in out, out
                # It says where its jobs and results go: with no data_dir configured, the
                # rig's own, the one `gonio scan` printed; and that its scans are calibrated.
                assert scan_dirs, "no gonio scan ran before the daemon"
                assert f"data directory {scan_dirs[-1].resolve()}" in out, out
                assert re.search(r"calibration: job \d+: white reference, 10 pairs", out), out
                served = True
                continue
            said = re.search(r"^data directory (\S+) \(job store", run(command), re.M)
            if said:
                scan_dirs.append(Path(said.group(1)))
    finally:
        if sim is not None:
            sim.stop()
    assert sim is not None and served, "the block lost its rig config or daemon step"

    # The calibrated scan: the one written after the white-reference step.
    outputs = [re.search(r"-o (\S+\.h5)", line) for line in lines]
    scans = [m.group(1) for m in outputs if m is not None]
    assert len(scans) >= 2, scans
    res = read_result(tmp_path / scans[-1])
    s = res.samples
    cal = Calibration.model_validate(s.calibration)
    assert cal.reference_albedo == pytest.approx(0.99) and cal.pairs
    assert len(s.pairs) == 10  # the design's pairs, through apply-design
    alpha = np.deg2rad(s.stage_angles_deg)[None, :]
    wi = lab_to_specimen(np.asarray(s.light_dirs)[:, None, :], alpha)
    wo = lab_to_specimen(np.asarray(s.sensor_dirs)[:, None, :], alpha)
    truth = default_material().eval(wi.reshape(-1, 3), wo.reshape(-1, 3)).reshape(s.values.shape)
    # In 1/sr: the specimen's BRDF up to the simulated sensor noise.
    rel = np.abs(s.values - truth) / np.maximum(truth, 0.05 * truth.max())
    assert float(np.median(rel)) < 0.03, float(np.median(rel))
    assert float(np.quantile(rel, 0.9)) < 0.10
    # The scan of the `gonio sim` rig records the simulated material (gonio render's truth
    # row, as the README says of simulated scans): the very BRDF the simulator replays.
    from gonio.figures import true_material

    recorded = true_material(res)
    assert recorded is not None, res.provenance
    assert np.allclose(recorded.eval(wi.reshape(-1, 3), wo.reshape(-1, 3)).reshape(truth.shape),
                       truth)
    # The specimen is named after the result file (-o felt.h5), not "specimen".
    jobs = subprocess.run(["gonio", "jobs", "list", "--json", "--db",
                           str(scan_dirs[-1] / "gonio.sqlite")], env=env, text=True,
                          capture_output=True, check=True)
    specimens = [j["specimen"] for j in json.loads(jobs.stdout)]
    stem = Path(scans[-1]).stem
    assert specimens[-1] == stem, specimens
