"""The ``--line-code`` map of ``db import``: railML lines and tracks → our line codes and
tracks, and which balise groups are initial pairs.

A TOML file::

    metric_crs = "EPSG:3067"             # optional: copied into the source set's network.toml

    [lines."line_007_28_47"]             # a railML line (2.x trackGroups/line, 3.x lines/line) by id
    line_code = "007"
    track = "S"                          # U, D or S for every track of the line (default S)
    name = "Rata 007"                    # optional (default: the railML name)

    [tracks."x.x.xxx.LIVI.INFRA.41.1000283158071"]   # one railML track / netElement, overriding its line
    line_code = "007"
    track = "D"

    [initial_pairs]                      # balise group (3.x baliseGroup id, or any of its balises' ids)
    "bg_12" = "05"                       #   → station code of the initial pair it is

Without a map a railML line becomes line code = its ``@code`` (else its id), track S, and a
track in no line is not imported (its elements are reported). Our own railML export carries
line code and track on each netElement (``tpos:lineCode``, ``tpos:track``): used when the
map does not say otherwise.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from dbtools.inputs import not_special
from dbtools.interchange.model import RailmlDoc
from schemas.enums import Track
from schemas.errors import InputError

TRACKS = tuple(t.value for t in Track)


@dataclass(frozen=True)
class Target:
    line_code: str
    track: str


@dataclass
class LineMap:
    lines: dict[str, dict[str, str]] = field(default_factory=dict)
    tracks: dict[str, dict[str, str]] = field(default_factory=dict)
    initial_pairs: dict[str, str] = field(default_factory=dict)
    metric_crs: str | None = None
    path: str | None = None


def _table(data: dict[str, Any], key: str, path: Path) -> dict[str, dict[str, str]]:
    raw = data.get(key, {})
    if not isinstance(raw, dict):
        raise InputError(f"[{key}] must be a table", path=path)
    out: dict[str, dict[str, str]] = {}
    for ident, spec in raw.items():
        if not isinstance(spec, dict) or "line_code" not in spec:
            raise InputError(f'[{key}."{ident}"] needs line_code', path=path)
        track = str(spec.get("track", Track.SINGLE.value))
        if track not in TRACKS:
            raise InputError(f"[{key}.\"{ident}\"] track '{track}' is not one of {', '.join(TRACKS)}", path=path)
        unknown = set(spec) - {"line_code", "track", "name"}
        if unknown:
            raise InputError(f'[{key}."{ident}"] unknown key(s) {", ".join(sorted(unknown))}', path=path)
        out[str(ident)] = {k: str(v) for k, v in spec.items()} | {"track": track}
    return out


def read_map(path: Path | None) -> LineMap:
    """The map (empty without a file); InputError naming the file and key on anything unusable."""
    if path is None:
        return LineMap()
    path = not_special(Path(path), "--line-code map (TOML)")
    if not path.is_file():
        raise InputError("no such file (the --line-code map)", path=path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8-sig"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise InputError(f"not a valid TOML map: {exc}", path=path) from exc
    unknown = set(data) - {"lines", "tracks", "initial_pairs", "metric_crs"}
    if unknown:
        raise InputError(
            f"unknown key(s) {', '.join(sorted(unknown))} (lines, tracks, initial_pairs, metric_crs)", path=path
        )
    pairs = data.get("initial_pairs", {})
    if not isinstance(pairs, dict):
        raise InputError("[initial_pairs] must be a table of group id = station code", path=path)
    crs = data.get("metric_crs")
    return LineMap(
        _table(data, "lines", path),
        _table(data, "tracks", path),
        {str(k): str(v) for k, v in pairs.items()},
        None if crs is None else str(crs),
        str(path),
    )


def resolve(doc: RailmlDoc, lmap: LineMap) -> dict[str, Target]:
    """railML track id → our (line code, track), for every track that can be placed."""
    out: dict[str, Target] = {}
    for tid, t in doc.tracks.items():
        spec = lmap.tracks.get(tid)
        if spec is None and t.line_id is not None:
            spec = lmap.lines.get(t.line_id)
        if spec is not None:
            out[tid] = Target(spec["line_code"], spec["track"])
            continue
        line = doc.lines.get(t.line_id or "")
        code = t.ext.get("lineCode") or (line.code or line.id if line is not None else None)
        if code is not None:
            track = t.ext.get("track", Track.SINGLE.value)
            out[tid] = Target(code, track if track in TRACKS else Track.SINGLE.value)
    return out


def line_names(doc: RailmlDoc, lmap: LineMap, targets: dict[str, Target]) -> dict[str, dict[str, str | None]]:
    """line_code → {name, attributes} from the map or the railML lines."""
    out: dict[str, dict[str, str | None]] = {}
    for tid, target in sorted(targets.items()):
        line = doc.lines.get(doc.tracks[tid].line_id or "")
        spec = lmap.lines.get(line.id, {}) if line is not None else {}
        name = spec.get("name") or (line.name if line is not None else None)
        attrs = line.ext.get("attributes") if line is not None else None
        entry = out.setdefault(target.line_code, {"name": None, "attributes": None})
        entry["name"] = entry["name"] or name
        entry["attributes"] = entry["attributes"] or attrs
    return out
