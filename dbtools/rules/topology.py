"""Network topology rules (SPEC §8.1; RailTopoModel netElements/netRelations, railML 3
``switchIS``, OSRD switch ports): tracks, connections, switches and track_points.

Tracks are :func:`dbtools.topology.all_tracks` (declared plus implied line tracks). A
*port* is the track end a switch names in ``a1/b1/b2/a2`` (:data:`schemas.network.SWITCH_PORTS`
per type); the *routes* of a switch are :data:`schemas.network.SWITCH_ROUTES`. Every rule
is vectorised over the whole network (no per-track loop): switch ports and connection ends
are long tables with shared integer codes of switch, track and end
(:mod:`dbtools.rules.topology_tables`), so joins and duplicate tests run on integers, and
track ids are looked up by the network's one factorisation of them
(:func:`dbtools.topology.track_codes`; issue 30: ≥ 50,000 tracks).

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
from dbtools.rules.topology_tables import (
    ALL_PORTS,
    ROUTES,
    add_codes,
    held_objects,
    incidence_rows,
    incidence_table,
    int_isin,
    is_in,
    port_lengths,
    port_rows,
    port_table,
    switch_pairs,
)
from dbtools.topology import all_tracks, connection_rows, grid_extents, track_codes
from schemas.enums import Navigability, Severity
from schemas.findings import Finding
from schemas.network import CONNECTIONS, NETWORK_TRACKS, SWITCH_PORTS, SWITCHES, TRACK_POINTS
from schemas.tables import BALISES

I64 = npt.NDArray[np.int64]
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
    _references(net, tracks, out)
    ports = port_table(net.switches)
    inc = incidence_table(net.connections)
    add_codes(net, inc, ports)
    _switch_ports(net, ports, inc, out)
    _navigability(net, ports, inc, out)
    _multiple(net, inc, out)
    _overlap(net, ports, tracks, out)
    _ends(net, tracks, out)
    _km_jump(net, tracks, config, out)
    out.items += check_geometry(net, tracks, config, loc)
    return out.items


def _references(net: Network, tracks: pd.DataFrame, out: _Out) -> None:
    refs = [
        *((CONNECTIONS.name, net.connections, col, "connection") for col in ("track_a", "track_b")),
        *((SWITCHES.name, net.switches, f"{p}_track", f"switch port {p.upper()}") for p in ALL_PORTS),
    ]
    if "track_id" in net.balises.columns:
        refs.append((BALISES.name, net.balises, "track_id", "balise"))
    codes = track_codes(net)  # ``tracks`` is all_tracks: an id is known when a row of it holds it
    known = [codes.rows(table, col) >= 0 for table, _, col, _ in refs]

    def ref(k: int) -> None:
        table, frame, col, what = refs[k]
        bad = np.flatnonzero(frame[col].notna().to_numpy() & ~known[k])
        if bad.size == 0:
            return
        v = column(frame, col)
        out.add(
            "topology.invalid_reference",
            Severity.ERROR,
            table,
            bad,
            lambda i: (f"{col} '{v[i]}' names no track ({what})", {"column": col, "value": py(v[i])}),
        )

    for k in range(2 + len(ALL_PORTS)):  # connections, then switch ports
        ref(k)
    first = codes.rows(TRACK_POINTS.name, "track_id")  # declared: the first rows of all_tracks
    bad = np.flatnonzero((first < 0) | (first >= len(net.tracks)))
    if bad.size:
        tp_ids = column(net.track_points, "track_id")
        out.add(
            "topology.invalid_reference",
            Severity.ERROR,
            TRACK_POINTS.name,
            bad,
            lambda i: (f"track_points of '{tp_ids[i]}', which tracks does not declare", {"column": "track_id"}),
        )
    if len(refs) > 2 + len(ALL_PORTS):  # balises
        ref(len(refs) - 1)
    c = net.connections
    bad = np.flatnonzero(c["switch_id"].notna().to_numpy() & ~is_in(c["switch_id"], net.switches["switch_id"]))
    if bad.size:
        sid = column(c, "switch_id")
        out.add(
            "topology.invalid_reference",
            Severity.ERROR,
            CONNECTIONS.name,
            bad,
            lambda i: (f"switch_id '{sid[i]}' names no switch", {"column": "switch_id", "value": py(sid[i])}),
        )


#: Ports that may be empty: a branch leading out of the DB (``schemas.network``).
OPEN_PORTS = ("b1", "b2")


def _required(net: Network) -> npt.NDArray[np.bool_]:
    """The ports a switch of its type needs. The port table holds the switches' rows once per
    port, in the order of ``ALL_PORTS`` (:func:`port_table`): the test runs on the switches'
    types once and is repeated per port."""
    t = held_objects(net, SWITCHES.name, "type")
    n = len(t)
    is_kind = {kind: t == kind.value for kind in SWITCH_PORTS}
    need = [np.zeros(n, dtype=bool) for _ in ALL_PORTS]
    for kind, names in SWITCH_PORTS.items():
        for k, port in enumerate(ALL_PORTS):
            if port in names:
                need[k] |= is_kind[kind]
    return np.concatenate(need) if need else np.zeros(0, dtype=bool)


def _switch_ports(net: Network, ports: pd.DataFrame, inc: pd.DataFrame, out: _Out) -> None:
    req = _required(net)
    given = ports["has_track"].to_numpy() & ports["has_end"].to_numpy()
    may_be_open = np.isin(ports["pk"].to_numpy(), [ALL_PORTS.index(p) for p in OPEN_PORTS])
    empty = port_rows(net, ports[req & ~given & ~may_be_open])
    out.add(
        "topology.switch_port",
        Severity.ERROR,
        SWITCHES.name,
        empty["row"].to_numpy(),
        _msg(
            empty, lambda r: f"{r.type} switch {r.switch_id} needs port {r.port.upper()} ({r.port}_track, {r.port}_end)"
        ),
    )
    edge = port_rows(net, ports[req & ~given & may_be_open])
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
    with_switch = inc["has_switch"].to_numpy()
    unused = _merged(
        port_rows(net, ports[given & ~int_isin(ports["key"].to_numpy(), inc["key"].to_numpy()[with_switch])])
    )
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
    dup = port_rows(net, ports[given & ports["key"].duplicated(keep="first").to_numpy()])
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
    at = np.flatnonzero(with_switch)
    m = incidence_rows(net, inc.iloc[at[~int_isin(inc["key"].to_numpy()[at], ports["key"].to_numpy()[given])]])
    stray = m[isin(m["switch_id"].to_numpy(dtype=object), texts(net.switches["switch_id"]))].drop_duplicates("row")
    out.add(
        "topology.switch_port",
        Severity.ERROR,
        CONNECTIONS.name,
        stray["row"].to_numpy(),
        _msg(stray, lambda r: f"connection names switch {r.switch_id} but {r.track} {r.end} is none of its ports"),
    )


def _merged(frame: pd.DataFrame) -> pd.DataFrame:
    """The rows as the pandas merge the rule was first made with gave them: a missing
    switch_id is None, not NaN (its message says ``switch None``)."""
    sid = frame["switch_id"].to_numpy(dtype=object, copy=True)
    sid[pd.isna(sid)] = None
    return frame.assign(switch_id=pd.Series(sid, index=frame.index, dtype="object"))


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


def _navigability(net: Network, ports: pd.DataFrame, inc: pd.DataFrame, out: _Out) -> None:
    c = net.connections
    if not c["switch_id"].notna().any():
        return
    a = switch_pairs(ports, inc)
    n_sw = len(ports) // len(ALL_PORTS)
    kind, kinds = pd.factorize(held_objects(net, SWITCHES.name, "type"))  # −1: missing
    route = np.zeros((len(kinds) + 1, 16), dtype=bool)  # (switch type, port pair) → a route; last row: no type
    for t, routes in ROUTES.items():
        at = np.flatnonzero(np.asarray(kinds, dtype=object) == t)
        for code, _ in routes:
            route[at, code] = True
    pair = a["pair"].to_numpy()
    is_route = route[kind[a["row"].to_numpy() % n_sw], pair] if n_sw else np.zeros(len(a), dtype=bool)
    crow = a["crow"].to_numpy()
    navs = c["navigability"]
    given = navs.notna().to_numpy()[crow]  # a missing one is schema.required
    is_none = np.asarray((navs == NONE).to_numpy(dtype=bool, na_value=False), dtype=bool)[crow]
    wrong = given & ((is_route & is_none) | (~is_route & ~is_none))
    bad = a[wrong]
    nav_of = dict(zip(bad["crow"], column(c.iloc[bad["crow"].to_numpy()], "navigability"), strict=True))
    pair_of = {
        r: (pa_, pb) if pa_ <= pb else (pb, pa_) for r, pa_, pb in zip(bad["crow"], bad["pa"], bad["pb"], strict=True)
    }
    sid = column(c, "switch_id")
    out.add(
        "topology.navigability",
        Severity.ERROR,
        CONNECTIONS.name,
        bad["crow"].to_numpy(),
        lambda i: (
            f"ports {pair_of[i][0].upper()}–{pair_of[i][1].upper()} of switch {sid[i]} "
            + (
                "are a route but the connection is not navigable (none)"
                if nav_of[i] == NONE
                else f"are no route of the switch (branch↔branch) but navigability is {nav_of[i]}; expected none"
            ),
            {"column": "navigability", "value": nav_of[i], "keys": {"switch_id": py(sid[i])}},
        ),
    )
    _missing_routes(net, ports, a, out)


def _missing_routes(net: Network, ports: pd.DataFrame, a: pd.DataFrame, out: _Out) -> None:
    """Routes of a switch that no connection naming the switch (by id) joins."""
    sw = net.switches
    n = len(sw)
    have = a["sk"].to_numpy() * 16 + a["pair"].to_numpy()
    sk, types = ports["sk"].to_numpy()[:n], held_objects(net, SWITCHES.name, "type")
    # (switch code, pair code) pairs present, as a dense table: codes are small non-negative integers
    present = np.zeros(16 * (1 + max(int(sk.max(initial=0)), int(have.max(initial=0)) // 16)), dtype=bool)
    present[have] = True
    given = ports["has_track"].to_numpy()
    has_track = {p: given[k * n : (k + 1) * n] for k, p in enumerate(ALL_PORTS)}
    rows, order, names = [], [], []
    for t, routes in ROUTES.items():
        of_type = types == t
        for n_route, (code, (lo, hi)) in enumerate(routes):
            hit = np.flatnonzero(of_type & has_track[lo] & has_track[hi] & ~present[sk * 16 + code])
            rows.append(hit)
            order.append(np.full(hit.size, n_route))
            names += [f"{lo.upper()}–{hi.upper()}"] * hit.size
    row, j = np.concatenate(rows), np.concatenate(order)
    route_texts: dict[int, list[str]] = {}
    for k in np.lexsort((j, row)):
        route_texts.setdefault(int(row[k]), []).append(names[k])
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
    """Track ends (integer track and end codes) with more than one connection, one of them
    without a switch; in the order of each end's first connection end in ``inc``."""
    ends = np.flatnonzero(inc["has_track"].to_numpy() & inc["has_end"].to_numpy())
    tk, ek = inc["tk"].to_numpy()[ends], inc["ek"].to_numpy()[ends]
    group, _ = pd.factorize(tk * (1 + int(ek.max(initial=0))) + ek)  # in order of first appearance
    n = np.bincount(group)
    free = np.bincount(group, weights=~inc["has_switch"].to_numpy()[ends]) > 0
    bad_group = np.flatnonzero((n > 1) & free)
    is_bad = np.zeros(len(n), dtype=bool)
    is_bad[bad_group] = True
    at = np.flatnonzero(is_bad[group])  # the bad ends' rows, each group's first one first
    row = inc["row"].to_numpy()[ends[at]]
    first = at[np.unique(group[at], return_index=True)[1]]  # first end of each bad group (by group code)
    low = np.full(len(n), np.iinfo(np.int64).max)
    np.minimum.at(low, group[at], row)
    text = incidence_rows(net, inc.iloc[ends[first]])[["track", "end"]].to_numpy(dtype=object)
    bad = pd.DataFrame(
        {
            "n": n[bad_group],
            "free": free[bad_group],
            "row": low[bad_group],
            "track": text[:, 0],
            "end": text[:, 1],
        }
    )
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
    """The duplicate tests on the integer codes of a frame of the port rows' codes; the port
    table's own rows (text) only for what is reported."""
    ok = np.flatnonzero(ports["has_track"].to_numpy() & ports["has_end"].to_numpy())
    codes = pd.DataFrame({k: ports[k].to_numpy()[ok] for k in ("key", "sk", "tk", "ek")}, index=ok)
    d = codes[~codes["key"].duplicated().to_numpy()]
    dup = d.duplicated(["tk", "ek"], keep=False).to_numpy()
    shared = port_rows(net, ports.loc[d.index[dup]])
    first = port_rows(net, ports.loc[d[dup].drop_duplicates(["tk", "ek"], keep="last").index])
    names = shared.groupby(["track", "end"])["switch_id"].agg(lambda s: ", ".join(map(str, s)))
    out.add(
        "topology.switch_overlap",
        Severity.ERROR,
        SWITCHES.name,
        first["row"].to_numpy(),
        _msg(first, lambda r: f"switches {names[(r.track, r.end)]} share the port {r.track} {r.end}"),
    )
    lim = out.config.switch_min_spacing_m
    per = d.drop_duplicates(["sk", "tk"])
    per = per[per.duplicated("tk", keep=False).to_numpy()]
    tk = per["tk"].to_numpy()
    _, at, back = np.unique(tk, return_index=True, return_inverse=True)  # each track looked up once
    port_of = per.index
    each = port_lengths(net, tracks, port_of[at])  # each track's length by its code
    with np.errstate(invalid="ignore"):
        short = np.flatnonzero(each < lim)
        per = port_rows(net, ports.loc[port_of[each[back.reshape(-1)] < lim]])
    length = dict(zip(port_rows(net, ports.loc[port_of[at[short]]])["track"], each[short], strict=True))
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


def _ends(net: Network, tracks: pd.DataFrame, out: _Out) -> None:
    n_decl = len(net.tracks)
    if net.connections.empty:
        return
    tid = texts(tracks["track_id"])[:n_decl]
    c = net.connections
    at_end = pd.concat([c["end_a"], c["end_b"]], ignore_index=True)
    # each connection end's track as its first row of the declared tracks (their codes): a
    # declared row is in a set of ends' tracks when the first row of its id is among theirs
    end_row = np.concatenate(connection_rows(net, tracks))
    end_row[end_row >= n_decl] = -1  # a track only implied: not among the declared ones
    own_row = track_codes(net).rows("all_tracks", "track_id")[:n_decl]  # a declared id's first row is declared

    def among(ends: npt.NDArray[np.bool_] | None) -> npt.NDArray[np.bool_]:
        hit = np.zeros(n_decl + 1, dtype=bool)
        hit[end_row if ends is None else end_row[ends]] = True  # −1 (no such id) marks the spare last slot
        return np.asarray(hit[own_row], dtype=bool)

    connected = among(None)
    isolated = np.flatnonzero(~connected)
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
    decl = tracks.iloc[:n_decl]
    lo, hi = _grid_extent(net, n_decl)
    opened = {}
    for e in ("begin", "end"):
        k = column(decl, f"km_{e}_m")
        with np.errstate(invalid="ignore"):
            boundary = np.isfinite(k) & ((np.abs(k - lo) <= 1.0) | (np.abs(k - hi) <= 1.0))
        held = decl[f"{e}_buffer_stop"] if f"{e}_buffer_stop" in decl.columns else None
        if held is not None and isinstance(held.dtype, pd.BooleanDtype):  # the canonical dtype: no loop
            stopped = held.to_numpy(dtype=bool, na_value=False)
        else:
            stop = column(decl, f"{e}_buffer_stop") if held is not None else np.full(n_decl, None)
            stopped = np.array([x is not None and bool(x) for x in stop], dtype=bool)
        used = among((at_end == e).fillna(False).to_numpy(dtype=bool))
        opened[e] = connected & ~used & ~stopped & ~boundary

    def text(i: int) -> str:
        return f"track {tid[i]}: " + "; ".join(
            f"{e} has no connection (no buffer stop is recorded)" for e in ("begin", "end") if opened[e][i]
        )

    out.add(
        "topology.open_end",
        Severity.WARNING,
        NETWORK_TRACKS.name,
        np.flatnonzero(opened["begin"] | opened["end"]),
        lambda i: (text(i), {"keys": {"track_id": tid[i]}}),
    )


def _grid_extent(net: Network, n: int) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Lowest and highest km of the grid of the line and track of each of the first ``n``
    rows of :func:`all_tracks` (NaN: no grid), by the network's shared line/track codes."""
    g = grid_extents(net)
    if g.empty or not n:
        return np.full(n, np.nan), np.full(n, np.nan)
    at = track_codes(net).line_tracks.grid_rows("all_tracks")[:n]
    lo, hi = g["km_lo"].to_numpy(float), g["km_hi"].to_numpy(float)
    return np.where(at >= 0, lo[at], np.nan), np.where(at >= 0, hi[at], np.nan)


def _km_jump(net: Network, tracks: pd.DataFrame, config: ValidationConfig, out: _Out) -> None:
    c = net.connections
    if c.empty:
        return
    t = tracks
    ia, ib = connection_rows(net, tracks)
    rows = np.flatnonzero((ia >= 0) & (ib >= 0))
    if rows.size == 0:
        return
    k0, k1 = (column(t, k) for k in ("km_begin_m", "km_end_m"))
    line_code, lines = pd.factorize(t["line_code"])  # −1: missing
    a, b = ia[rows], ib[rows]
    ca, cb = line_code[a], line_code[b]
    la = np.asarray([*lines, None], dtype=object)[ca]  # −1: None
    begin_a, begin_b = (
        np.asarray((c[k] == "begin").to_numpy(dtype=bool, na_value=False))[rows] for k in ("end_a", "end_b")
    )
    ka = np.where(begin_a, k0[a], k1[a]).astype(float)
    kb = np.where(begin_b, k0[b], k1[b]).astype(float)
    with np.errstate(invalid="ignore"):
        jump = (ca == cb) & (ca >= 0) & (np.abs(ka - kb) > config.km_jump_m)
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
    ta, tb = (column(c, k) if at else np.empty(0, dtype=object) for k in ("track_a", "track_b"))
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
