"""Opening inputs (dbtools/inputs.py, issue 32 item 7): compressed inputs within configurable
limits (a bomb is a clear error and exit 2, never an OOM or a traceback, also under a memory
limit), format detection reads a head only, and a FIFO, device or socket given as an input
is refused without being opened (no hang)."""

from __future__ import annotations

import gzip
import os
import shutil
import socket
import subprocess
import sys
import zipfile
import zlib
from pathlib import Path

import openpyxl
import pytest
from typer.testing import CliRunner

from cli.main import app
from dbtools.inputs import check_zip, input_limits, read_head, read_input_bytes, regular_file
from dbtools.sample_network import sample_source_dir
from schemas.errors import InputError
from schemas.inputs import InputLimits

ROOT = Path(__file__).resolve().parents[2]
RECORDERS = ROOT / "tests" / "data" / "recorders"
SENTENCE = b"$GPGGA,000000.00,3554.4231,N,13928.9858,E,2,10,1.0,15.0,M,39.0,M,,*5C\r\n"
MB = 1 << 20


def _cli(args: list[str], cwd: Path, *, address_space: int | None = None) -> subprocess.CompletedProcess[str]:
    """The CLI in a subprocess (a hang ends in a timeout, not a stuck suite), optionally
    under a memory limit (RLIMIT_AS)."""
    limit = f"resource.setrlimit(resource.RLIMIT_AS, ({address_space}, {address_space}))\n" if address_space else ""
    code = f"import resource, sys\n{limit}sys.argv = ['trainpos', *sys.argv[1:]]\nfrom cli.main import app\napp()\n"
    env = {**os.environ, "PYTHONPATH": str(ROOT), "COLUMNS": "300"}
    return subprocess.run(
        [sys.executable, "-c", code, *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=120
    )


def _gzip_bomb(path: Path, gigabytes: float) -> Path:
    """A gzip file starting like NMEA decompressing to ``gigabytes`` (concatenated members of
    one 32 MB block, a sentence and zeros: written in a moment, a few MB on disk)."""
    block = SENTENCE * 2 + bytes(32 * MB - 2 * len(SENTENCE))
    c = zlib.compressobj(9, zlib.DEFLATED, 31)
    member = c.compress(block) + c.flush()
    with open(path, "wb") as fh:
        for _ in range(int(gigabytes * 1024 / 32)):
            fh.write(member)
    return path


# ----------------------------------------------------------------------------- gzip limits


def test_gzip_members_are_read_whole(tmp_path: Path) -> None:
    path = tmp_path / "a.nmea.gz"
    path.write_bytes(gzip.compress(SENTENCE * 3) + gzip.compress(SENTENCE))
    assert read_input_bytes(path) == SENTENCE * 4
    plain = tmp_path / "b.nmea"
    plain.write_bytes(SENTENCE)
    assert read_input_bytes(plain) == SENTENCE


def test_a_truncated_gzip_is_an_input_error(tmp_path: Path) -> None:
    path = tmp_path / "a.nmea.gz"
    path.write_bytes(gzip.compress(os.urandom(200_000))[:-100])
    with pytest.raises(InputError, match="truncated or corrupt gzip"):
        read_input_bytes(path)


def test_the_size_limit_is_configurable(tmp_path: Path) -> None:
    path = tmp_path / "a.nmea.gz"
    path.write_bytes(gzip.compress(os.urandom(3 * MB)))  # incompressible: the ratio is ~1
    assert len(read_input_bytes(path)) == 3 * MB
    with input_limits(InputLimits(max_decompressed_mb=2)), pytest.raises(InputError, match="max_decompressed_mb"):
        read_input_bytes(path)


def test_a_gzip_bomb_is_refused_on_its_ratio(tmp_path: Path) -> None:
    bomb = _gzip_bomb(tmp_path / "bomb.nmea.gz", 0.25)
    with pytest.raises(InputError, match="max_ratio") as info:
        read_input_bytes(bomb)
    assert info.value.path == str(bomb)
    with input_limits(InputLimits(max_ratio=1e6)):
        assert len(read_input_bytes(bomb)) > 200 * MB  # a larger limit lets it through


def test_a_gzip_bomb_under_a_memory_limit_exits_2_with_a_message(tmp_path: Path) -> None:
    bomb = _gzip_bomb(tmp_path / "bomb.nmea.gz", 3)  # 3 GB of sentences, ~10 MB on disk
    res = _cli(
        ["logs", "import", str(bomb), "--vehicle", str(RECORDERS / "vehicle.toml"), "--out", "o"],
        tmp_path,
        address_space=2 << 30,
    )
    assert res.returncode == 2, res.stderr
    message = " ".join(res.stderr.split())
    assert f"{bomb}: decompresses to more than 100 times" in message and "Traceback" not in res.stderr


def test_logs_import_applies_the_input_section_of_its_config(tmp_path: Path) -> None:
    src = tmp_path / "rx.nmea.gz"
    src.write_bytes(gzip.compress((RECORDERS / "sample.nmea").read_bytes()))
    cfg = tmp_path / "limits.toml"
    cfg.write_text("[input]\nmax_decompressed_mb = 0.0002\n", encoding="utf-8")
    args = ["logs", "import", str(src), "--vehicle", str(RECORDERS / "vehicle.toml"), "--out", str(tmp_path / "o")]
    res = CliRunner().invoke(app, [*args, "--config", str(cfg)], env={"COLUMNS": "300"})
    assert res.exit_code == 2 and "max_decompressed_mb" in res.output, res.output
    assert CliRunner().invoke(app, args).exit_code in (0, 1)  # the defaults let it through


def test_config_show_has_the_input_section(runner: CliRunner) -> None:
    res = runner.invoke(app, ["config", "show", "--section", "input"])
    assert res.exit_code == 0 and "max_decompressed_mb" in res.output and "max_ratio" in res.output


# ------------------------------------------------------------------------- format detection


def test_format_detection_reads_a_head_only(tmp_path: Path) -> None:
    big = tmp_path / "huge.log"
    with open(big, "wb") as fh:
        fh.write(SENTENCE)
        fh.truncate(3 << 30)  # 3 GB (sparse): reading it whole exceeds the memory limit below
    bomb = _gzip_bomb(tmp_path / "bomb.gz", 3)
    code = (
        "import resource, sys\n"
        "resource.setrlimit(resource.RLIMIT_AS, (1 << 30, 1 << 30))\n"
        "from pathlib import Path\n"
        "from fieldlogs.recorders.importer import detect_format\n"
        "print(detect_format(Path(sys.argv[1])), detect_format(Path(sys.argv[2])))\n"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    res = subprocess.run(
        [sys.executable, "-c", code, str(big), str(bomb)], env=env, capture_output=True, text=True, timeout=120
    )
    assert res.returncode == 0 and res.stdout.split() == ["nmea", "nmea"], res.stderr
    assert read_head(bomb, 100) == (SENTENCE * 2)[:100]
    assert len(read_head(bomb)) == 4096


# ------------------------------------------------------------------------------ xlsx bombs


def _xlsx_bomb(path: Path, megabytes: int) -> Path:
    """A valid workbook whose sheet holds ``megabytes`` MB of identical rows."""
    book = openpyxl.Workbook()
    book.active.title = "balises"
    book.active.append(["balise_id"])
    small = path.with_suffix(".small.xlsx")
    book.save(small)
    row = b'<row><c t="inlineStr"><is><t>x</t></is></c></row>'
    with zipfile.ZipFile(small) as zin, zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED, compresslevel=9) as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename != "xl/worksheets/sheet1.xml":
                zout.writestr(item, data)
                continue
            head, tail = data.split(b"</sheetData>")
            with zout.open(item.filename, "w", force_zip64=True) as fh:
                fh.write(head)
                chunk = row * (MB // len(row))
                for _ in range(megabytes):
                    fh.write(chunk)
                fh.write(b"</sheetData>" + tail)
    small.unlink()
    return path


def test_an_xlsx_bomb_is_refused_before_openpyxl_reads_it(tmp_path: Path) -> None:
    bomb = _xlsx_bomb(tmp_path / "balises.xlsx", 64)
    with pytest.raises(InputError, match="max_ratio"):
        check_zip(bomb)
    with input_limits(InputLimits(max_decompressed_mb=32, max_ratio=1e6)), pytest.raises(InputError, match="MB"):
        check_zip(bomb)


def test_an_xlsx_bomb_in_a_source_set_exits_2_under_a_memory_limit(tmp_path: Path) -> None:
    src = tmp_path / "src"
    shutil.copytree(sample_source_dir(), src)
    (src / "balises.csv").unlink()
    bomb = _xlsx_bomb(src / "balises.xlsx", 256)
    res = _cli(["db", "build", str(src), "--out", str(tmp_path / "o.sqlite")], tmp_path, address_space=2 << 30)
    assert res.returncode == 2, res.stderr
    assert f"{bomb}: decompresses to more than" in " ".join(res.stderr.split())


# ------------------------------------------------------------------------ not regular files


def test_regular_file_refuses_what_is_not_one(tmp_path: Path) -> None:
    fifo = tmp_path / "db.sqlite"
    os.mkfifo(fifo)
    with pytest.raises(InputError, match="FIFO"):
        regular_file(fifo)
    with pytest.raises(InputError, match="character device"):
        regular_file(Path("/dev/null"))
    with pytest.raises(InputError, match="folder"):
        regular_file(tmp_path)
    with pytest.raises(InputError, match="no such file"):
        regular_file(tmp_path / "missing")
    sock_path = tmp_path / "s.sock"
    with socket.socket(socket.AF_UNIX) as sock:
        sock.bind(str(sock_path))
        with pytest.raises(InputError, match="socket"):
            regular_file(sock_path)


@pytest.mark.parametrize(
    "command",
    ["validate", "run", "diff", "logs import", "release", "gz", "vehicle", "config", "railml", "build", "build csv"],
)
def test_a_fifo_given_as_an_input_is_refused_not_opened(tmp_path: Path, sample_db: Path, command: str) -> None:
    fifo = tmp_path / ("in.nmea.gz" if command == "gz" else "in.sqlite")
    os.mkfifo(fifo)
    vehicle = ["--vehicle", str(RECORDERS / "vehicle.toml")]
    src = tmp_path / "src"
    if command in ("build", "build csv"):  # a source set whose balises.xlsx (.csv) is a FIFO
        shutil.copytree(sample_source_dir(), src)
        (src / "balises.csv").unlink()
        os.mkfifo(src / ("balises.xlsx" if command == "build" else "balises.csv"))
    args = {
        "vehicle": ["logs", "import", str(RECORDERS / "sample.nmea"), "--vehicle", str(fifo), "--out", "o"],
        "config": ["run", str(tmp_path), "--db", str(sample_db), "--config", str(fifo), "--out", "o"],
        "railml": ["db", "import", str(fifo), "--format", "railml", "--out", "o"],
        "build": ["db", "build", str(src), "--out", "o.sqlite"],
        "build csv": ["db", "build", str(src), "--out", "o.sqlite"],
        "validate": ["db", "validate", str(fifo)],
        "run": ["run", str(tmp_path), "--db", str(fifo), "--out", "o"],
        "diff": ["db", "diff", str(sample_db), str(fifo)],
        "logs import": ["logs", "import", str(fifo), *vehicle, "--out", "o"],
        "release": ["db", "release", str(fifo), "--registry", "reg"],
        "gz": ["logs", "import", str(fifo), "--format", "nmea", *vehicle, "--out", "o"],
    }[command]
    res = _cli(args, tmp_path)
    assert res.returncode == 2, res.stderr
    assert "FIFO" in res.stderr and "not opened" in " ".join(res.stderr.split())


def test_hatanaka_output_is_within_the_limits(tmp_path: Path) -> None:
    import hatanaka

    from fieldlogs.recorders.common import read_text

    rnx = ROOT / "tests" / "data" / "rinex" / "OPEC00NOR_S_20220010000_01D_30S_MO_excerpt.rnx"
    crx = tmp_path / "rx.crx"
    crx.write_bytes(hatanaka.rnx2crx(rnx.read_bytes()))
    size = len(read_text(crx))
    assert size > len(crx.read_bytes())
    limit = (size - 1) / MB
    with input_limits(InputLimits(max_decompressed_mb=limit)), pytest.raises(InputError, match="max_decompressed_mb"):
        read_text(crx)


def test_out_of_memory_is_exit_2_with_a_message(monkeypatch: pytest.MonkeyPatch, sample_db: Path) -> None:
    import dbtools.validate

    def exhausted(*_: object, **__: object) -> None:
        raise MemoryError

    monkeypatch.setattr(dbtools.validate, "validate_path", exhausted)
    res = CliRunner().invoke(app, ["db", "validate", str(sample_db)], env={"COLUMNS": "300"})
    assert res.exit_code == 2 and "out of memory" in res.output and "[input] max_decompressed_mb" in res.output
    assert "internal error" not in res.output
