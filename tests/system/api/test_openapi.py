"""The committed OpenAPI schema matches the app: API changes are deliberate."""

from __future__ import annotations

import json

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
