"""Limits on what reading one input file may cost: the ``[input]`` section of the
configuration tree, applied by the one input-opening mechanism (:mod:`dbtools.inputs`) to
every compressed input — a gzip file (``.nmea.gz``, ``.ubx.gz``, ``.obs.gz``), the members
of an ``.xlsx`` workbook (a zip) — before its content is held in memory, and to an XML
file (railML) before it is parsed."""

from __future__ import annotations

from dataclasses import dataclass

from schemas.settings import check_ranges, setting

#: Bytes a compressed input may decompress to whatever its ratio: small files may compress
#: arbitrarily well (an empty sheet, a file of one repeated sentence), so the ratio limit
#: applies only beyond this size.
RATIO_FREE_BYTES = 16 << 20
#: Bytes format detection reads (decompressed) from the start of an input.
HEAD_BYTES = 4096


@dataclass(frozen=True)
class InputLimits:
    """Limits of compressed inputs: a larger or more compressed one is refused (exit 2)
    before it is decompressed any further, naming the file and the limit."""

    max_decompressed_mb: float = setting(
        512.0,
        "largest decompressed size of one compressed input (a .gz log, an .xlsx workbook's members together)",
        "MB",
        gt=0,
    )
    max_ratio: float = setting(
        100.0,
        f"largest decompressed/compressed size ratio beyond {RATIO_FREE_BYTES >> 20} MB decompressed (a "
        "decompression bomb); recorder logs compress 3–20×, workbooks up to ~50×",
        "",
        gt=1,
    )

    max_xml_mb: float = setting(
        256.0,
        "largest XML file (railML) read: it is parsed as a whole tree so that every finding can name "
        "its line, about 15 bytes of memory per byte of file (256 MB: about 4 GB)",
        "MB",
        gt=0,
    )

    def __post_init__(self) -> None:
        check_ranges(self)

    @property
    def max_bytes(self) -> int:
        """``max_decompressed_mb`` in bytes."""
        return int(self.max_decompressed_mb * (1 << 20))
