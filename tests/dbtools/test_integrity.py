"""The content-hash check of every DB load (dbtools/integrity.py, read_network)."""

from __future__ import annotations

import shutil
import sqlite3
import struct
from pathlib import Path

import pytest

from dbtools.database import read_network
from dbtools.diff import diff_paths
from dbtools.integrity import ContentHashError, hash_policy
from dbtools.validate import validate_path
from schemas.errors import EXIT_UNREADABLE, InputError


def bit_flipped(db: Path, out: Path) -> Path:
    """A copy of ``db`` with the lowest mantissa bit of one stored latitude flipped: a
    change of 7e-15 deg, below every comparison tolerance, as a failing disk would make it."""
    with sqlite3.connect(f"file:{db}?mode=ro", uri=True) as conn:
        lats = [r[0] for r in conn.execute("SELECT lat FROM gis ORDER BY line_code, track, km_m LIMIT 50")]
    conn.close()
    data = bytearray(db.read_bytes())
    stored = next(b for b in (struct.pack(">d", v) for v in lats) if data.count(b) == 1)  # stored once
    data[data.find(stored) + 7] ^= 0x01
    out.write_bytes(bytes(data))
    return out


def hand_edited(db: Path, out: Path) -> Path:
    """A copy of ``db`` with one balise moved 30 m by hand (its meta left as it was)."""
    shutil.copy(db, out)
    out.chmod(0o644)
    with sqlite3.connect(out) as conn:
        conn.execute("UPDATE balises SET km_actual_m = km_actual_m + 30 WHERE rowid = 1")
    conn.close()
    return out


def without_hash(db: Path, out: Path) -> Path:
    shutil.copy(db, out)
    out.chmod(0o644)
    with sqlite3.connect(out) as conn:
        conn.execute("DELETE FROM meta WHERE key = 'content_hash'")
    conn.close()
    return out


@pytest.mark.parametrize("damage", [bit_flipped, hand_edited, without_hash], ids=lambda f: f.__name__)
def test_a_modified_db_is_refused_on_load(sample_db: Path, tmp_path: Path, damage: object) -> None:
    bad = damage(sample_db, tmp_path / "bad.sqlite")  # type: ignore[operator]
    before = bad.read_bytes()
    with pytest.raises(ContentHashError) as exc:
        read_network(bad)
    assert isinstance(exc.value, InputError) and exc.value.exit_code == EXIT_UNREADABLE
    assert exc.value.path == str(bad) and "--no-verify-hash" in exc.value.message
    assert ("cannot be verified" if damage is without_hash else "modified afterwards") in exc.value.message
    assert bad.read_bytes() == before  # only read


def test_opting_out_uses_the_db_and_records_it(sample_db: Path, tmp_path: Path) -> None:
    bad = bit_flipped(sample_db, tmp_path / "bad.sqlite")
    with hash_policy(verify=False) as policy:
        net = read_network(bad)
        read_network(sample_db)  # a good DB is not recorded
    assert len(net.gis) == len(read_network(sample_db).gis)
    assert len(policy.used_unverified) == 1 and policy.used_unverified[0].startswith(f"{bad}: content hash")
    with hash_policy(verify=True), pytest.raises(ContentHashError):
        read_network(bad)
    with pytest.raises(ContentHashError):  # the opt-out ends with its block
        read_network(bad)


def test_a_clean_db_loads_and_reports_read_without_the_check(sample_db: Path, tmp_path: Path) -> None:
    assert len(read_network(sample_db).balises) > 0
    bad = bit_flipped(sample_db, tmp_path / "bad.sqlite")
    with hash_policy(verify=True) as policy:
        assert len(read_network(bad, verify=False).gis) > 0  # the caller checks it itself
        rules = {f.rule for f in validate_path(bad)}
    assert "db.content_hash" in rules and policy.used_unverified == []


def test_diff_of_a_bit_flipped_db_says_so(sample_db: Path, tmp_path: Path) -> None:
    bad = bit_flipped(sample_db, tmp_path / "bad.sqlite")
    d = diff_paths(sample_db, bad)
    assert not d.has_changes  # 7e-15 deg is below the row comparison's tolerance …
    assert d.new["content_verified"] is False and d.old["content_verified"] is True
    assert d.new["actual_content_hash"] != d.new["content_hash"] == d.old["content_hash"]
    assert d.summary[0].startswith(f"NEW ({bad}): content does not match its stored content_hash")
    assert "content hashes differ" in d.summary[-1]  # … and the summary does not call them identical
    same = diff_paths(sample_db, sample_db)
    assert same.summary == [s for s in same.summary if "content" not in s or s.startswith("no content differences (")]
