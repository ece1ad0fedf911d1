"""`gonio serve --sim` as a process: what it leaves behind on SIGTERM, and what it says when
the address it prints (with the session's API key in it) is reachable from other machines."""

from __future__ import annotations

import signal
from pathlib import Path

import pytest

from tests.system.daemon_proc import start_daemon, wait_for

pytestmark = [pytest.mark.system, pytest.mark.timeout(300)]

EXPOSED = "reachable from other machines"


# is_loopback_host itself: tests/unit/test_daemon.py.


def _sim(tmp_path: Path, *args: str):  # type: ignore[no-untyped-def]
    # No keys configured: the daemon makes a session key and prints it in the address. TMPDIR
    # is this test's folder, so the temporary rig folder is looked for here.
    return start_daemon(["--no-export-fits",
                         "--sim", "--throwaway", "--port", "0", "--time-scale", "10", *args],
                        GONIO_API_KEYS="", TMPDIR=str(tmp_path))


def test_sigterm_removes_the_temporary_rig_folder_and_loopback_gives_no_warning(
    tmp_path: Path,
) -> None:
    d = _sim(tmp_path, "--host", "127.0.0.2")
    try:
        assert d.url.startswith("http://127.0.0.2:")
        folders = list(tmp_path.glob("gonio-serve-*"))
        assert len(folders) == 1 and (folders[0] / "rig.toml").is_file()
    finally:
        status = d.stop(signal.SIGTERM)
    assert status == 0, d.text()
    assert list(tmp_path.glob("gonio-serve-*")) == [], d.text()
    assert "#key=" in d.text() and EXPOSED not in d.text()


def test_a_reachable_address_with_the_key_in_it_comes_with_a_warning(tmp_path: Path) -> None:
    d = _sim(tmp_path, "--host", "0.0.0.0")
    try:
        # stdout and stderr are read by two threads: wait for the warning's line and for the
        # address with the key (it may come after the warning).
        wait_for(lambda: "holds the session's API key" in "".join(d.err)
                 and "#key=" in "".join(d.out), 60, "the warning and the keyed address")
        out, err = "".join(d.out), "".join(d.err)
        assert "#key=" in out
        assert f"warning: --host 0.0.0.0 is {EXPOSED}" in err
        assert "listening on 0.0.0.0: every machine that can reach this address" in err
    finally:
        d.stop()
