"""The committed OpenAPI schema matches the app: API changes are deliberate; and the
regeneration command writes it in its canonical form."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from gonio.api import schema
from gonio.api.schema import SCHEMA_FILE, current_schema, render


def test_committed_schema_matches_the_app() -> None:
    live = current_schema()
    committed = json.loads(SCHEMA_FILE.read_text(encoding="utf-8"))
    if committed != live:
        added = sorted(set(live["paths"]) - set(committed["paths"]))
        removed = sorted(set(committed["paths"]) - set(live["paths"]))
        raise AssertionError(
            "the app's OpenAPI schema differs from gonio/api/openapi.json "
            f"(paths added: {added or 'none'}, removed: {removed or 'none'}; other changes "
            "possible). If the API change is intended, regenerate the file with\n"
            "    python -m gonio.api.schema --write\n"
            "and mention the change in docs/api.md."
        )
    assert SCHEMA_FILE.read_text(encoding="utf-8") == render(committed), (
        "gonio/api/openapi.json is not in canonical form; regenerate it with "
        "python -m gonio.api.schema --write"
    )


def test_every_mutation_is_keyed_and_documents_its_errors() -> None:
    schema = current_schema()
    for path, ops in schema["paths"].items():
        for method, op in ops.items():
            if method in ("post", "put", "delete", "patch"):
                assert op.get("security"), f"{method.upper()} {path} has no API key requirement"


def test_every_operation_documents_the_errors_it_can_answer_with() -> None:
    """What the guards and parameters of a route imply is in its schema, with a JSON body
    (the fuzzer checks the server against these; this checks they are there at all)."""
    schema = current_schema()
    refs = {"ErrorBody", "ValidationErrorBody"}
    assert refs <= set(schema["components"]["schemas"])
    for path, ops in schema["paths"].items():
        for method, op in ops.items():
            responses = op["responses"]
            where = f"{method.upper()} {path}"
            if op.get("security"):
                assert {"401", "403"} <= set(responses), where
            if method in ("post", "put", "delete") and "requestBody" in op:
                assert {"413", "422"} <= set(responses), where
            if "{job_id}" in path:
                assert "404" in responses, where
            if method != "get" and path.startswith("/api/v1/jobs") and path != \
                    "/api/v1/jobs/dry-run":
                assert "423" in responses, f"{where}: a change refused under the lock"
            for status, resp in responses.items():
                if int(status) < 400:
                    continue
                body = resp["content"]["application/json"]["schema"]["$ref"]
                if status not in ("401", "403", "404", "413", "422", "423"):
                    continue  # a route's own answer (e.g. /health's 503 is a Health body)
                want = "ValidationErrorBody" if status == "422" else "ErrorBody"
                assert body == f"#/components/schemas/{want}", (where, status, body)
    dry = schema["paths"]["/api/v1/jobs/dry-run"]["post"]
    assert dry.get("security") and "423" not in dry["responses"]


def test_render_is_sorted_two_space_json_with_a_final_newline() -> None:
    assert render({"b": [1, {"d": "é", "c": None}], "a": 1}) == (
        '{\n  "a": 1,\n  "b": [\n    1,\n    {\n      "c": null,\n      "d": "é"\n    }\n'
        '  ]\n}\n')


def test_the_command_prints_or_writes_the_schema(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    target = tmp_path / "openapi.json"
    monkeypatch.setattr(schema, "SCHEMA_FILE", target)
    assert schema.main([]) == 0
    printed = capsys.readouterr().out
    assert not target.exists() and json.loads(printed)["info"]["title"] == "gonio"
    assert schema.main(["--write"]) == 0
    assert target.read_text(encoding="utf-8") == printed
    assert f"wrote {target}" in capsys.readouterr().out
