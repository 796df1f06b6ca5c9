"""Typed errors → one line on stderr and a documented exit code; never a traceback."""

from __future__ import annotations

import contextlib
import errno
import functools
import os
import sys
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import typer

from cli.render import err_console, print_findings, safe
from dbtools.inputs import input_limits
from dbtools.integrity import HashPolicy, hash_policy
from schemas.errors import EXIT_UNREADABLE, FindingsError, TrainposError

EXIT_INTERNAL = 4
F = TypeVar("F", bound=Callable[..., Any])


def cli_command(fn: F) -> F:
    """Wrap a command: typed errors become a message and their exit code.

    An unexpected exception (a bug) exits 4 with a one-line message; set
    ``TRAINPOS_DEBUG=1`` to see the traceback.
    """

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            with (
                hash_policy(verify=not kwargs.get("no_verify_hash", False)) as policy,
                _input_limits(kwargs.get("config")),
            ):
                try:
                    return fn(*args, **kwargs)
                finally:
                    _warn_unverified(policy)
        except typer.Exit:
            raise
        except FindingsError as exc:
            print_findings(exc.findings, console=err_console())
            err_console().print(f"[bold red]error:[/] {safe(exc)}", highlight=False)
            raise typer.Exit(exc.exit_code) from None
        except TrainposError as exc:
            err_console().print(f"[bold red]error:[/] {safe(exc)}", highlight=False)
            raise typer.Exit(exc.exit_code) from None
        except KeyboardInterrupt:
            err_console().print("interrupted")
            raise typer.Exit(130) from None
        except MemoryError:  # the environment, not a bug: an input too large for this machine
            err_console().print(
                "[bold red]error:[/] out of memory: an input is too large for this machine's memory "
                + safe("(compressed inputs: lower [input] max_decompressed_mb in a --config file to be told which)"),
                highlight=False,
            )
            raise typer.Exit(EXIT_UNREADABLE) from None
        except OSError as exc:  # the environment, not a bug: permission denied, disk full, …
            err_console().print(f"[bold red]error:[/] {safe(environment_message(exc))}", highlight=False)
            raise typer.Exit(EXIT_UNREADABLE) from None
        except Exception as exc:  # a bug: say so plainly, keep the traceback for debugging
            if os.environ.get("TRAINPOS_DEBUG"):
                traceback.print_exc(file=sys.stderr)
            err_console().print(
                f"[bold red]internal error:[/] {safe(type(exc).__name__)}: {safe(exc)} "
                "(this is a bug in trainpos; set TRAINPOS_DEBUG=1 for details)",
                highlight=False,
            )
            raise typer.Exit(EXIT_INTERNAL) from None

    return wrapper  # type: ignore[return-value]


def _input_limits(config: object) -> contextlib.AbstractContextManager[object]:
    """The ``[input]`` limits of a command's ``--config`` file in force (:mod:`dbtools.inputs`)."""
    if not isinstance(config, Path):
        return contextlib.nullcontext()
    from fieldlogs.config import load_tree

    return input_limits(load_tree(config).input)


def _warn_unverified(policy: HashPolicy) -> None:
    for line in dict.fromkeys(policy.used_unverified):  # once per DB, in order
        err_console().print(f"[bold yellow]warning:[/] {safe(line)}; used anyway (--no-verify-hash)", highlight=False)


def environment_message(exc: OSError) -> str:
    """One line for an error of the machine (a file system, a disk): what, where, why."""
    where = exc.filename if exc.filename is not None else ""
    why = exc.strerror or type(exc).__name__
    if exc.errno == errno.ENOSPC:
        why += " (free some space and run the command again: nothing was half-written)"
    elif exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
        why += " (check the folder's permissions)"
    return f"{where}: {why}" if where else why
