"""Text cells as the typed frames hold them: stripped, and null where blank.

:func:`stripped_text` is what :func:`schemas.frames._coerce_column` does to a text cell —
``str.strip()`` (Arrow's ``utf8_trim_whitespace``, the kernel pandas's Arrow strings call),
then null where :func:`schemas.frames._blank` finds a blank: null, empty, or ``nan``/``na``/
``null`` in any letter case once stripped — for a whole Arrow column at once.

The kernels (:func:`stripped_text_kernels`: trim, lower, compare, select) copy every cell of
the column three times; a national network's source set has 5 M text cells (track ids,
switch ids, ends, kinds …), almost none of them padded or blank. So each chunk is first
judged from its offsets and bytes: when no non-empty cell starts or ends with a byte
≤ 0x20 (ASCII whitespace and controls) or ≥ 0x80 (any byte of a non-ASCII character, which
might be Unicode whitespace), trimming changes no cell, and the only blanks are the nulls,
the empty cells and the cells of 2–4 bytes starting with an ``n`` or ``N`` that are a blank
word in lower case — those few are lower-cased and looked up alone, and the chunk is returned
as it is when none is blank.
A chunk with a padded or non-ASCII edge goes through the kernels, as before. Same values,
type and chunks either way (hypothesis test against the kernels in tests/schemas).
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

#: Text cells taken for blank once stripped, in lower case (as ``schemas.frames._blank``).
BLANK_WORDS = ("nan", "na", "null")
_WORD_LENGTHS = np.array(sorted({len(w) for w in BLANK_WORDS}), dtype=np.int64)
_WORD_FIRST = np.array(sorted({ord(c) for w in BLANK_WORDS for c in (w[0].lower(), w[0].upper())}), dtype=np.uint8)


def stripped_text_kernels(arr: pa.ChunkedArray) -> pa.ChunkedArray:
    """:func:`stripped_text` by Arrow's kernels over every cell."""
    trimmed = pc.utf8_trim_whitespace(arr)
    words = pa.array(BLANK_WORDS)
    blank = pc.fill_null(pc.or_kleene(pc.equal(trimmed, ""), pc.is_in(pc.utf8_lower(trimmed), value_set=words)), True)
    return pc.if_else(blank, pa.scalar(None, pa.string()), trimmed)


def stripped_text(arr: pa.ChunkedArray) -> pa.ChunkedArray:
    """Text cells stripped, blanks null (module docstring), chunk by chunk."""
    if not (pa.types.is_string(arr.type) or pa.types.is_large_string(arr.type)):
        return stripped_text_kernels(arr)
    return pa.chunked_array([_stripped_chunk(c) for c in arr.chunks], type=arr.type)


def _stripped_chunk(a: pa.Array) -> pa.Array:
    n = len(a)
    width = np.int64 if pa.types.is_large_string(a.type) else np.int32
    _, offsets_buf, data_buf = a.buffers()
    if n == 0 or offsets_buf is None:
        return _kernels(a)
    off = np.frombuffer(offsets_buf, dtype=width)[a.offset : a.offset + n + 1].astype(np.int64)
    lengths = np.diff(off)
    filled = lengths > 0
    if filled.any():
        data = np.frombuffer(data_buf, dtype=np.uint8)
        edges = np.concatenate([data[off[:-1][filled]], data[off[1:][filled] - 1]])
        if ((edges <= 0x20) | (edges >= 0x80)).any():
            return _kernels(a)  # a padded cell, or a non-ASCII character at an edge
    blank = ~filled  # empty (or null)
    if a.null_count:
        blank |= np.asarray(a.is_null().to_numpy(zero_copy_only=False), dtype=bool)
    short = np.flatnonzero(np.isin(lengths, _WORD_LENGTHS))
    if len(short):  # only those starting as a blank word does
        short = short[np.isin(np.frombuffer(data_buf, dtype=np.uint8)[off[short]], _WORD_FIRST)]
    if len(short):
        words = pc.is_in(pc.utf8_lower(a.take(pa.array(short))), value_set=pa.array(BLANK_WORDS))
        blank[short] |= np.asarray(pc.fill_null(words, False).to_numpy(zero_copy_only=False), dtype=bool)
    if not blank.any():
        return a
    return pc.if_else(pa.array(blank), pa.scalar(None, a.type), a)


def _kernels(a: pa.Array) -> pa.Array:
    out = stripped_text_kernels(pa.chunked_array([a], type=a.type))
    return out.chunk(0) if out.num_chunks else pa.array([], type=a.type)
