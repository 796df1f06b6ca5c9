"""Outputs: one protection rule for every ``--out``, then atomic writes.

**The rule** (:func:`check_target`), the same for every command:

* an existing output is refused without ``--force`` (exit 3);
* ``--force`` never replaces — whatever the command —
  * a release registry or anything inside one (a folder holding ``registry.sqlite``: the
    released DBs, their manifests, the registry itself),
  * an input of the same command (the output is an input, inside one, or holds one),
  * a folder trainpos did not create: every output folder carries the marker file
    ``.trainpos-output``; an existing folder without it is replaced only when empty,
  * a file by a folder or a folder by a file;
* outputs honour the umask (the temporary files Python makes are private; the final file or
  folder gets the permissions a plain ``open`` would give).

**Atomic writes**: the output is written into a temporary sibling (``.NAME.PID.….tmp``) and
renamed into place, so an interrupted command never leaves a half-written output under the
requested name; temporary siblings left by a process that was killed are removed by the next
write to the same target.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import stat
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Literal

from schemas.errors import RefusedError

#: Marker file in every output folder trainpos writes.
MARKER = ".trainpos-output"
#: The file that makes a folder a release registry (``dbtools/release.py``).
REGISTRY_FILE = "registry.sqlite"


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_UMASK = _umask()


def in_registry(path: Path) -> Path | None:
    """The release registry ``path`` is, or lies inside, if any."""
    p = Path(path).absolute()
    for folder in (p, *p.parents):
        if (folder / REGISTRY_FILE).is_file():
            return folder
    return None


def _overlaps(a: Path, b: Path) -> bool:
    a, b = a.absolute().resolve(), b.absolute().resolve()
    return a == b or a in b.parents or b in a.parents


def check_target(
    path: Path, *, force: bool, kind: Literal["file", "folder"], inputs: Iterable[Path | str] = ()
) -> None:
    """Refuse (RefusedError, exit 3) what the module docstring's rule forbids."""
    path = Path(path)
    registry = in_registry(path)
    if registry is not None:
        raise RefusedError(f"a release registry ({registry}) is never written into or replaced", path=path)
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


def _sweep_stale(path: Path) -> None:
    """Remove temporary siblings of ``path`` left by processes that no longer run."""
    pattern = re.compile(rf"^\.{re.escape(path.name)}\.(?:old\.)?(\d+)\.")
    with contextlib.suppress(OSError):
        for sib in path.parent.iterdir():
            m = pattern.match(sib.name)
            if m is None or _alive(int(m.group(1))):
                continue
            if sib.is_dir():
                shutil.rmtree(sib, ignore_errors=True)
            else:
                with contextlib.suppress(OSError):
                    sib.unlink()


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _publish_mode(p: Path) -> None:
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
    path.parent.mkdir(parents=True, exist_ok=True)
    _sweep_stale(path)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.{os.getpid()}.", suffix=".tmp", dir=path.parent))
    try:
        yield tmp
        (tmp / MARKER).write_text("written by trainpos; --force may replace this folder\n", encoding="utf-8")
        _publish_mode(tmp)
        if path.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{path.name}.old.{os.getpid()}.", suffix=".tmp", dir=path.parent))
            os.replace(path, old / "x")
            os.replace(tmp, path)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, path)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


@contextlib.contextmanager
def atomic_file(path: Path, *, force: bool = False, inputs: Iterable[Path | str] = ()) -> Iterator[Path]:
    """Yield a temporary file path beside ``path``; on success it is renamed to ``path``."""
    path = Path(path)
    check_target(path, force=force, kind="file", inputs=inputs)
    path.parent.mkdir(parents=True, exist_ok=True)
    _sweep_stale(path)
    fd, name = tempfile.mkstemp(prefix=f".{path.name}.{os.getpid()}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        _publish_mode(tmp)
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
