"""``GET /api/v1/jobs/{id}/colour?against=`` takes a stored standard by name, as a lab keeps
its standards: colour CSVs (``gonio colour --csv`` or the route's ``format=csv``) in the data
directory's ``standards/`` folder. It took job ids only. The spectral rig and its two scans of
the blue panel are tests/system/api/test_browser_colour.py's (no browser here)."""

from __future__ import annotations

import pytest

from tests.system.api.test_browser_colour import (  # noqa: F401 (fixtures)
    _SpectralLab,
    spectral_jobs,
    spectral_lab,
)

pytestmark = [pytest.mark.system, pytest.mark.timeout(600)]


def test_against_takes_a_stored_standard_by_name_and_names_an_unknown_or_unreadable_one(
    spectral_lab: _SpectralLab, spectral_jobs: list[int],  # noqa: F811
) -> None:
    d = spectral_lab.serve(None)
    first, second = spectral_jobs
    folder = d.data_dir / "standards"
    folder.mkdir(exist_ok=True)
    with d.client() as c:
        # The first panel's colour table, kept as the lab's standard.
        table = c.get(f"/api/v1/jobs/{first}/colour", params={"format": "csv"})
        assert table.status_code == 200, table.text
        (folder / "blue master.csv").write_text(table.text, encoding="utf-8")

        by_job = c.get(f"/api/v1/jobs/{second}/colour", params={"against": first})
        assert by_job.status_code == 200, by_job.text
        by_name = c.get(f"/api/v1/jobs/{second}/colour", params={"against": "blue master"})
        assert by_name.status_code == 200, by_name.text
        diff = by_name.json()["difference"]
        assert diff["against"] == "blue master" and diff["standard"] == "blue master"
        # The same standard through the job and through its stored table: the same
        # differences, up to the CSV's rounding of L*, a*, b*.
        rows_job = {(r["instrument"], r["aspecular_deg"], r["azimuth_deg"]): r["dE00"]
                    for r in by_job.json()["difference"]["rows"]}
        rows_name = {(r["instrument"], r["aspecular_deg"], r["azimuth_deg"]): r["dE00"]
                     for r in diff["rows"]}
        assert rows_name.keys() == rows_job.keys() and rows_name
        for k, de in rows_job.items():
            assert rows_name[k] == pytest.approx(de, abs=0.01), k
        # Against another scan, the near-specular geometries neither scan's pairs read are
        # named (both values are the reconstruction's guess); a stored standard was
        # measured, so nothing is said against it. Which geometries: from each side's own
        # "measured" flags and angles, as docs/colour.md defines near-specular.
        from gonio.result_colour import NEAR_SPECULAR_DEG

        def unread_near(job: int) -> set[str]:
            col = c.get(f"/api/v1/jobs/{job}/colour").json()["colour"]
            return {f"{r['incidence_deg']:g}as{r['aspecular_deg']:g}"
                    for r, m in zip(col["rows"], col["measured"], strict=True)
                    if not m and abs(r["aspecular_deg"]) <= NEAR_SPECULAR_DEG}

        both = unread_near(first) & unread_near(second)
        assert both, "the blue panel's scans leave near-specular geometries to the table"
        shared = [n for n in by_job.json().get("notes", []) if "both sides' colour" in n]
        assert len(shared) == 1, by_job.json().get("notes")
        named = set(shared[0].split(" both sides'")[0].removeprefix("at ").split(", "))
        assert named == both, (named, both)
        assert not any("both sides' colour" in n for n in by_name.json().get("notes", []))
        # A panel against its own stored colour: no difference (".csv" may be given).
        own = c.get(f"/api/v1/jobs/{first}/colour", params={"against": "blue master.csv"})
        assert own.status_code == 200, own.text
        assert own.json()["difference"]["max_dE00"] < 0.01

        unknown = c.get(f"/api/v1/jobs/{second}/colour", params={"against": "green master"})
        assert unknown.status_code == 404, unknown.text
        said = unknown.json()["detail"]
        assert "no stored colour standard 'green master'" in said, said
        assert "it holds blue master" in said and "gonio colour RESULT.h5 --csv" in said, said
        # A name is a file of standards/ only, never a path.
        outside = c.get(f"/api/v1/jobs/{second}/colour", params={"against": "../gonio"})
        assert outside.status_code == 404, outside.text

        (folder / "torn.csv").write_text("patch,value\n1,2\n", encoding="utf-8")
        torn = c.get(f"/api/v1/jobs/{second}/colour", params={"against": "torn"})
        assert torn.status_code == 422, torn.text
        assert "torn.csv: columns" in torn.json()["detail"], torn.json()


def test_a_standard_is_stored_listed_and_refused_through_the_api_losing_nothing(
    spectral_lab: _SpectralLab, spectral_jobs: list[int],  # noqa: F811
) -> None:
    """``PUT /api/v1/colour-standards/{name}`` keeps a colour CSV as a stored standard and
    ``GET /api/v1/colour-standards`` lists them: a lab saves its master's colour from the
    page or a script instead of copying files into the data directory."""
    d = spectral_lab.serve(None)
    first, second = spectral_jobs
    with d.client() as c:
        # (The data directory is shared with the test above, which copied some in by hand.)
        before = set(c.get("/api/v1/colour-standards").json()["standards"])
        assert "panel master" not in before
        table = c.get(f"/api/v1/jobs/{first}/colour", params={"format": "csv"}).text
        put = c.put("/api/v1/colour-standards/panel master", content=table,
                    headers={"Content-Type": "text/csv"})
        assert put.status_code == 200, put.text
        stored = put.json()
        assert stored["name"] == "panel master" and stored["replaced"] is False
        # As many geometries as the table has rows (the header aside).
        assert stored["geometries"] == len(table.strip().splitlines()) - 1
        assert set(c.get("/api/v1/colour-standards").json()["standards"]) == before | {
            "panel master"}
        # The file is the one a lab would have copied there by hand.
        assert (d.data_dir / "standards" / "panel master.csv").read_text() == table
        # The panel against its own stored colour: no difference.
        own = c.get(f"/api/v1/jobs/{first}/colour", params={"against": "panel master"})
        assert own.json()["difference"]["max_dE00"] < 0.01

        # Refused, and the standard stored before is kept as it was.
        for name, body, said in (
                ("panel master", "patch,value\n1,2\n", "standard 'panel master': columns"),
                ("panel master", "", "no rows"),
                ("..", table, "cannot name a stored standard"),
                (".hidden", table, "cannot name a stored standard")):
            bad = c.put(f"/api/v1/colour-standards/{name}", content=body,
                        headers={"Content-Type": "text/csv"})
            assert bad.status_code in (404, 422), (name, bad.text)
            if bad.status_code == 422:
                assert said in bad.json()["detail"], (name, bad.json())
        assert (d.data_dir / "standards" / "panel master.csv").read_text() == table
        assert set(c.get("/api/v1/colour-standards").json()["standards"]) == before | {
            "panel master"}

        # Replaced by the second panel's colour: said, and compared with from then on.
        other = c.get(f"/api/v1/jobs/{second}/colour", params={"format": "csv"}).text
        again = c.put("/api/v1/colour-standards/panel master.csv", content=other,
                      headers={"Content-Type": "text/csv"})
        assert again.status_code == 200 and again.json()["replaced"] is True, again.text
        assert c.get(f"/api/v1/jobs/{second}/colour", params={"against": "panel master"}
                     ).json()["difference"]["max_dE00"] < 0.01
        # Storing needs the write key.
        anon = d.client(None).put("/api/v1/colour-standards/x", content=table,
                                        headers={"Content-Type": "text/csv"})
        assert anon.status_code == 401, anon.text


def test_a_stored_standard_is_deleted_by_name_and_an_unknown_name_is_a_404_naming_the_others(
    spectral_lab: _SpectralLab, spectral_jobs: list[int],  # noqa: F811
) -> None:
    """``DELETE /api/v1/colour-standards/{name}``: a lab removes a standard it no longer
    uses (a mistyped name, an old master) without reaching into the data directory."""
    d = spectral_lab.serve(None)
    first, _ = spectral_jobs
    stored = d.data_dir / "standards" / "old master.csv"
    with d.client() as c:
        table = c.get(f"/api/v1/jobs/{first}/colour", params={"format": "csv"}).text
        put = c.put("/api/v1/colour-standards/old master", content=table,
                    headers={"Content-Type": "text/csv"})
        assert put.status_code == 200 and stored.is_file(), put.text
        # Removing needs the write key; refused, nothing is removed.
        anon = d.client(None).delete("/api/v1/colour-standards/old master")
        assert anon.status_code == 401 and stored.is_file(), anon.text
        gone = c.delete("/api/v1/colour-standards/old master.csv")
        assert gone.status_code == 204, gone.text
        assert not stored.exists()
        assert "old master" not in c.get("/api/v1/colour-standards").json()["standards"]
        against = c.get(f"/api/v1/jobs/{first}/colour", params={"against": "old master"})
        assert against.status_code == 404, against.text
        # Twice, or a name never stored: 404 saying so, what is stored, and what to do.
        held = c.get("/api/v1/colour-standards").json()["standards"]
        for name in ("old master", "..gonio"):
            again = c.delete(f"/api/v1/colour-standards/{name}")
            assert again.status_code == 404, (name, again.text)
            said = again.json()["detail"]
            assert f"no stored colour standard {name!r}" in said, said
            assert (f"it holds {', '.join(held)}" if held else "it holds none") in said, said
            assert "nothing was removed" in said and "GET /api/v1/colour-standards" in said
