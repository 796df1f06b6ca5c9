"""Regenerate README's schema section from ``schemas/``: ``python -m cli.schema_docs``."""

from __future__ import annotations

from pathlib import Path

from cli.schema import schema_markdown
from schemas.catalog import ALL_SCHEMAS
from schemas.enums import ALARM_MEANING, EVENT_MEANING, AlarmType

BEGIN, END = "<!-- schemas:begin -->", "<!-- schemas:end -->"
EVENTS_BEGIN, EVENTS_END = "<!-- events:begin -->", "<!-- events:end -->"
README = Path(__file__).resolve().parent.parent / "README.md"


def schemas_markdown() -> str:
    return "\n\n".join(schema_markdown(t) for t in ALL_SCHEMAS.values())


def events_markdown() -> str:
    """The event types of ``events`` and the possession alarms and notices (schemas/enums.py)."""
    rows = ["| event type | what it means |", "|---|---|"]
    rows += [f"| `{t}` | {m} |" for t, m in EVENT_MEANING.items()]
    rows += ["", "| possession alarm / notice | what it means |", "|---|---|"]
    rows += [f"| `{t}` ({'alarm' if isinstance(t, AlarmType) else 'notice'}) | {m} |" for t, m in ALARM_MEANING.items()]
    return "\n".join(rows)


def _between(readme: str, begin: str, end: str, body: str) -> str:
    head, rest = readme.split(begin, 1)
    _, tail = rest.split(end, 1)
    return f"{head}{begin}\n{body}\n{end}{tail}"


def with_schemas(readme: str) -> str:
    """README with its generated sections (schemas, event types) rebuilt."""
    readme = _between(readme, BEGIN, END, schemas_markdown())
    return _between(readme, EVENTS_BEGIN, EVENTS_END, events_markdown())


def main() -> None:
    README.write_text(with_schemas(README.read_text(encoding="utf-8")), encoding="utf-8")


if __name__ == "__main__":
    main()
