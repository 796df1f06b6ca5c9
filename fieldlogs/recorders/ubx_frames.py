"""UBX framing shared by the reader (:mod:`fieldlogs.recorders.ubx`) and its message
modules (:mod:`~fieldlogs.recorders.ubx_esf`, :mod:`~fieldlogs.recorders.ubx_raw`): the
accepted frames of a file and the writer of one frame (u-blox interface description: sync
``B5 62``, class, id, little-endian length, payload, 8-bit Fletcher checksum)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

SYNC = b"\xb5\x62"


@dataclass
class Frames:
    """Accepted frames of a file: byte offset, class, id and payload length of each."""

    data: npt.NDArray[np.uint8]
    start: npt.NDArray[np.int64]
    cls: npt.NDArray[np.int64]
    mid: npt.NDArray[np.int64]
    length: npt.NDArray[np.int64]

    def of(self, key: tuple[int, int]) -> npt.NDArray[np.int64]:
        return np.flatnonzero((self.cls == key[0]) & (self.mid == key[1]))

    def fixed(self, idx: npt.NDArray[np.int64], dtype: np.dtype[np.void], offset: int = 0) -> npt.NDArray[np.void]:
        """Structured records of ``dtype.itemsize`` bytes at ``offset`` in each payload of ``idx``."""
        n = dtype.itemsize
        pos = self.start[idx][:, None] + 6 + offset + np.arange(n)[None, :]
        return np.ascontiguousarray(self.data[pos]).view(dtype).ravel()

    def payload(self, i: int) -> bytes:
        a = int(self.start[i]) + 6
        return self.data[a : a + int(self.length[i])].tobytes()


def frame(cls: int, mid: int, payload: bytes) -> bytes:
    """One UBX frame with its checksum."""
    body = bytes((cls, mid)) + len(payload).to_bytes(2, "little") + payload
    a = b = 0
    for x in body:
        a = (a + x) & 0xFF
        b = (b + a) & 0xFF
    return SYNC + body + bytes((a, b))
