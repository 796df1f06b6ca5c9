"""The network rules' findings on damaged networks equal the recorded ones (issue 30: the
topology and balise-group rules were made faster, their findings must stay the same).

Each case is a source set — one of the hand-made networks of ``tests/data/networks`` or a
small synthetic network with station layouts (:mod:`fieldlogs.simulate.networks.topology`) — whose CSV
cells are damaged by a seeded generator: one or two cells side by side copied from another row, a
cell blanked (or two cells side by side), a number moved, a row dropped or repeated. The damage is aimed at the network
tables (tracks, connections, switches, track_points, balises), so that every rule of
:mod:`dbtools.rules.topology`, :mod:`dbtools.rules.topology_geometry` and
:mod:`dbtools.rules.balise_groups` fires somewhere. ``db validate`` of each case must give the
findings of ``tests/data/topology_findings/golden.json`` (rule, severity, table, message,
keys, value, limit, file name, row, column; in the same order), recorded by the rules as
they were before the speed-up. Regenerate only when a rule's meaning changes on purpose::

    PYTHONPATH=. python tests/dbtools/test_topology_golden.py --write
"""

from __future__ import annotations

import json
import shutil
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from dbtools.gis.geometry import Projector
from dbtools.network import Network, canonical
from dbtools.sources import write_source_set
from dbtools.validate import validate_path
from fieldlogs.simulate.networks.synthetic import build_network, demo_line
from fieldlogs.simulate.networks.topology import station_network
from schemas.network import NETWORK_TABLES
from schemas.tables import BALISES

DATA = Path(__file__).resolve().parents[1] / "data"
GOLDEN = DATA / "topology_findings" / "golden.json"
HAND_MADE = ("junction", "crossover", "station4", "double_slip")
DAMAGED = ("tracks", "connections", "switches", "track_points", "balises")
#: Damaged variants per network (variant 0 is undamaged).
VARIANTS = 12


def synthetic(folder: Path) -> Path:
    """Two double-track demo lines with a loop pair and a crossover at each station."""
    projector = Projector(9)
    specs = [demo_line("0901", seed=3, length_m=7_000.0), demo_line("0902", seed=4, length_m=7_000.0, x0=20_000.0)]
    net = build_network(specs, projector)
    parts: dict[str, list[pd.DataFrame]] = {t.name: [] for t in NETWORK_TABLES}
    balises = [net.balises]
    for spec in specs:
        tables = station_network(spec, projector)
        balises.append(tables.pop("balises"))
        for name, frame in tables.items():
            parts[name].append(frame)
    net.tables[BALISES.name] = canonical(BALISES, pd.concat(balises, ignore_index=True))
    for t in NETWORK_TABLES:
        net.tables[t.name] = canonical(t, pd.concat(parts[t.name], ignore_index=True))
    return write_source_set(Network(net.tables, meta=net.meta), folder, force=True)


def _damage(frame: pd.DataFrame, rng: np.random.Generator) -> pd.DataFrame:
    """One random edit of a text frame (module doc)."""
    n = len(frame)
    if n == 0:
        return frame
    c = int(rng.integers(len(frame.columns)))
    i, col, cols = int(rng.integers(n)), str(frame.columns[c]), list(frame.columns[c : c + int(rng.integers(1, 3))])
    op = int(rng.integers(6))
    if op == 0:  # one or two cells (a port's track and end, a group's NID_C and NID_BG) from another row
        frame.loc[frame.index[i], cols] = frame[cols].iloc[int(rng.integers(n))].to_numpy()
    elif op == 1:
        frame.loc[frame.index[i], cols] = ""
    elif op == 2:  # a number moved (text cells get a suffix)
        v = frame[col].iloc[i]
        try:
            frame.loc[frame.index[i], col] = repr(round(float(v) + float(rng.normal(0.0, 30.0)), 3))
        except ValueError:
            frame.loc[frame.index[i], col] = f"{v}x" if v else v
    elif op == 3:
        frame = frame.drop(index=frame.index[i])
    elif op == 4:  # a row repeated with one cell from another row
        row = frame.iloc[[i]].copy()
        row[col] = frame[col].iloc[int(rng.integers(n))]
        frame = pd.concat([frame, row], ignore_index=True)
    else:  # two rows' cells of one column swapped
        j = int(rng.integers(n))
        a, b = frame[col].iloc[i], frame[col].iloc[j]
        frame.loc[frame.index[i], col], frame.loc[frame.index[j], col] = b, a
    return frame


def damaged(src: Path, dst: Path, seed: int) -> Path:
    """A copy of source set ``src`` with ``seed``-chosen damage (none for seed 0)."""
    shutil.copytree(src, dst)
    if seed == 0:
        return dst
    rng = np.random.default_rng(seed)
    tables = {
        n: pd.read_csv(dst / f"{n}.csv", dtype=str, keep_default_na=False)
        for n in DAMAGED
        if (dst / f"{n}.csv").exists()
    }
    for _ in range(int(rng.integers(1, 6))):
        name = sorted(tables)[int(rng.integers(len(tables)))]
        tables[name] = _damage(tables[name], rng)
    for name, frame in tables.items():
        frame.to_csv(dst / f"{name}.csv", index=False, lineterminator="\n")
    return dst


def _isolated(tables: dict[str, pd.DataFrame]) -> None:
    """A copy of the first track under a new id, joined to nothing."""
    t = tables["tracks"]
    tables["tracks"] = pd.concat([t, t.iloc[[0]].assign(track_id="LONE")], ignore_index=True)


def _shared_port(tables: dict[str, pd.DataFrame]) -> None:
    """The second switch's A1 port moved to the first switch's A1 track end."""
    s = tables["switches"]
    s.loc[s.index[1], ["a1_track", "a1_end"]] = s[["a1_track", "a1_end"]].iloc[0].to_numpy()


#: Damage the random draws may miss: (network, edit of the text tables).
EDITS = {"isolated": ("junction", _isolated), "shared_port": ("crossover", _shared_port)}


def edited(src: Path, dst: Path, edit: Callable[[dict[str, pd.DataFrame]], None]) -> Path:
    shutil.copytree(src, dst)
    tables = {n: pd.read_csv(dst / f"{n}.csv", dtype=str, keep_default_na=False) for n in ("tracks", "switches")}
    edit(tables)
    for name, frame in tables.items():
        frame.to_csv(dst / f"{name}.csv", index=False, lineterminator="\n")
    return dst


def findings_of(path: Path) -> list[dict[str, Any]]:
    out = []
    for f in validate_path(path):
        d = f.to_dict()
        if "file" in d:
            d["file"] = Path(d["file"]).name
        out.append(d)
    return out


def cases(tmp: Path) -> dict[str, Path]:
    """Case name → damaged source set."""
    sources = {name: DATA / "networks" / name for name in HAND_MADE}
    sources["synthetic"] = synthetic(tmp / "synthetic-src")
    out = {
        f"{name}/{seed}": damaged(src, tmp / f"{name}-{seed}", seed)
        for name, src in sources.items()
        for seed in range(VARIANTS + 1)
    }
    for label, (name, edit) in EDITS.items():
        out[f"{name}/{label}"] = edited(sources[name], tmp / f"{name}-{label}", edit)
    return out


def test_findings_equal_the_recorded_ones(tmp_path: Path) -> None:
    golden = json.loads(GOLDEN.read_text(encoding="utf-8"))
    found = {name: findings_of(path) for name, path in cases(tmp_path).items()}
    assert sorted(found) == sorted(golden)
    for name in golden:
        assert found[name] == golden[name], name


def test_the_damage_reaches_every_network_rule() -> None:
    """The recorded cases exercise the rules they guard (else the comparison proves little)."""
    golden = json.loads(GOLDEN.read_text(encoding="utf-8"))
    rules = {f["rule"] for fs in golden.values() for f in fs}
    want = {
        "topology.invalid_reference",
        "topology.switch_port",
        "topology.navigability",
        "topology.multiple_connections",
        "topology.gap",
        "topology.km_jump",
        "topology.track_length",
        "topology.open_end",
        "topology.balise_position",
        "topology.balise_ambiguous",
        "topology.crossover_angle",
        "topology.switch_open_port",
        "topology.switch_overlap",
        "topology.isolated_track",
        "balise.group_members",
        "balise.group_duplicate",
        "balise.group_fields",
    }
    assert want <= rules, want - rules


if __name__ == "__main__" and sys.argv[1:] == ["--write"]:
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        result = {name: findings_of(path) for name, path in cases(Path(tmp)).items()}
    GOLDEN.parent.mkdir(parents=True, exist_ok=True)
    GOLDEN.write_text(json.dumps(result, indent=1, ensure_ascii=False, sort_keys=True) + "\n", encoding="utf-8")
    print(f"{sum(map(len, result.values()))} findings in {len(result)} cases → {GOLDEN}")
elif __name__ == "__main__":
    pytest.main([__file__])
