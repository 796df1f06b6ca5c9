"""Opening input files: the one mechanism every reader of a user-given file or DB goes through.

* **Regular files only** (:func:`regular_file`): a path given as an input file or DB must be
  a regular file (symbolic links followed). A FIFO, a device or a socket is refused with a
  message naming it and is never opened — opening a FIFO blocks until a writer appears,
  reading a device may never end.
* **Compressed inputs within limits** (:func:`read_input_bytes`, :func:`check_zip`): a gzip
  file is decompressed in pieces, and refused (InputError, exit 2) as soon as its content
  passes ``[input] max_decompressed_mb`` or, beyond :data:`schemas.inputs.RATIO_FREE_BYTES`,
  ``[input] max_ratio`` times its compressed size — before more of it is held in memory. A
  zip container (an ``.xlsx`` workbook) is checked on its members' sizes before anything
  reads them: Python's zip reader never returns more than a member's declared size.
* **Format detection reads a head** (:func:`read_head`): at most
  :data:`schemas.inputs.HEAD_BYTES`, decompressed, whatever the file's size.

The limits are those of the configuration tree's ``[input]`` section (:class:`InputLimits`)
made current by :func:`input_limits` (the CLI does so for a command's ``--config``), the
defaults otherwise.
"""

from __future__ import annotations

import contextlib
import os
import stat
import zipfile
import zlib
from collections.abc import Iterator
from contextvars import ContextVar
from pathlib import Path
from typing import BinaryIO

from schemas.errors import InputError
from schemas.inputs import HEAD_BYTES, RATIO_FREE_BYTES, InputLimits

#: Magic number of a gzip file.
GZIP_MAGIC = b"\x1f\x8b"
#: Compressed bytes decompressed at a time.
CHUNK = 1 << 20

_LIMITS: ContextVar[InputLimits | None] = ContextVar("input_limits", default=None)


def current_limits() -> InputLimits:
    """The ``[input]`` limits in force (the defaults unless :func:`input_limits` set others)."""
    return _LIMITS.get() or InputLimits()


@contextlib.contextmanager
def input_limits(limits: InputLimits) -> Iterator[InputLimits]:
    """Make ``limits`` the ones in force for the block."""
    token = _LIMITS.set(limits)
    try:
        yield limits
    finally:
        _LIMITS.reset(token)


_KINDS = (
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)


def regular_file(path: Path, what: str = "file") -> Path:
    """``path`` when it is a regular file (or a link to one); InputError otherwise — missing,
    a folder, a FIFO, a device, a socket — without ever opening it. ``what`` names what was
    expected in the message (``"onboard DB file (.sqlite)"``)."""
    path = Path(path)
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError as exc:
        raise InputError("no such file", path=path) from exc
    except OSError as exc:
        raise InputError(f"cannot be read: {exc.strerror}", path=path) from exc
    if stat.S_ISREG(mode):
        return path
    if stat.S_ISDIR(mode):
        raise InputError(f"is a folder ({what} expected)", path=path)
    kind = next((name for test, name in _KINDS if test(mode)), "not a regular file")
    raise InputError(f"is {kind}, not a regular file ({what} expected); it was not opened", path=path)


def not_special(path: Path, what: str = "file") -> Path:
    """``path``, unless it exists and is a FIFO, a device or a socket: then InputError, and it
    is never opened. A missing path or a folder is left to the caller's own message (a
    reader that says "vehicle file not found")."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        regular_file(path, what)
    return path


def _too_big(path: Path, size: int, compressed: int, limits: InputLimits) -> InputError | None:
    """The refusal of ``size`` decompressed bytes from ``compressed`` bytes, or None."""
    if size > limits.max_bytes:
        return InputError(
            f"decompresses to more than {limits.max_decompressed_mb:g} MB (the limit [input] max_decompressed_mb; "
            "a larger limit in a --config file lets it through)",
            path=path,
        )
    if size > RATIO_FREE_BYTES and size > limits.max_ratio * max(compressed, 1):
        return InputError(
            f"decompresses to more than {limits.max_ratio:g} times its compressed size ({compressed} bytes): a "
            "decompression bomb, or an unusual file (the limit [input] max_ratio; a larger one in a --config file "
            "lets it through)",
            path=path,
        )
    return None


def check_decompressed(path: Path, size: int, compressed: int) -> None:
    """InputError when ``size`` bytes decompressed from ``compressed`` pass the ``[input]``
    limits (a decoder that cannot stream, e.g. Hatanaka's: checked on its output)."""
    err = _too_big(Path(path), size, compressed, current_limits())
    if err is not None:
        raise err


def read_input_bytes(path: Path) -> bytes:
    """The content of an input file, gunzipped when it is gzip (by magic number, not by name:
    concatenated gzip members too), within the ``[input]`` limits."""
    path = regular_file(path, "source file")
    with open(path, "rb") as fh:
        head = fh.read(2)
        fh.seek(0)
        if head != GZIP_MAGIC:
            return fh.read()
        return _gunzip(fh, path, os.fstat(fh.fileno()).st_size)


def _gunzip(fh: BinaryIO, path: Path, compressed: int) -> bytes:
    """Every gzip member of the open file ``fh``, refused as soon as the output passes a limit."""
    limits = current_limits()
    out: list[bytes] = []  # joined once at the end (no reallocation copies on the way)
    size = 0
    d = zlib.decompressobj(wbits=31)
    in_member = False  # d has had input and not reached its member's end
    data = fh.read(CHUNK)
    try:
        while data:
            in_member = True
            # at most one chunk of output per step: a bomb is refused ≤ 1 MB past the limit
            out.append(d.decompress(data, CHUNK))
            size += len(out[-1])
            if (err := _too_big(path, size, compressed, limits)) is not None:
                raise err
            if d.eof:  # a member ends; the next one (a concatenated file) follows
                data, d, in_member = d.unused_data, zlib.decompressobj(wbits=31), False
            else:
                data = d.unconsumed_tail
            if not data:
                data = fh.read(CHUNK)
    except zlib.error as exc:
        raise InputError(f"truncated or corrupt gzip file: {exc}", path=path) from exc
    if in_member:
        raise InputError("truncated or corrupt gzip file: it ends inside a compressed member", path=path)
    return b"".join(out)


def read_head(path: Path, n: int = HEAD_BYTES) -> bytes:
    """The first ``n`` bytes of an input (decompressed when it is gzip), read without reading
    the rest: for format detection."""
    path = regular_file(path, "source file")
    with open(path, "rb") as fh:
        head = fh.read(n)
    if not head.startswith(GZIP_MAGIC):
        return head
    d = zlib.decompressobj(wbits=31)
    try:
        with open(path, "rb") as fh:
            out = b""
            while len(out) < n and not d.eof:
                data = fh.read(HEAD_BYTES)
                if not data:
                    break
                out += d.decompress(data, n - len(out))
    except zlib.error as exc:
        raise InputError(f"truncated or corrupt gzip file: {exc}", path=path) from exc
    return out[:n]


def check_zip(path: Path) -> None:
    """InputError when the zip container ``path`` (an .xlsx workbook) is not a readable zip,
    or its members together decompress beyond the ``[input]`` limits — checked on the sizes
    the zip declares, before any member is read (a member never yields more than its
    declared size)."""
    path = regular_file(path, "workbook")
    try:
        with zipfile.ZipFile(path) as z:
            members = z.infolist()
    except (zipfile.BadZipFile, OSError, ValueError) as exc:
        raise InputError(f"not a readable .xlsx workbook: {exc}", path=path) from exc
    size = sum(m.file_size for m in members)
    compressed = sum(m.compress_size for m in members)
    err = _too_big(path, size, compressed, current_limits())
    if err is not None:
        raise err
