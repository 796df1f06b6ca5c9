"""``bench/run_breakdown.py``'s stage list: every entry names a callable of today's pipeline,
and a stale one stops the script naming it (issue 34: ``run_aids`` had moved out of
``fieldlogs.pipeline.run`` and the script died with an AttributeError)."""

from __future__ import annotations

from typing import Any

import pytest

from tests.bench.scripts import load_script

rb = load_script("run_breakdown")


def test_every_wrapped_stage_resolves() -> None:
    resolved = rb.resolve_all(rb.WRAPPED)
    assert [r.stage for r in resolved] == list(rb.WRAPPED)
    assert all(callable(r.target) for r in resolved)


def test_labels_are_unique() -> None:
    labels = [s.label for s in rb.WRAPPED]
    assert len(labels) == len(set(labels))


@pytest.mark.parametrize(
    ("module", "attr", "named"),
    [
        ("fieldlogs.pipeline.run", "run_aids", "has no attribute 'run_aids'"),
        ("fieldlogs.pipeline.gone", "run_aids", "module 'fieldlogs.pipeline.gone' not importable"),
        ("fieldlogs.pipeline.run", "NoSuchUnit.for_run", "has no attribute 'NoSuchUnit'"),
        ("fieldlogs.pipeline.run", "STREAMS", "not callable"),
    ],
)
def test_a_stale_stage_stops_the_script_naming_it(module: str, attr: str, named: str) -> None:
    good = rb.Stage("fieldlogs.pipeline.run", "summarise", "summary")
    stale = rb.Stage(module, attr, "the stale one")
    with pytest.raises(SystemExit) as exc:
        rb.resolve_all([good, stale])
    message = str(exc.value.code)
    assert f"{module}.{attr}" in message and named in message and "'the stale one'" in message
    assert "summarise" not in message


class Probe:
    """A class whose methods the wrapper must keep callable as they were."""

    def __init__(self, k: int) -> None:
        self.k = k

    def times(self, x: int) -> int:
        return self.k * x

    @classmethod
    def make(cls, k: int) -> Probe:
        return cls(k)

    @staticmethod
    def twice(x: int) -> int:
        return 2 * x


@pytest.mark.parametrize("attr", ["Probe.times", "Probe.make", "Probe.twice"])
def test_wrapped_methods_keep_their_binding_and_count_calls(attr: str, monkeypatch: pytest.MonkeyPatch) -> None:
    name = attr.split(".")[1]
    monkeypatch.setattr(Probe, name, Probe.__dict__[name])  # restored after the test
    label = f"probe {name}"
    rb._wrap(rb.resolve(rb.Stage(__name__, attr, label)))
    calls: dict[str, Any] = {
        "times": lambda: Probe(3).times(2) == 6,
        "make": lambda: Probe.make(4).k == 4 and Probe(1).make(5).k == 5,
        "twice": lambda: Probe.twice(3) == 6 and Probe(1).twice(4) == 8,
    }
    before = rb._calls[label]
    assert calls[name]()
    assert rb._calls[label] > before
    assert rb._phases[-1][0] == label
