"""Regenerate README's schema section from ``schemas/``: ``python -m cli.schema_docs``."""

from __future__ import annotations

from pathlib import Path

from cli.schema import schema_markdown
from schemas import ALL_SCHEMAS

BEGIN, END = "<!-- schemas:begin -->", "<!-- schemas:end -->"
README = Path(__file__).resolve().parent.parent / "README.md"


def schemas_markdown() -> str:
    return "\n\n".join(schema_markdown(t) for t in ALL_SCHEMAS.values())


def with_schemas(readme: str) -> str:
    head, rest = readme.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    return f"{head}{BEGIN}\n{schemas_markdown()}\n{END}{tail}"


def main() -> None:
    README.write_text(with_schemas(README.read_text(encoding="utf-8")), encoding="utf-8")


if __name__ == "__main__":
    main()
