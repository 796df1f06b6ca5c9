"""typer's command and group classes of ``trainpos``, coercing plain parameters without pydantic.

typer (0.29) coerces every parameter's value through a pydantic ``TypeAdapter`` it builds on
first use, and imports pydantic for it (0.1 s of start-up, more than the rest of a command's
parsing). :class:`PathCommand` coerces the plain kinds itself — a ``Path``, a ``str``, an
``Enum`` choice — as those adapters do; anything else keeps typer's own coercion.
:class:`Group` is typer's group with its ``--help`` flag defaulting to False.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import Any

from typer._click.exceptions import BadParameter
from typer._click.utils import _escape_control_characters
from typer._coercion import RuntimeParam
from typer._param_types import coerce_cli_choice, coerce_cli_path
from typer.core import TyperCommand, TyperGroup, _TyperParameter

__all__ = ["Group", "PathCommand", "small_pages"]


def small_pages() -> None:
    """Ask numpy, not yet imported, for ordinary 4 KiB pages: ``NUMPY_MADVISE_HUGEPAGE=0``
    unless the user set it. numpy advises the kernel to back every array of 4 MiB or more
    with 2 MiB huge pages; where the kernel then compacts memory to find them (transparent
    huge pages "madvise" with defrag "madvise", a common default), a command that allocates
    and frees many grid-sized arrays — ``db validate`` of a national DB — spends that time in
    the kernel: 0.1 s of its 3.1 s CPU, its peak memory the same (bench/NOTES.md, issue 34).
    No effect once numpy is imported (a test run), nor on any result."""
    os.environ.setdefault("NUMPY_MADVISE_HUGEPAGE", "0")


class Group(TyperGroup):
    """typer's group, its ``--help`` flag defaulting to False instead of None.

    typer coerces a flag's missing value (None) through pydantic, which it imports for
    that: for ``trainpos COMMAND --help`` the groups above COMMAND would import pydantic
    for nothing, more than the rest of the start-up costs (issue 21: ≤ 0.3 s). False is
    what a missing flag means, so the help shown and every exit stay the same.
    """

    def get_help_option(self, ctx: Any) -> Any:
        return _help_default_false(super().get_help_option(ctx))


def _help_default_false(option: Any) -> Any:
    if option is not None and option.default is None:
        option.default = False
    return option


@dataclass(frozen=True)
class _PlainPath(RuntimeParam):
    """typer's coercion of a plain ``Path`` parameter without pydantic: typer turns the text
    into a Path through a pydantic ``TypeAdapter(Path)`` (``Path(text)``) and then calls
    ``coerce_cli_path``; this calls it with ``Path(text)`` itself."""

    def _coerce_value(self, value: Any, param: Any, ctx: Any) -> Any:
        return coerce_cli_path(
            Path(value) if isinstance(value, str) else value, self.parameter_info, path_type=Path, param=param, ctx=ctx
        )


@dataclass(frozen=True)
class _PlainStr(RuntimeParam):
    """typer's coercion of a plain ``str`` parameter without pydantic (``TypeAdapter(str)`` of
    a command-line text is the text itself)."""

    def _coerce_value(self, value: Any, param: Any, ctx: Any) -> Any:
        return value


@dataclass(frozen=True)
class _PlainChoice(RuntimeParam):
    """typer's coercion of an ``Enum`` parameter without pydantic: the adapter typer builds
    calls ``coerce_cli_choice`` with the enumeration's members and reports its ValueError as
    pydantic words it ("Value error, …"); this does the same without the adapter."""

    def _coerce_value(self, value: Any, param: Any, ctx: Any) -> Any:
        choices = list(self.annotation)
        try:
            return coerce_cli_choice(value, choices=choices, case_sensitive=self.parameter_info.case_sensitive, ctx=ctx)
        except ValueError as exc:
            raise BadParameter(_escape_control_characters(f"Value error, {exc}"), ctx=ctx, param=param) from exc


class PathCommand(TyperCommand):
    """typer's command, its plain ``Path`` parameters coerced without importing pydantic
    (0.1–0.2 s of a ``trainpos run``, issue 21; 0.1 s of a ``db validate``, issue 34) and its
    ``--help`` flag defaulting to False (as :class:`Group`'s). Plain: annotated ``Path`` (or
    ``Path | None``), none of typer's path checks (exists, resolve_path, allow_dash, path_type),
    which keep typer's own coercion; every other parameter too. A plain ``str`` (no parser)
    is taken as given, as pydantic would; an ``Enum`` (no parser) is matched to its members
    by typer's own ``coerce_cli_choice``, as typer's adapter does."""

    def get_help_option(self, ctx: Any) -> Any:
        return _help_default_false(super().get_help_option(ctx))

    def parse_args(self, ctx: Any, args: list[str]) -> list[str]:
        for p in self.params:
            if isinstance(p, _TyperParameter) and p._runtime_param is None and _plain_path(p):
                p._runtime_param = _PlainPath(p.type_descriptor.parameter_info, Path)
            elif isinstance(p, _TyperParameter) and p._runtime_param is None and _plain_str(p):
                p._runtime_param = _PlainStr(p.type_descriptor.parameter_info, str)
            elif isinstance(p, _TyperParameter) and p._runtime_param is None and _plain_enum(p):
                p._runtime_param = _PlainChoice(p.type_descriptor.parameter_info, p.type_descriptor.annotation)
        return super().parse_args(ctx, args)


def _plain_str(p: _TyperParameter) -> bool:
    d = p.type_descriptor
    return d.annotation is str and d.parameter_info.parser is None and not (p.multiple or p.nargs != 1)


def _plain_enum(p: _TyperParameter) -> bool:
    d = p.type_descriptor
    plain = d.parameter_info.parser is None and not (p.multiple or p.nargs != 1)
    return isinstance(d.annotation, type) and issubclass(d.annotation, Enum) and plain


def _plain_path(p: _TyperParameter) -> bool:
    d = p.type_descriptor
    info = d.parameter_info
    checks = (info.exists, info.resolve_path, info.allow_dash, info.path_type, info.parser, d.file_annotation)
    return d.annotation is Path and not any(c for c in checks) and not (p.multiple or p.nargs != 1)
