"""Tables printed by the command line (``bench``, ``batch --report``): counts as
integers, and columns split over several tables that each fit the terminal's width."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

#: Width the printed tables fit when the terminal's is unknown.
WIDTH = 80
#: Characters a column takes besides its text (rich's padding and border).
COLUMN_OVERHEAD = 3


def format_column(values: Sequence[Any], digits: int = 3) -> list[str]:
    """The cells of one column: a column whose numbers are all whole (counts) as integers,
    other floats with ``digits`` decimals, NaN and None empty, anything else as ``str``."""
    numbers = [v for v in values if isinstance(v, (int, float)) and not isinstance(v, bool)]
    finite = [float(v) for v in numbers if not math.isnan(float(v))]
    whole = bool(finite) and all(v.is_integer() for v in finite)
    out = []
    for v in values:
        if v is None or (isinstance(v, float) and math.isnan(v)):
            out.append("")
        elif isinstance(v, (int, float)) and not isinstance(v, bool):
            out.append(str(int(v)) if whole else f"{float(v):.{digits}f}")
        else:
            out.append(str(v))
    return out


def fit_columns(rows: Sequence[Sequence[str]], width: int = WIDTH) -> list[list[list[str]]]:
    """``rows`` (header first) split into tables of at most ``width`` characters: each
    repeats the first column (the row's name) and takes as many of the next columns as fit.

    Parameters
    ----------
    rows : sequence of sequence of str
        The header and the rows, all of the same length.
    width : int
        Characters per line.

    Returns
    -------
    list of tables, each a list of rows (header first)
    """
    widths = [max(len(str(r[i])) for r in rows) + COLUMN_OVERHEAD for i in range(len(rows[0]))]
    tables: list[list[int]] = []
    current: list[int] = []
    used = widths[0] + 1
    for i in range(1, len(widths)):
        if current and used + widths[i] > width:
            tables.append(current)
            current, used = [], widths[0] + 1
        current.append(i)
        used += widths[i]
    tables.append(current)
    return [[[r[0], *(r[i] for i in columns)] for r in rows] for columns in tables]
