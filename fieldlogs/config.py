"""The suite's configuration tree: every setting of every application, declared once.

One TOML file (``--config FILE.toml``) configures every command: ``run``, ``audit`` and
``gis verify`` read the pipeline's sections (``[odometry]``, ``[balise]``, ``[feature]``,
``[gps]``, ``[margin]``, ``[gnss]``, ``[clock]``, ``[window]``, ``[track_select]``, ``cycle_s``), ``gis verify``
also ``[gis_verify]``,
``possession check`` reads ``[gps]`` and ``[possession]``, ``survey`` the pipeline's sections
and ``[survey]``; each command refuses unknown sections and keys, wrong types and values out
of range; every command with ``--config`` applies its ``[input]`` section (limits of compressed
inputs, :mod:`dbtools.inputs`). ``trainpos config show`` prints the whole tree (or one section) with every
default, unit, range and meaning as commented TOML; fed back with ``--config`` it changes
nothing.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from dbtools.gis.verify.config import VerifyConfig
from fieldlogs.gnss.config import GnssConfig
from fieldlogs.pipeline.config import (
    CYCLE_S,
    BaliseConfig,
    ClockConfig,
    FeatureConfig,
    GpsConfig,
    MarginConfig,
    OdometryConfig,
    PipelineConfig,
    TrackSelectConfig,
    WindowConfig,
    check_budgets,
    read_toml,
)
from fieldlogs.possession.config import PossessionConfig
from fieldlogs.survey.config import SurveyConfig
from schemas.errors import InputError, UsageError
from schemas.inputs import InputLimits
from schemas.settings import SettingError, check_ranges, describe, render_toml, section_from_dict, setting, typed


@dataclass(frozen=True)
class SuiteConfig:
    """Every section of the configuration tree."""

    odometry: OdometryConfig = field(default_factory=OdometryConfig)
    balise: BaliseConfig = field(default_factory=BaliseConfig)
    feature: FeatureConfig = field(default_factory=FeatureConfig)
    gps: GpsConfig = field(default_factory=GpsConfig)
    margin: MarginConfig = field(default_factory=MarginConfig)
    gnss: GnssConfig = field(default_factory=GnssConfig)
    clock: ClockConfig = field(default_factory=ClockConfig)
    window: WindowConfig = field(default_factory=WindowConfig)
    track_select: TrackSelectConfig = field(default_factory=TrackSelectConfig)
    possession: PossessionConfig = field(default_factory=PossessionConfig)
    survey: SurveyConfig = field(default_factory=SurveyConfig)
    gis_verify: VerifyConfig = field(default_factory=VerifyConfig)
    input: InputLimits = field(default_factory=InputLimits)
    cycle_s: float = setting(**CYCLE_S)

    def __post_init__(self) -> None:
        check_ranges(self)

    @property
    def pipeline(self) -> PipelineConfig:
        return PipelineConfig(
            self.odometry,
            self.balise,
            self.feature,
            self.gps,
            self.margin,
            self.cycle_s,
            gnss=self.gnss,
            clock=self.clock,
            window=self.window,
            track_select=self.track_select,
        )

    @classmethod
    def from_toml(cls, path: Path) -> SuiteConfig:
        return cls.from_dict(read_toml(path), source=str(path))

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "config") -> SuiteConfig:
        """Overrides from ``data`` (a TOML table per section, plain settings at the top)."""
        tree = cls()
        names = [f.name for f in fields(cls)]
        for key, value in data.items():
            if key not in names:
                raise InputError(f"unknown section or key '{key}' (known: {', '.join(names)})", path=source)
            current = getattr(tree, key)
            try:
                if isinstance(value, dict) and hasattr(current, "__dataclass_fields__"):
                    tree = replace(tree, **{key: section_from_dict(current, value, key, source)})
                elif hasattr(current, "__dataclass_fields__"):
                    raise InputError(f"'{key}' must be a table ([{key}])", path=source)
                else:
                    tree = replace(tree, **{key: typed(source, key, current, value)})
            except SettingError as exc:
                raise SettingError(exc.message, path=source) from None
        check_budgets(tree.balise, tree.feature, tree.clock, source)
        return tree


def load_tree(path: Path | None) -> SuiteConfig:
    """The tree with the overrides of ``path`` (defaults without a file)."""
    return SuiteConfig.from_toml(path) if path is not None else SuiteConfig()


def section_names(tree: Any) -> list[str]:
    return [k for k, v in describe(tree).items() if "value" not in v]


def show_toml(tree: Any, section: str | None = None) -> str:
    _known(tree, section)
    return render_toml(tree, section)


def show_dict(tree: Any, section: str | None = None) -> dict[str, Any]:
    _known(tree, section)
    return describe(tree, section)


def _known(tree: Any, section: str | None) -> None:
    names = section_names(tree)
    if section is not None and section not in names:
        raise UsageError(f"no config section '{section}' (known: {', '.join(names)})")
