"""The onboard DB of a replay: a picklable reference and the one per-process worker cache.

A :class:`DbRef` names the DB file and the SHA-256 of its canonical content
(:func:`dbtools.network.content_hash`, not the hash written in its ``meta`` table: a
hand-edited or bit-flipped DB keeps that one). Workers receive the reference, never the
tables; :func:`load_network` reads the file once per process and keeps it for every later
run with the same reference (path + content hash). Structures derived from the tables
(indexes, look-ups) stay cached on the loaded :class:`~dbtools.network.Network` itself
(:meth:`Network.cached`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from dbtools.database import read_network
from dbtools.network import Network, content_hash, network_content_hash
from schemas.errors import InputError

_CACHE: dict[tuple[str, str], Network] = {}


@dataclass(frozen=True)
class DbRef:
    """An onboard DB as workers see it: absolute path and content hash."""

    path: str
    content_hash: str

    @property
    def key(self) -> tuple[str, str]:
        return (self.path, self.content_hash)


def open_db(path: Path, network: Network | None = None) -> tuple[DbRef, Network]:
    """Read the DB (or take ``network``, already read from it), hash its content and keep
    it in this process's cache, so that runs replayed here do not read it again."""
    path = Path(path).resolve()
    net = network if network is not None else read_network(path)  # verified (dbtools.integrity)
    ref = DbRef(str(path), network_content_hash(net))
    _CACHE.clear()
    _CACHE[ref.key] = net
    return ref, net


def load_network(ref: DbRef) -> Network:
    """The DB of ``ref``, read once per process. InputError when its content is no longer
    the one the replay started with (the file was replaced or edited meanwhile)."""
    net = _CACHE.get(ref.key)
    if net is None:
        net = read_network(Path(ref.path), verify=False)  # checked against the reference instead
        actual = content_hash(net.tables)
        if actual != ref.content_hash:
            raise InputError(
                f"the DB changed while the runs were replayed (content hash {actual[:12]}, "
                f"expected {ref.content_hash[:12]})",
                path=ref.path,
            )
        _CACHE.clear()  # one DB per worker process: a new reference replaces the old one
        _CACHE[ref.key] = net
    return net
