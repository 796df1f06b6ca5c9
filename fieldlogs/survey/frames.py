"""Small frame helpers of the survey."""

from __future__ import annotations

from types import SimpleNamespace

import pandas as pd


def rows(frame: pd.DataFrame) -> list[SimpleNamespace]:
    """The rows of ``frame`` with attribute access (``row.km_m``), values as pandas holds them."""
    return [SimpleNamespace(**{str(k): v for k, v in rec.items()}) for rec in frame.to_dict("records")]
