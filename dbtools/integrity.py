"""The content-hash check of every onboard DB load.

``db build`` stores SHA-256 over the canonical content of every table
(:func:`dbtools.network.content_hash`) as ``meta['content_hash']``.
:func:`dbtools.database.read_network` computes it again on every load and refuses a DB
whose content no longer matches it — a bit flip on disk, a row edited by hand with an
SQLite tool — with :class:`ContentHashError` (an :class:`~schemas.errors.InputError`:
exit 2). A DB without a stored hash cannot be verified and is refused the same way.

The check is on unless the caller opts out: code run inside ``hash_policy(verify=False)``
(the CLI's ``--no-verify-hash``) uses such a DB and records it in the policy, so that the
command can say which DB it used unverified. Commands that *report* on DBs (``db
validate``, ``db diff``, ``db verify-release``, ``db review``) read without the check and
report a mismatch as a finding or a summary line instead.

This module is light (no pandas) so that the CLI can import it at start-up. What the
check costs on a national DB: bench/NOTES.md, "Content hash on every load".
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from contextvars import ContextVar
from dataclasses import dataclass, field
from pathlib import Path

from schemas.errors import InputError


class ContentHashError(InputError):
    """An onboard DB whose content does not match the content hash stored when it was built."""


@dataclass
class HashPolicy:
    """Whether DB loads are verified, and the DBs used although they did not match."""

    verify: bool = True
    used_unverified: list[str] = field(default_factory=list)
    """One line per DB load that did not match (``verify`` False only)."""


_POLICY: ContextVar[HashPolicy | None] = ContextVar("trainpos_hash_policy", default=None)


@contextlib.contextmanager
def hash_policy(*, verify: bool) -> Iterator[HashPolicy]:
    """Loads inside the block verify the content hash (``verify``) or only record a mismatch."""
    policy = HashPolicy(verify)
    token = _POLICY.set(policy)
    try:
        yield policy
    finally:
        _POLICY.reset(token)


def mismatch_text(stored: str | None, actual: str) -> str:
    """What is wrong with a DB whose stored hash is ``stored`` and whose content hashes to ``actual``."""
    if not stored:
        return "the DB has no content hash in its meta table, so its content cannot be verified"
    return (
        f"content hash {actual[:12]}… does not match the one stored when the DB was built ({stored[:12]}…): "
        "the DB was modified afterwards (a bit flip, a row edited by hand)"
    )


def check_content_hash(stored: str | None, actual: str, path: Path | str) -> None:
    """Raise :class:`ContentHashError` unless ``actual`` is the ``stored`` hash — or, under
    ``hash_policy(verify=False)``, record the mismatch in the policy and return."""
    if stored and stored == actual:
        return
    what = mismatch_text(stored, actual)
    policy = _POLICY.get()
    if policy is not None and not policy.verify:
        policy.used_unverified.append(f"{path}: {what}")
        return
    raise ContentHashError(
        f"{what}; rebuild it with `trainpos db build` or restore the released file (--no-verify-hash uses it anyway)",
        path=path,
    )
