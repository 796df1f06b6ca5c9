"""The long tables the topology rules work on (:mod:`dbtools.rules.topology`): one row per
switch port and one per connection end, with shared integer codes of switch, track and end so
that joins, duplicate tests and look-ups run on integers (issue 30: a national network has
≥ 50,000 tracks); their text (objects, NaN for missing, as pandas' ``str`` columns give it)
only for the rows a rule reports (:func:`port_rows`, :func:`incidence_rows`)."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc

from dbtools.network import Network
from dbtools.rules.common import isin as text_isin
from dbtools.rules.common import texts
from dbtools.topology import SWITCH_PORT_NAMES, track_codes
from schemas.network import CONNECTIONS, SWITCH_ROUTES, SWITCHES

I64 = npt.NDArray[np.int64]
ALL_PORTS = SWITCH_PORT_NAMES


def text_objects(s: pd.Series) -> npt.NDArray[np.object_]:
    """A text column as objects with NaN for missing, as pandas' ``str`` columns give them."""
    return np.asarray(s.to_numpy(dtype=object, na_value=np.nan), dtype=object)


def held_objects(net: Network, table: str, name: str) -> npt.NDArray[np.object_]:
    """:func:`text_objects` of a column of one of the network's tables, converted once per
    loaded network (the rules pick rows of it)."""
    return net.cached(("text_objects", table, name), lambda: text_objects(net.tables[table][name]))


def picked_objects(net: Network, table: str, name: str, rows: npt.NDArray[np.int64]) -> npt.NDArray[np.object_]:
    """:func:`held_objects` at ``rows``: the rows' text only, unless the whole column is already
    held as objects or most of it is asked for (a rule reports few rows of a national network:
    no Python string made for the others)."""
    held = net.peek(("text_objects", table, name))
    frame = net.tables[table]
    if held is None and 8 * len(rows) < len(frame):
        return text_objects(frame[name].iloc[np.asarray(rows, dtype=np.int64)])
    return held_objects(net, table, name)[rows]


def object_frame(columns: dict[str, npt.NDArray[Any]], index: pd.Index | None = None) -> pd.DataFrame:
    """A frame of the arrays as they are (pandas would turn object text into ``str``)."""
    return pd.DataFrame({k: pd.Series(v, dtype=v.dtype, index=index) for k, v in columns.items()}, index=index)


def port_table(sw: pd.DataFrame) -> pd.DataFrame:
    """Long table of switch ports, one row per switch and port of ``ALL_PORTS`` (port-major:
    rows k·n … (k+1)·n − 1 are port ``ALL_PORTS[k]`` of the n switches): ``row`` (of
    switches) and ``pk`` (k); the text of chosen rows by :func:`port_rows`."""
    n, k = len(sw), len(ALL_PORTS)
    return pd.DataFrame({"row": np.tile(np.arange(n), k), "pk": np.repeat(np.arange(k), n)})


def port_rows(net: Network, ports: pd.DataFrame) -> pd.DataFrame:
    """Rows of the port table (a selection of it) with their text: switch_id, type, port,
    track, end — objects, NaN for missing (read from the switches' rows they stand for)."""
    srow, pk = ports["row"].to_numpy(), ports["pk"].to_numpy()
    track, end = np.empty(len(ports), dtype=object), np.empty(len(ports), dtype=object)
    for k, p in enumerate(ALL_PORTS):
        at = np.flatnonzero(pk == k)
        if at.size:
            track[at], end[at] = (picked_objects(net, SWITCHES.name, f"{p}_{w}", srow[at]) for w in ("track", "end"))
    text = object_frame(
        {
            "switch_id": picked_objects(net, SWITCHES.name, "switch_id", srow),
            "type": picked_objects(net, SWITCHES.name, "type", srow),
            "port": np.array(ALL_PORTS, dtype=object)[pk],
            "track": track,
            "end": end,
        },
        ports.index,
    )
    return pd.concat([ports, text], axis=1)


def incidence_table(c: pd.DataFrame) -> pd.DataFrame:
    """Both ends of every connection (every end a, then every end b): ``row`` (of
    connections); the text of chosen rows by :func:`incidence_rows`."""
    rows = np.arange(len(c))
    return pd.DataFrame({"row": np.concatenate([rows, rows])})


def incidence_rows(net: Network, inc: pd.DataFrame) -> pd.DataFrame:
    """Rows of the incidence table (a selection of it) with their text: track, end, other
    track and end, side a/b, switch_id — objects, NaN for missing."""
    crow, b_side = inc["row"].to_numpy(), inc.index.to_numpy() >= len(net.connections)
    side = np.where(b_side, "b", "a").astype(object)
    ta, ea, tb, eb = (picked_objects(net, CONNECTIONS.name, k, crow) for k in ("track_a", "end_a", "track_b", "end_b"))
    text = object_frame(
        {
            "track": np.where(b_side, tb, ta),
            "end": np.where(b_side, eb, ea),
            "other": np.where(b_side, ta, tb),
            "other_end": np.where(b_side, ea, eb),
            "side": side,
            "switch_id": picked_objects(net, CONNECTIONS.name, "switch_id", crow),
        },
        inc.index,
    )
    return pd.concat([inc, text], axis=1)


def shared_codes(*columns: pd.Series) -> list[I64]:
    """Integer codes shared by the columns: equal values (a missing one included) get equal
    codes, so that joins and duplicate tests run on integers (Arrow's hashing of the text
    as held, no Python strings)."""
    codes, _ = pd.factorize(pd.concat(columns, ignore_index=True), use_na_sentinel=False)
    return np.split(codes.astype(np.int64), np.cumsum([len(c) for c in columns])[:-1])


def _given(*columns: pd.Series) -> npt.NDArray[np.bool_]:
    """Which values of the columns, one after the other, are not missing (from the columns as
    held: Arrow's validity bitmap, not a test of each object)."""
    return np.concatenate([np.asarray(c.notna().to_numpy(), dtype=bool) for c in columns])


def add_codes(net: Network, inc: pd.DataFrame, ports: pd.DataFrame) -> None:
    """Add codes of switch (``sk``), track (``tk``, ``ok`` of the other track) and end
    (``ek``, ``oek``) to the incidence and port tables, ``key`` = the (switch, track,
    end) triple as one integer and, to the incidence table, ``okey`` = that of the other end;
    and which values are given: ``has_track``, ``has_end`` (both tables), ``has_switch``
    (the incidence table)."""
    c, sw = net.connections, net.switches
    inc["has_track"], inc["has_end"] = _given(c["track_a"], c["track_b"]), _given(c["end_a"], c["end_b"])
    inc["has_switch"] = _given(c["switch_id"], c["switch_id"])
    ports["has_track"] = _given(*(sw[f"{p}_track"] for p in ALL_PORTS))
    ports["has_end"] = _given(*(sw[f"{p}_end"] for p in ALL_PORTS))
    csk, ssk = shared_codes(c["switch_id"], sw["switch_id"])
    inc["sk"], ports["sk"] = np.concatenate([csk, csk]), np.tile(ssk, len(ALL_PORTS))
    n_code = []
    for what, inc_cols, port_cols in (("track", ("tk", "ok"), "tk"), ("end", ("ek", "oek"), "ek")):
        if what == "track":  # the network's one factorisation of track ids
            of = track_codes(net).of
            ca, cb = of[(CONNECTIONS.name, "track_a")], of[(CONNECTIONS.name, "track_b")]
            cp = [of[(SWITCHES.name, f"{p}_track")] for p in ALL_PORTS]
        else:
            ca, cb, *cp = shared_codes(c[f"{what}_a"], c[f"{what}_b"], *(sw[f"{p}_{what}"] for p in ALL_PORTS))
        inc[inc_cols[0]], inc[inc_cols[1]] = np.concatenate([ca, cb]), np.concatenate([cb, ca])
        ports[port_cols] = np.concatenate(cp)
        n_code.append(1 + max((int(x.max()) for x in (ca, cb, *cp) if len(x)), default=0))
    n_t, n_e = n_code
    for f in (inc, ports):
        f["key"] = (f["sk"].to_numpy() * n_t + f["tk"].to_numpy()) * n_e + f["ek"].to_numpy()
    inc["okey"] = (inc["sk"].to_numpy() * n_t + inc["ok"].to_numpy()) * n_e + inc["oek"].to_numpy()


def int_isin(values: npt.ArrayLike, known: npt.ArrayLike) -> npt.NDArray[np.bool_]:
    """``np.isin`` for integer keys by a hash look-up (no sort)."""
    return np.asarray(pd.Series(np.asarray(values)).isin(np.asarray(known)).to_numpy(), dtype=bool)


def int_join(left: I64, right: I64) -> tuple[I64, I64]:
    """Row pairs (i, j) with ``left[i] == right[j]`` in the order of an inner
    ``DataFrame.merge`` (by i, then by j): ``right`` sorted once (stable), each key's run
    found by ``np.searchsorted``."""
    order = np.argsort(right, kind="stable")
    r = right[order]
    lo = np.searchsorted(r, left, "left")
    cnt = np.searchsorted(r, left, "right") - lo
    li = np.repeat(np.arange(len(left), dtype=np.int64), cnt)
    within = np.arange(int(cnt.sum()), dtype=np.int64) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    return li, np.asarray(order[np.repeat(lo, cnt) + within], dtype=np.int64)


def arrow_text(s: pd.Series) -> pa.ChunkedArray | None:
    """A text column as Arrow strings (None: not held as Arrow strings)."""
    to_arrow = getattr(s.array, "__arrow_array__", None)
    a = to_arrow() if to_arrow is not None else None
    return a if a is not None and (pa.types.is_string(a.type) or pa.types.is_large_string(a.type)) else None


def is_in(s: pd.Series, known: pd.Series) -> npt.NDArray[np.bool_]:
    """``s[i]`` is one of ``known`` (a missing value is when ``known`` has one), by Arrow's
    hash look-up on the Arrow-held text (no Python strings), else :func:`dbtools.rules.common.isin`."""
    a, k = arrow_text(s), arrow_text(known)
    if a is None or k is None:
        return text_isin(texts(s), texts(known))
    values = (k.combine_chunks() if isinstance(k, pa.ChunkedArray) else k).cast(a.type)
    hit = pc.is_in(a, value_set=values)
    return np.asarray(hit.to_numpy(zero_copy_only=False), dtype=bool)


#: Port → digit of a port pair's code (the pair's smaller and larger port: 4·lo + hi).
PORT_DIGIT = {p: i for i, p in enumerate(sorted(ALL_PORTS))}
#: Switch type → codes of its routes, in declared order, with the routes as sorted pairs.
ROUTES = {
    t.value: [(PORT_DIGIT[lo] * 4 + PORT_DIGIT[hi], (lo, hi)) for lo, hi in (sorted(r) for r in rs)]
    for t, rs in SWITCH_ROUTES.items()
}


def pair_codes(ka: I64, kb: I64) -> I64:
    """Codes of port pairs given as indexes into ``ALL_PORTS``."""
    digits = np.array([PORT_DIGIT[p] for p in ALL_PORTS])
    da, db = digits[ka], digits[kb]
    return np.asarray(np.minimum(da, db) * 4 + np.maximum(da, db), dtype=np.int64)


def switch_pairs(ports: pd.DataFrame, inc: pd.DataFrame) -> pd.DataFrame:
    """Connections naming a switch, with the ports of that switch their ends are at (a row
    per pair of ports; none where an end is at no port): crow (row of connections), pa/pb,
    ``row`` (pa's row of the port table), sk (the switch's code) and the port pair's code ``pair`` — joined on
    the integer (switch, track, end) keys (:func:`int_join`)."""
    side_a = np.arange(len(inc)) < len(inc) // 2  # incidence_table: every end a, then every end b
    at = np.flatnonzero(side_a & inc["has_switch"].to_numpy())
    on = np.flatnonzero(ports["has_track"].to_numpy())
    port_key = ports["key"].to_numpy()[on]
    i, j = int_join(inc["key"].to_numpy()[at], port_key)  # end a at port pa
    k, m = int_join(inc["okey"].to_numpy()[at[i]], port_key)  # end b at port pb
    pa_rows, pb_rows = on[j[k]], on[m]
    n_sw = len(ports) // len(ALL_PORTS)  # port_table: the switches once per port of ALL_PORTS
    ka, kb = pa_rows // n_sw, pb_rows // n_sw
    names = np.array(ALL_PORTS, dtype=object)
    return object_frame(  # the text columns stay objects (no conversion to Arrow text and back)
        {
            "crow": inc["row"].to_numpy()[at[i[k]]],
            "sk": inc["sk"].to_numpy()[at[i[k]]],
            "pa": names[ka],
            "pb": names[kb],
            "row": pa_rows,
            "pair": pair_codes(ka, kb),
        }
    )


def port_lengths(net: Network, tracks: pd.DataFrame, rows: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """``length_m`` of the track at the port table's rows ``rows`` (:func:`port_table`'s order
    is that of the switches' port columns in :func:`dbtools.topology.track_codes`): the last
    row of ``tracks`` (:func:`dbtools.topology.all_tracks`) holding its id; NaN: no such track."""
    codes = track_codes(net)
    ports = np.concatenate([codes.of[(SWITCHES.name, f"{p}_track")] for p in ALL_PORTS])
    last = codes.last[ports[np.asarray(rows, dtype=np.int64)]]
    length = np.append(tracks["length_m"].to_numpy(dtype=float, na_value=np.nan), np.nan)
    return np.asarray(length[np.where(last >= 0, last, len(tracks))], dtype=float)
