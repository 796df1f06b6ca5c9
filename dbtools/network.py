"""The content of one onboard DB version as typed frames, however it was loaded."""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import TypeVar

import numpy as np
import numpy.typing as npt
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc

from schemas.enums import S003_KINDS
from schemas.frame_screen import key_order
from schemas.frames import PANDAS_DTYPE
from schemas.model import Table
from schemas.network import CONNECTIONS, NETWORK_TRACKS, SWITCHES, TRACK_POINTS
from schemas.tables import (
    BALISE_GROUP_COLUMNS,
    BALISES,
    DB_TABLES,
    FEATURE_POINTS,
    GIS,
    KM_BREAKS,
    LINES,
    TABLES_ADDED,
    TRACK_FEATURE_POINTS,
)

T = TypeVar("T")


@dataclass
class Network:
    """Typed, canonical frames of every content table (sorted by primary key)."""

    tables: dict[str, pd.DataFrame]
    origin: str = ""
    """Where it came from (source folder or DB file), for messages."""
    meta: dict[str, str] = field(default_factory=dict)
    files: dict[str, str] = field(default_factory=dict)
    """Table name → file it was read from (source sets only)."""
    source_rows: dict[str, np.ndarray] = field(default_factory=dict)
    """Table name → file line (1-based, header = line 1) of each row of the canonical frame
    (source sets only), so that findings on sorted frames can name the line to edit."""
    _cache: dict[object, object] = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self) -> None:
        # a network always holds the network tables (empty for a line-only one)
        for t in TABLES_ADDED:
            if t.name not in self.tables:
                self.tables[t.name] = empty_frame(t)

    def cached(self, key: object, factory: Callable[[], T]) -> T:
        """Structures derived from the tables (look-up dicts, spatial indexes) are built
        once per loaded network and shared by every run processed with it."""
        if key not in self._cache:
            self._cache[key] = factory()
        return self._cache[key]  # type: ignore[return-value]

    def peek(self, key: object) -> object | None:
        """What :meth:`cached` holds under ``key``, or None when it was not built yet."""
        return self._cache.get(key)

    @property
    def gis(self) -> pd.DataFrame:
        return self.tables[GIS.name]

    @property
    def balises(self) -> pd.DataFrame:
        return self.tables[BALISES.name]

    @property
    def s003_balises(self) -> pd.DataFrame:
        """The I1/I2/C balises (the papers' system, keyed by line, station and track): what
        line-based consumers (the pipeline's balise aid, survey, the simulator) work with. The
        G balises of European groups are the network's (:mod:`dbtools.topology`)."""

        def build() -> pd.DataFrame:
            b = self.balises
            s003 = b["kind"].isin([k.value for k in S003_KINDS]).to_numpy(dtype=bool)
            return b if s003.all() else b[s003].reset_index(drop=True)

        return self.cached(("s003_balises",), build)

    @property
    def feature_points(self) -> pd.DataFrame:
        return self.tables[FEATURE_POINTS.name]

    @property
    def track_feature_points(self) -> pd.DataFrame:
        """Feature points of network tracks by distance along the track (empty: none)."""
        t = self.tables.get(TRACK_FEATURE_POINTS.name)
        return t if t is not None else empty_frame(TRACK_FEATURE_POINTS)

    @property
    def lines(self) -> pd.DataFrame:
        return self.tables[LINES.name]

    @property
    def km_breaks(self) -> pd.DataFrame:
        return self.tables[KM_BREAKS.name]

    @property
    def tracks(self) -> pd.DataFrame:
        """The declared tracks (empty for a line-only network: see :mod:`dbtools.topology`)."""
        t = self.tables.get(NETWORK_TRACKS.name)
        return t if t is not None else empty_frame(NETWORK_TRACKS)

    @property
    def connections(self) -> pd.DataFrame:
        t = self.tables.get(CONNECTIONS.name)
        return t if t is not None else empty_frame(CONNECTIONS)

    @property
    def switches(self) -> pd.DataFrame:
        t = self.tables.get(SWITCHES.name)
        return t if t is not None else empty_frame(SWITCHES)

    @property
    def track_points(self) -> pd.DataFrame:
        t = self.tables.get(TRACK_POINTS.name)
        return t if t is not None else empty_frame(TRACK_POINTS)


_DTYPES = {name: pd.Series([], dtype=dtype).dtype for name, dtype in PANDAS_DTYPE.items()}


def empty_frame(table: Table) -> pd.DataFrame:
    return pd.DataFrame({c.name: pd.Series([], dtype=PANDAS_DTYPE[c.dtype]) for c in table.columns})


def canonical(table: Table, frame: pd.DataFrame) -> pd.DataFrame:
    """Declared columns in declared order, declared dtypes, sorted by primary key."""
    return _in_key_order(table, frame).reset_index(drop=True)


def canonical_frame(table: Table, frame: pd.DataFrame, *, ordered: bool) -> pd.DataFrame:
    """:func:`canonical`, or, when the caller knows ``frame`` to be canonical already
    (``ordered``: built by :func:`canonical` and not changed since), ``frame`` itself: the
    key-order test of a national network's text keys is not made a second and third time
    (``db build`` hashes and writes the frames of ``read_source_set``)."""
    return frame if ordered else canonical(table, frame)


def canonical_with_index(table: Table, frame: pd.DataFrame) -> tuple[pd.DataFrame, np.ndarray]:
    """:func:`canonical` plus the index label of the input row behind each output row."""
    out = _in_key_order(table, frame)
    return out.reset_index(drop=True), out.index.to_numpy()


def _in_key_order(table: Table, frame: pd.DataFrame) -> pd.DataFrame:
    """The declared columns and dtypes of ``frame``, sorted by the primary key, with the
    input's index labels (never materialised here: a frame's range index would keep the
    array of its labels, 8 MB for a million rows, cached)."""
    cols: dict[str, pd.Series] = {}
    for c in table.columns:
        s = frame[c.name] if c.name in frame.columns else pd.Series([None] * len(frame), index=frame.index)
        if s.dtype == _DTYPES[c.dtype]:
            pass  # already canonical (the common case): no copy
        elif c.dtype == "str":
            s = s.astype("string")
        elif c.dtype == "int":
            s = pd.to_numeric(s).astype("Int64")
        elif c.dtype == "bool":
            s = s.astype("boolean")
        else:
            s = pd.to_numeric(s).astype("float64")
        cols[c.name] = s
    out = pd.DataFrame(cols, index=frame.index, copy=False)  # no copy into one float block
    if table.primary_key and len(out) and not sorted_by(out, table.primary_key):
        out = out.sort_values(list(table.primary_key), kind="stable")
    return out


def sorted_by(frame: pd.DataFrame, keys: tuple[str, ...]) -> bool:
    """True when the rows are already in the order a stable sort on ``keys`` gives (each
    row's key tuple ≤ the next one's), so the sort can be skipped: frames read back from a
    DB are (tables are read in key order). False whenever a key has a missing value (the
    sort puts those last) or is not text or a number; the caller then sorts
    (:func:`schemas.frame_screen.key_order`)."""
    return key_order(frame, keys)[0]


def joined_text(s: pd.Series) -> bytes:
    """The UTF-8 bytes of a text column's values joined by 0x1f, a missing value as the
    empty string — the bytes every stored ``content_hash`` was made of (the former
    ``s.astype(object).where(s.notna(), "\\x00")``, whose NUL fill value pandas turns into
    ""). The concatenation of :func:`joined_text_parts`."""
    return b"".join(bytes(part) for part in joined_text_parts(s))


#: Values per part of :func:`joined_text_parts` (bounds its temporaries).
TEXT_BLOCK = 1 << 16


def joined_text_parts(s: pd.Series) -> Iterator[npt.NDArray[np.uint8]]:
    """:func:`joined_text` in consecutive parts of ``TEXT_BLOCK`` values (the hash is fed part
    by part: no copy of the whole column), from the column's Arrow buffers, no Python string
    per value: each part is its values' bytes with 0x1f after every value but the column's
    last — a reshape when the values share one length (codes, tracks), else the data buffer of
    Arrow's ``binary_join_element_wise`` of each value with the empty string, 0x1f between
    (1.7× faster than ``np.insert`` of the separators at the values' ends, which it replaced:
    the national network's track ids, switch ids and names are of many lengths)."""
    arr = pa.array(s.array if isinstance(s.dtype, pd.StringDtype) else s.astype(object), from_pandas=True)
    n = len(arr)
    for a in range(0, n, TEXT_BLOCK):
        part = arr.slice(a, TEXT_BLOCK)
        if isinstance(part, pa.ChunkedArray):  # a DB's column comes in many small batches
            part = part.combine_chunks()
        if not (pa.types.is_string(part.type) or pa.types.is_large_string(part.type)):
            part = part.cast(pa.large_string())
        if part.null_count:
            part = pc.fill_null(part, "")
        m = len(part)
        _, offsets_buf, data_buf = part.buffers()
        offset_type = np.int64 if pa.types.is_large_string(part.type) else np.int32
        off = np.frombuffer(offsets_buf, dtype=offset_type)[part.offset : part.offset + m + 1].astype(np.int64)
        data = np.zeros(0, np.uint8) if data_buf is None else np.frombuffer(data_buf, dtype=np.uint8)
        body = data[off[0] : off[-1]]
        lengths = np.diff(off)
        out: npt.NDArray[np.uint8]
        if m and np.all(lengths == lengths[0]):
            width = int(lengths[0])
            rows = np.empty((m, width + 1), dtype=np.uint8)
            rows[:, :width] = body.reshape(m, width)
            rows[:, width] = 0x1F
            out = rows.reshape(-1)
        else:  # each value and its separator appended by Arrow's join, read from its data buffer
            sep = pa.scalar("\x1f", part.type)
            joined = pc.binary_join_element_wise(part, pa.scalar("", part.type), sep)
            _, j_offsets, j_data = joined.buffers()
            j_off = np.frombuffer(j_offsets, dtype=offset_type)[joined.offset : joined.offset + m + 1]
            out = np.frombuffer(j_data, dtype=np.uint8)[int(j_off[0]) : int(j_off[-1])]
        yield out[:-1] if a + m == n else out


def content_hash(tables: dict[str, pd.DataFrame], *, ordered: bool = False) -> str:
    """SHA-256 over all content tables in canonical form.

    Identical whether the frames come from a source set being built or from a DB read
    back, so a hand-edited or corrupted DB no longer matches the hash in its meta table.
    What schema versions 2 and 3 added (the network tables, the balise-group columns,
    ``track_feature_points``) enters only when it holds something: a line-only network hashes
    as it did under version 1, a network without track feature points as under version 2.
    ``ordered``: the frames are canonical already (:func:`dbtools.sources.read_source_set`'s
    are), so their key order is not checked again (:func:`canonical_frame`).
    """
    h = hashlib.sha256()
    for table in DB_TABLES:
        frame = canonical_frame(table, tables.get(table.name, empty_frame(table)), ordered=ordered)
        if table in TABLES_ADDED and frame.empty:
            continue
        h.update(f"table:{table.name}:{len(frame)}\n".encode())
        for c in table.columns:
            if c in BALISE_GROUP_COLUMNS and table is BALISES and not frame[c.name].notna().any():
                continue
            h.update(f"col:{c.name}\n".encode())
            s = frame[c.name]
            if c.dtype == "str":
                for part in joined_text_parts(s):
                    h.update(part.data)
            elif c.dtype in ("int", "bool"):
                arr = s.astype("Float64").to_numpy(dtype=np.float64, na_value=np.nan)
                h.update(np.ascontiguousarray(arr).data)  # the array's bytes, not a copy of them
            else:
                arr = s.to_numpy(dtype=np.float64, na_value=np.nan)
                nan = np.isnan(arr)
                if nan.any():
                    arr = np.where(nan, np.nan, arr)  # one NaN bit pattern
                h.update(np.ascontiguousarray(arr).data)
    return h.hexdigest()


def network_content_hash(network: Network) -> str:
    """:func:`content_hash` of a loaded network's tables, computed once per network (the
    load that verifies it and the replay reference that follows share it)."""
    return network.cached(("content_hash",), lambda: content_hash(network.tables))
