"""Outputs: one protection rule for every ``--out``, then atomic writes.

**The rule** (:func:`check_target`), the same for every command:

* nothing is written inside a release registry (a folder holding ``registry.sqlite``: the
  released DBs, their manifests, the registry itself), with or without ``--force`` — the one
  check :func:`refuse_registry`, which every output path passes (outputs that are not
  replaced but resumed, like an audit DB, call it directly); exit 3;
* an existing output is refused without ``--force`` (exit 3);
* ``--force`` never replaces — whatever the command —
  * an input of the same command (the output is an input, inside one, or holds one),
  * a folder trainpos did not create: every output folder carries the marker file
    ``.trainpos-output``; an existing folder without it is replaced only when empty,
  * a file by a folder or a folder by a file;
* outputs honour the umask (the temporary files Python makes are private; the final file or
  folder gets the permissions a plain ``open`` would give).

**Errors of the machine** while an output is written — disk full, a read-only or
write-protected folder, a file too large, an I/O error; OSErrors and the same errors of SQLite
(:func:`output_errors`) — are reported against the output path the user gave (``--out``),
never against a temporary file nor without a path: an OSError naming that path, with the
reason (the CLI's exit 2).

**Atomic writes**: the output is written into a temporary sibling and renamed into place, so
an interrupted command never leaves a half-written output under the requested name. A
temporary sibling carries an unmistakable signature, ``.NAME.trainpos-tmp.PID.TOKEN`` (TOKEN:
16 random hex digits; :func:`temp_sibling`). A folder replaced with ``--force`` is first
renamed aside as ``.NAME.trainpos-old.PID.TOKEN`` and removed only once the new one is in
place. The next check of the same target (:func:`sweep_stale`) removes temporary siblings
whose process is gone, and renames an orphaned old copy back when the target is missing (a
kill between the two renames); it touches no other file, whatever its name looks like.
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import secrets
import shutil
import stat
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Literal

from schemas.errors import RefusedError, TrainposError

#: Marker file in every output folder trainpos writes.
MARKER = ".trainpos-output"
#: The file that makes a folder a release registry (``dbtools/release.py``).
REGISTRY_FILE = "registry.sqlite"
#: Tags of the temporary-sibling signature: a new output being written, and the previous
#: copy of a folder during a ``--force`` replace.
TEMP_TAG = "trainpos-tmp"
OLD_TAG = "trainpos-old"
#: The signature: ``.NAME.TAG.PID.TOKEN`` (TOKEN: 16 random hex digits), plus the journal
#: files SQLite may leave beside a temporary DB. Nothing else is ever swept.
TEMP_RE = re.compile(
    rf"^\.(?P<name>.+)\.(?P<tag>{TEMP_TAG}|{OLD_TAG})\.(?P<pid>[0-9]{{1,10}})\.[0-9a-f]{{16}}(?:-journal|-wal|-shm)?$"
)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_UMASK = _umask()


def in_registry(path: Path) -> Path | None:
    """The release registry ``path`` is, or lies inside, if any: a folder holding
    :data:`REGISTRY_FILE`, found along the path as given and along its resolved path (a
    symlink into a registry is inside it)."""
    given = Path(path).absolute()
    for p in (given, Path(os.path.realpath(given))):
        for folder in (p, *p.parents):
            if (folder / REGISTRY_FILE).is_file():
                return folder
    return None


def refuse_registry(path: Path) -> None:
    """The check every output path passes, whatever writes it (``--out``, ``--propose``,
    ``--plot``, an audit DB resumed in place): nothing is ever written inside a release
    registry or over one — RefusedError, exit 3. Only ``db release`` adds to a registry."""
    registry = in_registry(path)
    if registry is not None:
        raise RefusedError(
            f"a release registry ({registry}) is never written into or replaced: no output goes inside one "
            "(only db release adds a version); choose a path outside it",
            path=path,
        )


def _overlaps(a: Path, b: Path) -> bool:
    a, b = a.absolute().resolve(), b.absolute().resolve()
    return a == b or a in b.parents or b in a.parents


def check_target(
    path: Path, *, force: bool, kind: Literal["file", "folder"], inputs: Iterable[Path | str] = ()
) -> None:
    """Refuse (RefusedError, exit 3) what the module docstring's rule forbids."""
    path = Path(path)
    refuse_registry(path)
    sweep_stale(path)  # an old copy a killed replace left aside is back under its name first
    for src in inputs:
        if _overlaps(path, Path(src)):
            raise RefusedError(f"the output would replace an input of this command ({src})", path=path)
    if not path.exists() and not path.is_symlink():
        return
    if not force:
        raise RefusedError("output exists; use --force to replace it", path=path)
    if kind == "file" and path.is_dir():
        raise RefusedError("output is a folder; a file is never written over a folder", path=path)
    if kind == "folder" and not path.is_dir():
        raise RefusedError("output is a file; a folder is never written over a file", path=path)
    if kind == "folder" and not (path / MARKER).exists() and any(path.iterdir()):
        raise RefusedError(
            f"--force replaces only a folder trainpos wrote (it has a {MARKER} marker) or an empty one", path=path
        )


def refuse_existing(path: Path, force: bool) -> None:
    """An existing output is refused without ``force`` (the first part of the rule)."""
    if Path(path).exists() and not force:
        raise RefusedError("output exists; use --force to replace it", path=path)


#: Errors of the machine an output write meets (errno): reported against the output path.
MACHINE_ERRNOS = frozenset(
    {errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS, errno.EACCES, errno.EPERM, errno.EIO, errno.ENAMETOOLONG}
)
#: SQLite's primary result codes of the same errors, and what each means as an errno
#: (SQLITE_PERM, SQLITE_READONLY, SQLITE_IOERR, SQLITE_FULL, SQLITE_CANTOPEN).
SQLITE_ERRNOS = {3: errno.EACCES, 8: errno.EROFS, 10: errno.EIO, 13: errno.ENOSPC, 14: errno.EACCES}
#: The same, by the words of SQLite's messages (drivers that keep only the message: ADBC).
SQLITE_WORDS = {
    "disk is full": errno.ENOSPC,
    "readonly database": errno.EROFS,
    "disk i/o error": errno.EIO,
    "unable to open database file": errno.EACCES,
}


def machine_errno(exc: BaseException) -> int | None:
    """The errno of an error of the machine (disk full, read-only, permission, I/O) behind
    ``exc`` — an OSError, a ``sqlite3`` error or another database driver's error naming
    SQLite's reason — or None when ``exc`` is not one."""
    if isinstance(exc, OSError):
        return exc.errno if exc.errno in MACHINE_ERRNOS else None
    if isinstance(exc, TrainposError):
        return None  # already reported against its own file (an input read while writing)
    code = getattr(exc, "sqlite_errorcode", None)
    if isinstance(code, int) and code & 0xFF in SQLITE_ERRNOS:
        return SQLITE_ERRNOS[code & 0xFF]
    text = str(exc).lower()
    return next((e for words, e in SQLITE_WORDS.items() if words in text), None)


def _names_other_file(exc: BaseException, path: Path, tmp: Path | None) -> bool:
    """True when ``exc`` is an OSError about a file that is neither the output, its folder,
    its temporary nor a file inside or beside that temporary (SQLite's journal): an input
    read while writing, whose own message stands."""
    name = getattr(exc, "filename", None) if isinstance(exc, OSError) else None
    if name is None:
        return False
    p = Path(os.fsdecode(name)).absolute()
    out = Path(path).absolute()
    if p in (out, out.parent):
        return False
    m = TEMP_RE.match(p.name)
    if m is not None and m["name"] == out.name and p.parent == out.parent:
        return False  # a temporary sibling of the output (its signature)
    if tmp is None:
        return True
    t = tmp.absolute()
    return not (p == t or t in p.parents or p.name.startswith(t.name))


@contextlib.contextmanager
def output_errors(path: Path, tmp: Path | None = None) -> Iterator[None]:
    """Errors of the machine raised inside the block (:func:`machine_errno`) while the output
    ``path`` is written (through its temporary ``tmp``) become an OSError naming ``path``
    with the reason; other errors pass unchanged."""
    try:
        yield
    except Exception as exc:
        code = machine_errno(exc)
        if code is None or _names_other_file(exc, Path(path), tmp):
            raise
        raise OSError(code, os.strerror(code), str(path)) from exc


def temp_sibling(target: Path, *, folder: bool = False, tag: str = TEMP_TAG) -> Path:
    """Create (exclusively, private) a fresh temporary file or folder beside ``target``,
    named with the signature :data:`TEMP_RE` that :func:`sweep_stale` recognises."""
    while True:
        tmp = _signed_name(Path(target), tag)
        try:
            if folder:
                os.mkdir(tmp, 0o700)
            else:
                os.close(os.open(tmp, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o600))
        except FileExistsError:  # 64 random bits taken: draw again
            continue
        return tmp


def _signed_name(target: Path, tag: str) -> Path:
    """A fresh name with the signature: ``.NAME.TAG.PID.TOKEN`` beside ``target``."""
    return target.with_name(f".{target.name}.{tag}.{os.getpid()}.{secrets.token_hex(8)}")


def _own_temps(path: Path) -> list[tuple[Path, str]]:
    """(sibling, tag) of every temporary sibling of ``path`` whose owning process is gone,
    newest first; only names with the full signature count (a user's ``.NAME.2026.bak``
    never does)."""
    found: list[tuple[float, Path, str]] = []
    with contextlib.suppress(OSError):
        for sib in path.parent.iterdir():
            m = TEMP_RE.match(sib.name)
            if m is None or m.group("name") != path.name or process_alive(int(m.group("pid"))):
                continue
            with contextlib.suppress(OSError):
                found.append((sib.lstat().st_mtime, sib, m.group("tag")))
    return [(sib, tag) for _, sib, tag in sorted(found, key=lambda f: f[0], reverse=True)]


def sweep_stale(path: Path) -> None:
    """Clean up after processes killed while writing ``path``: their temporary siblings are
    removed, except that the previous copy of a folder being replaced (killed between its
    two renames) is renamed back to ``path`` when ``path`` is missing — never deleted."""
    path = Path(path)
    for sib, tag in _own_temps(path):
        if tag != OLD_TAG:
            _remove(sib)
        elif not path.exists() and not path.is_symlink():
            with contextlib.suppress(OSError):  # left in place if it cannot be renamed back
                os.replace(sib, path)
        else:  # the replace finished: the new copy is in place
            _remove(sib)


def _remove(p: Path) -> None:
    if p.is_dir() and not p.is_symlink():
        shutil.rmtree(p, ignore_errors=True)
    else:
        with contextlib.suppress(OSError):
            p.unlink()


def process_alive(pid: int) -> bool:
    """Whether process ``pid`` runs on this machine (this process counts; unknown: alive)."""
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True
    return True


def publish_mode(p: Path) -> None:
    """The permissions a plain open/mkdir would have given (umask honoured)."""
    if p.is_dir():
        for sub in [p, *p.rglob("*")]:
            base = 0o777 if sub.is_dir() else 0o666
            if sub.is_file() and stat.S_IMODE(sub.stat().st_mode) & stat.S_IXUSR:
                base = 0o777
            os.chmod(sub, base & ~_UMASK)
    else:
        os.chmod(p, 0o666 & ~_UMASK)


@contextlib.contextmanager
def atomic_folder(path: Path, *, force: bool = False, inputs: Iterable[Path | str] = ()) -> Iterator[Path]:
    """Yield a temporary folder; on success it replaces ``path`` (see the module rule)."""
    path = Path(path)
    check_target(path, force=force, kind="folder", inputs=inputs)
    with output_errors(path):
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = temp_sibling(path, folder=True)
    try:
        with output_errors(path, tmp):
            yield tmp
            (tmp / MARKER).write_text("written by trainpos; --force may replace this folder\n", encoding="utf-8")
            publish_mode(tmp)
            if path.exists():
                _replace_folder(tmp, path)
            else:
                os.replace(tmp, path)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _replace_folder(new: Path, path: Path) -> None:
    """Two renames: ``path`` aside under the signature (``.NAME.trainpos-old.PID.TOKEN``),
    ``new`` into place; the old copy is removed only then. Killed between the renames, the
    old copy stays recoverable: the next write to ``path`` renames it back (:func:`sweep_stale`)."""
    old = _signed_name(path, OLD_TAG)  # 64 random bits: no other file has this name
    os.rename(path, old)
    try:
        os.replace(new, path)
    except BaseException:  # failed (not killed): the old copy goes straight back
        os.rename(old, path)
        raise
    shutil.rmtree(old, ignore_errors=True)


@contextlib.contextmanager
def atomic_file(path: Path, *, force: bool = False, inputs: Iterable[Path | str] = ()) -> Iterator[Path]:
    """Yield a temporary file path beside ``path``; on success it is renamed to ``path``."""
    path = Path(path)
    check_target(path, force=force, kind="file", inputs=inputs)
    with output_errors(path):
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = temp_sibling(path)
    try:
        with output_errors(path, tmp):
            yield tmp
            publish_mode(tmp)
            os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise


def write_text(path: Path, text: str, *, force: bool = False, inputs: Iterable[Path | str] = ()) -> Path:
    """``text`` written atomically to ``path`` under the rule (UTF-8)."""
    with atomic_file(path, force=force, inputs=inputs) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)
