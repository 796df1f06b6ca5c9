"""Network topology rules (SPEC §8.1; RailTopoModel netElements/netRelations, railML 3
``switchIS``, OSRD switch ports): tracks, connections, switches and track_points.

Tracks are :func:`dbtools.topology.all_tracks` (declared plus implied line tracks). A
*port* is the track end a switch names in ``a1/b1/b2/a2`` (:data:`schemas.network.SWITCH_PORTS`
per type); the *routes* of a switch are :data:`schemas.network.SWITCH_ROUTES`. Every rule
is vectorised over the whole network (merges and group-bys, no per-track loop).

* ``topology.invalid_reference`` (error) — a connection, switch port, track_points row or
  balise names a track id that does not exist, or a connection a switch_id that does not.
  Fix: correct the id, or add the track/switch.
* ``topology.switch_port`` (error) — a port a switch of its type needs is empty; a port no
  connection of that switch reaches (unused); one track end at two ports of a switch (used
  twice); a connection naming a switch at a track end that is none of its ports. Fix: make
  the ports and the switch's connections name the same track ends.
* ``topology.navigability`` (error) — at a switch, a route (toe↔branch of a point switch,
  A1–B1/A2–B2 and the slips' A1–B2/A2–B1) without a connection or with navigability
  ``none``, or a pair of ports that is no route (branch↔branch) navigable. Fix: the
  connection's navigability (convention: routes ``both``, other pairs ``none``).
* ``topology.multiple_connections`` (error) — a track end with more than one connection where
  not all of them pass a switch: without a switch a train cannot leave an end two ways.
  Fix: add the switch (and its switch_id), or remove the extra connection.
* ``topology.switch_overlap`` (error) — two switches share a port, or are joined by a track
  shorter than ``switch_min_spacing_m`` (their turnouts would overlap). Fix: the port or
  track lengths; a double slip is one switch of type ``double_slip``, not two.
* ``topology.gap`` (error) — the coordinates of two joined ends are more than
  ``connection_gap_m`` apart (:mod:`dbtools.rules.track_geometry`). Fix: the end (begin/end)
  of the connection, the track's km range or its centreline.
* ``topology.km_jump`` (error) — two tracks of one line whose km at the joined ends differ by
  more than ``km_jump_m`` and no ``km_breaks`` row of that line goes from one km to the
  other. Fix: the tracks' km, or a ``km_breaks`` row.
* ``topology.track_length`` (error) — ``length_m`` differs from the length of the
  centreline by more than max(``length_tolerance_m``, ``length_tolerance_rel`` × length).
  Fix: ``length_m`` (it is what dead reckoning measures on the track).
* ``topology.crossover_angle`` (warning) — the largest angle between a crossover's chords
  and the main track at a switch end, divided by the frog angle atan(1/n) of that switch, is
  outside ``crossover_angle_range`` [S001 §8(c)]. Fix: the switch number or the crossover's
  track_points.
* ``topology.open_end`` (warning) — a connected track's end has no connection and no buffer
  stop (``tracks.begin_buffer_stop``/``end_buffer_stop``): an end of a track along a line
  that is the end of its line's GIS grid is the network's boundary and is not reported; any
  other open end (a missing connection, an unrecorded buffer stop) is named so that a person
  decides. Fix: add the connection, or record the buffer stop.
* ``topology.switch_open_port`` (warning) — a switch's branch port (B1, B2) is empty: the
  branch leads out of the DB (an extract's edge, e.g. the Finnish railML file's switches).
  Fix: import the neighbouring tracks, or accept it at the edge of the network.
* ``topology.isolated_track`` (warning) — a declared track with no connection at all in a
  network that has connections. Fix: connect it, or remove it.

Balise rules that need the network are in :mod:`dbtools.rules.balise_groups`.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.network import Network
from dbtools.rules.common import Locator, capped, column, fmt_km, isin, py, texts
from dbtools.rules.config import ValidationConfig
from dbtools.rules.topology_geometry import check_geometry
from dbtools.topology import all_tracks
from schemas.enums import Navigability, Severity
from schemas.findings import Finding
from schemas.network import CONNECTIONS, NETWORK_TRACKS, SWITCH_PORTS, SWITCH_ROUTES, SWITCHES, TRACK_POINTS
from schemas.tables import BALISES

I64 = npt.NDArray[np.int64]
ALL_PORTS = ("a1", "b1", "b2", "a2")
NONE = Navigability.NONE.value


class _Out:
    """Findings collected per rule, capped, each located by the Locator."""

    def __init__(self, config: ValidationConfig, loc: Locator) -> None:
        self.items: list[Finding] = []
        self.cap, self.loc, self.config = config.max_findings_per_rule, loc, config

    def add(
        self,
        rule: str,
        sev: Severity,
        table: str,
        rows: I64 | list[int],
        build: Callable[[int], tuple[str, dict[str, object]]],
    ) -> None:
        """``build(row)`` → (message, extra Finding fields) for each row (a row of ``table``)."""

        def make(i: int) -> Finding:
            msg, extra = build(i)
            at = self.loc.at(table, i) if i >= 0 else {}
            return Finding(rule, sev, table, msg, **extra, **at)  # type: ignore[arg-type]

        self.items += capped(rule, sev, table, np.asarray(rows, dtype=np.int64), make, self.cap, self.loc.file(table))


def check_topology(net: Network, config: ValidationConfig, loc: Locator) -> list[Finding]:
    """All topology rules (module doc); nothing for a line-only network."""
    if net.tracks.empty and net.connections.empty and net.switches.empty and net.track_points.empty:
        return []
    out = _Out(config, loc)
    tracks = all_tracks(net)
    known = set(texts(tracks["track_id"]))
    _references(net, known, out)
    ports = _ports(net.switches)
    inc = _incidence(net.connections)
    _switch_ports(net, ports, inc, out)
    _navigability(net, ports, out)
    _multiple(net, inc, out)
    _overlap(net, ports, tracks, out)
    _ends(net, tracks, inc, out)
    _km_jump(net, tracks, config, out)
    out.items += check_geometry(net, tracks, inc, config, loc)
    return out.items


def _references(net: Network, known: set[str], out: _Out) -> None:
    def missing(frame: pd.DataFrame, col: str) -> I64:
        v = column(frame, col)
        return np.flatnonzero(pd.notna(v) & ~isin(v, known))

    def ref(table: str, frame: pd.DataFrame, col: str, what: str) -> None:
        v = column(frame, col)
        out.add(
            "topology.invalid_reference",
            Severity.ERROR,
            table,
            missing(frame, col),
            lambda i: (f"{col} '{v[i]}' names no track ({what})", {"column": col, "value": py(v[i])}),
        )

    for col in ("track_a", "track_b"):
        ref(CONNECTIONS.name, net.connections, col, "connection")
    for p in ALL_PORTS:
        ref(SWITCHES.name, net.switches, f"{p}_track", f"switch port {p.upper()}")
    declared = set(texts(net.tracks["track_id"]))
    tp_ids = column(net.track_points, "track_id")
    bad = np.flatnonzero(~isin(tp_ids, declared))
    out.add(
        "topology.invalid_reference",
        Severity.ERROR,
        TRACK_POINTS.name,
        bad,
        lambda i: (f"track_points of '{tp_ids[i]}', which tracks does not declare", {"column": "track_id"}),
    )
    if "track_id" in net.balises.columns:
        ref(BALISES.name, net.balises, "track_id", "balise")
    sid = column(net.connections, "switch_id")
    switches = texts(net.switches["switch_id"])
    bad = np.flatnonzero(pd.notna(sid) & ~isin(sid, switches))
    out.add(
        "topology.invalid_reference",
        Severity.ERROR,
        CONNECTIONS.name,
        bad,
        lambda i: (f"switch_id '{sid[i]}' names no switch", {"column": "switch_id", "value": py(sid[i])}),
    )


def _ports(sw: pd.DataFrame) -> pd.DataFrame:
    """Long table of switch ports: row (of switches), switch_id, type, port, track, end."""
    parts = []
    for p in ALL_PORTS:
        parts.append(
            pd.DataFrame(
                {
                    "row": np.arange(len(sw)),
                    "switch_id": column(sw, "switch_id"),
                    "type": column(sw, "type"),
                    "port": p,
                    "track": column(sw, f"{p}_track"),
                    "end": column(sw, f"{p}_end"),
                }
            )
        )
    return pd.concat(parts, ignore_index=True)


def _incidence(c: pd.DataFrame) -> pd.DataFrame:
    """Both ends of every connection: row (of connections), side a/b, track, end, switch_id,
    other track and end."""
    a = pd.DataFrame({"track": column(c, "track_a"), "end": column(c, "end_a"), "other": column(c, "track_b")})
    a["other_end"] = column(c, "end_b")
    b = pd.DataFrame({"track": column(c, "track_b"), "end": column(c, "end_b"), "other": column(c, "track_a")})
    b["other_end"] = column(c, "end_a")
    rows = np.arange(len(c))
    a["row"], b["row"], a["side"], b["side"] = rows, rows, "a", "b"
    sid = column(c, "switch_id")
    a["switch_id"], b["switch_id"] = sid, sid
    return pd.concat([a, b], ignore_index=True)


#: Ports that may be empty: a branch leading out of the DB (``schemas.network``).
OPEN_PORTS = ("b1", "b2")


def _required(ports: pd.DataFrame) -> npt.NDArray[np.bool_]:
    need = {(t.value, p) for t, ps in SWITCH_PORTS.items() for p in ps}
    t, p = texts(ports["type"]), texts(ports["port"])
    return np.array([(a, b) in need for a, b in zip(t, p, strict=True)], dtype=bool)


def _switch_ports(net: Network, ports: pd.DataFrame, inc: pd.DataFrame, out: _Out) -> None:
    req = _required(ports)
    given = ports["track"].notna().to_numpy() & ports["end"].notna().to_numpy()
    may_be_open = ports["port"].isin(OPEN_PORTS).to_numpy()
    empty = ports[req & ~given & ~may_be_open]
    out.add(
        "topology.switch_port",
        Severity.ERROR,
        SWITCHES.name,
        empty["row"].to_numpy(),
        _msg(
            empty, lambda r: f"{r.type} switch {r.switch_id} needs port {r.port.upper()} ({r.port}_track, {r.port}_end)"
        ),
    )
    edge = ports[req & ~given & may_be_open]
    out.add(
        "topology.switch_open_port",
        Severity.WARNING,
        SWITCHES.name,
        edge["row"].to_numpy(),
        _msg(
            edge,
            lambda r: (
                f"port {r.port.upper()} of {r.type} switch {r.switch_id} is empty: its branch leads out of the DB"
            ),
        ),
    )
    used = inc[inc["switch_id"].notna()][["switch_id", "track", "end"]].drop_duplicates()
    m = ports[given].merge(used, on=["switch_id", "track", "end"], how="left", indicator=True)
    unused = m[m["_merge"] == "left_only"]
    out.add(
        "topology.switch_port",
        Severity.ERROR,
        SWITCHES.name,
        unused["row"].to_numpy(),
        _msg(
            unused,
            lambda r: (
                f"port {r.port.upper()} of switch {r.switch_id} ({r.track} {r.end}) is used by no connection "
                f"naming the switch"
            ),
        ),
    )
    dup = ports[given & ports.duplicated(["switch_id", "track", "end"], keep="first").to_numpy()]
    out.add(
        "topology.switch_port",
        Severity.ERROR,
        SWITCHES.name,
        dup["row"].to_numpy(),
        _msg(
            dup,
            lambda r: f"track end {r.track} {r.end} is at two ports of switch {r.switch_id} (port {r.port.upper()})",
        ),
    )
    m = inc[inc["switch_id"].notna()].merge(
        ports[given][["switch_id", "track", "end"]].drop_duplicates(),
        on=["switch_id", "track", "end"],
        how="left",
        indicator=True,
    )
    known = set(texts(net.switches["switch_id"]))
    stray = m[(m["_merge"] == "left_only") & m["switch_id"].isin(known)].drop_duplicates("row")
    out.add(
        "topology.switch_port",
        Severity.ERROR,
        CONNECTIONS.name,
        stray["row"].to_numpy(),
        _msg(stray, lambda r: f"connection names switch {r.switch_id} but {r.track} {r.end} is none of its ports"),
    )


def _msg(frame: pd.DataFrame, text: Callable[[pd.Series], str]) -> Callable[[int], tuple[str, dict[str, object]]]:
    """Build findings from the rows of ``frame`` whose ``row`` column is the located row."""
    rows = frame["row"].to_numpy(dtype=np.int64)
    first = {int(r): k for k, r in reversed(list(enumerate(rows)))}  # the frame's first row of each located row

    def build(i: int) -> tuple[str, dict[str, object]]:
        r = frame.iloc[first[i]]
        return text(r), {"keys": _keys(r)}

    return build


def _keys(r: pd.Series) -> dict[str, object]:
    return {k: py(r[k]) for k in ("switch_id", "track") if k in r.index and py(r[k]) is not None}


def _navigability(net: Network, ports: pd.DataFrame, out: _Out) -> None:
    c = net.connections[net.connections["switch_id"].notna()]
    if c.empty:
        return
    p = ports[ports["track"].notna()][["switch_id", "port", "track", "end", "type", "row"]]
    a = c.reset_index().rename(columns={"index": "crow"})
    a = a.astype({"switch_id": object, "track_a": object, "end_a": object, "track_b": object, "end_b": object})
    a = a.merge(
        p.rename(columns={"port": "pa", "track": "track_a", "end": "end_a"}), on=["switch_id", "track_a", "end_a"]
    )
    a = a.merge(
        p[["switch_id", "port", "track", "end"]].rename(columns={"port": "pb", "track": "track_b", "end": "end_b"})
    )
    pa, pb = texts(a["pa"]), texts(a["pb"])
    a["pair"] = pd.Series(
        [(x, y) if x <= y else (y, x) for x, y in zip(pa, pb, strict=True)], index=a.index, dtype=object
    )
    routes = {t.value: tuple(tuple(sorted(r)) for r in rs) for t, rs in SWITCH_ROUTES.items()}  # declared order
    types = texts(a["type"])
    is_route = np.array([pr in routes.get(t, ()) for pr, t in zip(a["pair"], types, strict=True)], dtype=bool)
    nav = texts(a["navigability"])
    given = pd.notna(nav)  # a missing one is schema.required
    wrong = given & ((is_route & (nav == NONE)) | (~is_route & (nav != NONE)))
    bad = a[wrong]
    nav_of = dict(zip(bad["crow"], nav[wrong], strict=True))
    pair_of = dict(zip(bad["crow"], bad["pair"], strict=True))
    out.add(
        "topology.navigability",
        Severity.ERROR,
        CONNECTIONS.name,
        bad["crow"].to_numpy(),
        lambda i: (
            f"ports {pair_of[i][0].upper()}–{pair_of[i][1].upper()} of switch {net.connections['switch_id'].iloc[i]} "
            + (
                "are a route but the connection is not navigable (none)"
                if nav_of[i] == NONE
                else f"are no route of the switch (branch↔branch) but navigability is {nav_of[i]}; expected none"
            ),
            {
                "column": "navigability",
                "value": nav_of[i],
                "keys": {"switch_id": py(net.connections["switch_id"].iloc[i])},
            },
        ),
    )
    have = set(zip(a["switch_id"], a["pair"], strict=True))
    sw = net.switches
    missing: list[tuple[int, str]] = []
    for i, (s, t) in enumerate(zip(column(sw, "switch_id"), column(sw, "type"), strict=True)):
        for r in routes.get(str(t), ()):
            if (s, r) not in have and all(pd.notna(sw[f"{q}_track"].iloc[i]) for q in r):
                missing.append((i, f"{r[0].upper()}–{r[1].upper()}"))
    route_texts: dict[int, list[str]] = {}
    for i, route in missing:
        route_texts.setdefault(i, []).append(route)
    out.add(
        "topology.navigability",
        Severity.ERROR,
        SWITCHES.name,
        sorted(route_texts),
        lambda i: (
            f"route(s) {', '.join(route_texts[i])} of switch {sw['switch_id'].iloc[i]} have no connection "
            "naming the switch",
            {"keys": {"switch_id": py(sw["switch_id"].iloc[i])}},
        ),
    )


def _multiple(net: Network, inc: pd.DataFrame, out: _Out) -> None:
    g = inc.assign(free=inc["switch_id"].isna()).groupby(["track", "end"], sort=False)
    stats = g.agg(n=("row", "size"), free=("free", "any"), row=("row", "min")).reset_index()
    bad = stats[(stats["n"] > 1) & stats["free"]]
    out.add(
        "topology.multiple_connections",
        Severity.ERROR,
        CONNECTIONS.name,
        bad["row"].to_numpy(),
        _msg(
            bad,
            lambda r: (
                f"track end {r.track} {r.end} has {r.n} connections, not all at a switch: a train cannot "
                "leave one end two ways without a switch"
            ),
        ),
    )


def _overlap(net: Network, ports: pd.DataFrame, tracks: pd.DataFrame, out: _Out) -> None:
    p = ports[ports["track"].notna() & ports["end"].notna()]
    d = p.drop_duplicates(["switch_id", "track", "end"])
    shared = d[d.duplicated(["track", "end"], keep=False)]
    first = shared.drop_duplicates(["track", "end"], keep="last")
    names = shared.groupby(["track", "end"])["switch_id"].agg(lambda s: ", ".join(map(str, s)))
    out.add(
        "topology.switch_overlap",
        Severity.ERROR,
        SWITCHES.name,
        first["row"].to_numpy(),
        _msg(first, lambda r: f"switches {names[(r.track, r.end)]} share the port {r.track} {r.end}"),
    )
    length = dict(
        zip(
            texts(tracks["track_id"]),
            tracks["length_m"].to_numpy(dtype=float),
            strict=True,
        )
    )
    lim = out.config.switch_min_spacing_m
    per = d.drop_duplicates(["switch_id", "track"])
    per = per[per.duplicated("track", keep=False)]
    per = per[np.array([length.get(t, np.inf) < lim for t in texts(per["track"])], dtype=bool)]
    rows: list[int] = []
    text: dict[int, str] = {}
    for track, grp in per.groupby("track"):
        i = int(grp["row"].iloc[-1])
        rows.append(i)
        text[i] = (
            f"switches {', '.join(map(str, grp['switch_id']))} are joined by track {track} of only "
            f"{length[track]:.1f} m (< {lim:g} m): their turnouts overlap"
        )
    out.add("topology.switch_overlap", Severity.ERROR, SWITCHES.name, rows, lambda i: (text[i], {}))


def _ends(net: Network, tracks: pd.DataFrame, inc: pd.DataFrame, out: _Out) -> None:
    n_decl = len(net.tracks)
    if net.connections.empty:
        return
    tid = texts(tracks["track_id"])
    inc_track, inc_end = (
        texts(inc["track"]),
        texts(inc["end"]),
    )
    connected = set(inc_track)
    ends_used = set(zip(inc_track, inc_end, strict=True))
    isolated = [i for i in range(n_decl) if tid[i] not in connected]
    out.add(
        "topology.isolated_track",
        Severity.WARNING,
        NETWORK_TRACKS.name,
        isolated,
        lambda i: (
            f"track {tid[i]} has no connection in a network that has connections",
            {"keys": {"track_id": tid[i]}},
        ),
    )
    lo, hi = _grid_extent(net)
    line, tr = column(tracks, "line_code"), column(tracks, "track")
    k = {"begin": column(tracks, "km_begin_m"), "end": column(tracks, "km_end_m")}
    open_rows: list[int] = []
    text: dict[int, str] = {}
    stops = {e: column(tracks, f"{e}_buffer_stop") if f"{e}_buffer_stop" in tracks.columns else None for e in k}
    for i in range(n_decl):
        if tid[i] not in connected:
            continue
        for e in ("begin", "end"):
            stop = stops[e]
            if (tid[i], e) in ends_used or (stop is not None and stop[i] is not None and bool(stop[i])):
                continue  # connected, or a buffer stop stands there
            ext = (lo.get((line[i], tr[i])), hi.get((line[i], tr[i])))
            if np.isfinite(k[e][i]) and any(x is not None and abs(k[e][i] - x) <= 1.0 for x in ext):
                continue  # the end of the line's grid: the network's boundary
            open_rows.append(i)
            text[i] = text.get(i, f"track {tid[i]}: ") + f"{e} has no connection (no buffer stop is recorded); "
    out.add(
        "topology.open_end",
        Severity.WARNING,
        NETWORK_TRACKS.name,
        sorted(set(open_rows)),
        lambda i: (text[i].rstrip("; "), {"keys": {"track_id": tid[i]}}),
    )


def _grid_extent(net: Network) -> tuple[dict[tuple[object, object], float], dict[tuple[object, object], float]]:
    if net.gis.empty:
        return {}, {}
    g = net.gis.groupby(["line_code", "track"], observed=True)["km_m"].agg(["min", "max"]).reset_index()
    keys = [(str(a), str(b)) for a, b in zip(column(g, "line_code"), column(g, "track"), strict=True)]
    return dict(zip(keys, g["min"].to_numpy(float), strict=True)), dict(
        zip(keys, g["max"].to_numpy(float), strict=True)
    )


def _km_jump(net: Network, tracks: pd.DataFrame, config: ValidationConfig, out: _Out) -> None:
    c = net.connections
    if c.empty:
        return
    t = tracks.drop_duplicates("track_id")
    index = pd.Index(texts(t["track_id"]))
    ta, tb = column(c, "track_a"), column(c, "track_b")
    ia, ib = index.get_indexer(pd.Index(ta)), index.get_indexer(pd.Index(tb))
    rows = np.flatnonzero((ia >= 0) & (ib >= 0))
    if rows.size == 0:
        return
    a, b = t.iloc[ia[rows]], t.iloc[ib[rows]]
    la, lb = column(a, "line_code"), column(b, "line_code")

    def km(side: pd.DataFrame, ends: npt.NDArray[np.object_]) -> npt.NDArray[np.float64]:
        return np.where(ends == "begin", column(side, "km_begin_m"), column(side, "km_end_m")).astype(float)

    ka, kb = km(a, column(c, "end_a")[rows]), km(b, column(c, "end_b")[rows])
    with np.errstate(invalid="ignore"):
        jump = (la == lb) & pd.notna(la) & (np.abs(ka - kb) > config.km_jump_m)
    br = net.km_breaks
    breaks = {
        (str(lc), round(min(x, y), 3), round(max(x, y), 3))
        for lc, x, y in zip(column(br, "line_code"), column(br, "km_from_m"), column(br, "km_to_m"), strict=True)
    }
    hit = [
        j
        for j in np.flatnonzero(jump)
        if (str(la[j]), round(min(ka[j], kb[j]), 3), round(max(ka[j], kb[j]), 3)) not in breaks
    ]
    at = {int(rows[j]): j for j in hit}
    out.add(
        "topology.km_jump",
        Severity.ERROR,
        CONNECTIONS.name,
        sorted(at),
        lambda i: (
            f"line {la[at[i]]}: track {ta[i]} ends at km {fmt_km(ka[at[i]])} but track {tb[i]} joins it at km "
            f"{fmt_km(kb[at[i]])} ({abs(ka[at[i]] - kb[at[i]]):.1f} m apart) and no km_breaks row explains it",
            {"value": round(float(abs(ka[at[i]] - kb[at[i]])), 3), "limit": config.km_jump_m},
        ),
    )
