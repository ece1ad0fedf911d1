"""What a ``gonio`` process imports before it does anything: no SciPy.

Every ``gonio`` command builds the whole parser (each command module registers itself), and
``gonio serve`` imports the API app; SciPy (about 0.4 s of CPU) loads with the first fit or
interpolation instead, which many daemons and commands never reach (a refusal, a calibration
job, ``gonio rig lights-off``). The deferred imports themselves run in every test of
``joint.solve_joint`` and ``periodic.periodic_pchip_rows`` (tests/unit/brdf/reconstruction/).
"""

from __future__ import annotations

import subprocess
import sys


def test_the_daemon_and_the_cli_start_without_scipy() -> None:
    code = (
        "import sys\n"
        "import gonio.api.app, gonio.daemon, gonio.cli.serve_command, gonio.cli.sim_session\n"
        "import gonio.sim.rig\n"
        "from gonio.cli import build_parser\n"
        "build_parser()\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] == 'scipy'))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=120).stdout
    assert out.strip() == "[]"

