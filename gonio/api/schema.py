"""The committed OpenAPI schema (``gonio/api/openapi.json``) and how to regenerate it.

The schema is part of gonio's public interface: clients are generated from it. A test compares
the app's live schema with the committed file, so any change to the API is a deliberate,
reviewed change of that file. Regenerate after changing the API on purpose::

    python -m gonio.api.schema --write
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any, cast

SCHEMA_FILE = Path(__file__).with_name("openapi.json")


def current_schema() -> dict[str, Any]:
    """The OpenAPI document of the app as the code defines it now."""
    from gonio.api.app import create_app
    from gonio.service import GonioService

    # Building the schema touches no service method: routes are inspected, never called.
    app = create_app(cast(GonioService, object()), manage_service=False)
    return app.openapi()


def render(schema: dict[str, Any]) -> str:
    """Stable text form: sorted keys, two-space indent, trailing newline (small diffs)."""
    return json.dumps(schema, indent=2, sort_keys=True, ensure_ascii=False) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m gonio.api.schema", description=__doc__)
    parser.add_argument("--write", action="store_true", help=f"write {SCHEMA_FILE.name}")
    args = parser.parse_args(argv)
    text = render(current_schema())
    if args.write:
        SCHEMA_FILE.write_text(text, encoding="utf-8")
        print(f"wrote {SCHEMA_FILE}")
    else:
        print(text, end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
