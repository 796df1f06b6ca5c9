"""Options that several commands share, declared once: the same flag, the same help text, the
same default everywhere it appears."""

from __future__ import annotations

from typing import Any

import typer

#: ``--no-verify-hash``, the one opt-out of the content-hash check (``dbtools.integrity``)
#: for every command that loads an onboard DB: declare a parameter ``no_verify_hash`` with
#: this default; :func:`cli.errors.cli_command` reads it, the command body need not.
NO_VERIFY_HASH = typer.Option(
    False,
    "--no-verify-hash",
    help="Use an onboard DB whose content no longer matches the content hash stored when it was built "
    "(edited or corrupted); it is refused (exit 2) without this. The DB used is named in a warning.",
)

#: ``--dask-scheduler``: the commands that replay many runs can run them on a Dask cluster
#: through the same replayer as the local process pool (``fieldlogs.replay``).
DASK_SCHEDULER = typer.Option(
    None, "--dask-scheduler", help="Replay on this Dask cluster (tcp://host:8786) instead of local processes."
)


def workers_option(doing: str = "replaying runs") -> Any:
    """``--workers/-j N``: processes of the one replayer (``fieldlogs.replay``); default all
    cores, 1 = in the command's own process. ``doing`` says what the processes do."""
    return typer.Option(None, "--workers", "-j", min=1, help=f"Processes {doing} (default: all cores; 1 = in-process).")


#: ``--delimiter`` and ``--decimal``: the CSV convention of a user's spreadsheet export
#: (``dbtools.csv_locale``), for every command reading source sets, plans or mapped CSV.
DELIMITER = typer.Option(
    None,
    "--delimiter",
    help="Field delimiter of the CSV inputs: ',', ';', tab (or 'tab') or '|' (default: detected from the first "
    "lines; a file that contradicts it is refused).",
)
DECIMAL = typer.Option(
    None,
    "--decimal",
    help="Decimal separator of the CSV inputs' number columns: '.' or ',' (default: detected from the cells when the "
    "delimiter is not a comma; a cell that contradicts it is refused).",
)


def csv_locale(delimiter: str | None, decimal: str | None) -> Any:
    """The ``dbtools.csv_locale.CsvLocale`` of ``--delimiter``/``--decimal`` (None: neither
    given); UsageError on a value that is no delimiter or decimal separator."""
    if delimiter is None and decimal is None:
        return None
    from dbtools.csv_locale import CsvLocale

    return CsvLocale(delimiter, decimal)
