"""The research data folder of the benchmark scripts: ``--data DIR`` or ``$INTRINSYM_DATA``.

The data set (TOSCA, KIDS, SCAPE, Sumner's horse, a few static meshes) is not
distributed with intrinsym; a script that needs it skips with one line and exit code 0
when neither names an existing folder.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

#: The environment variable naming the data folder when ``--data`` is not given.
ENV = "INTRINSYM_DATA"


def add_data_argument(parser: argparse.ArgumentParser, text: str = "research data folder") -> None:
    """Add ``--data DIR`` (default: ``$INTRINSYM_DATA``) to ``parser``."""
    parser.add_argument("--data", metavar="DIR", help=f"{text} (default: ${ENV})")


def data_folder(arg: str | Path | None) -> Path | None:
    """The data folder named by ``arg``, else by ``$INTRINSYM_DATA``; None when neither
    is set or the folder named does not exist."""
    value = arg if arg else os.environ.get(ENV)
    if not value:
        return None
    path = Path(value).expanduser()
    return path if path.is_dir() else None


def no_data(script: str, arg: str | Path | None) -> str:
    """The one line a script prints when :func:`data_folder` found nothing."""
    value = arg if arg else os.environ.get(ENV)
    if not value:
        return f"{script}: skipped, no research data folder (give --data DIR or set {ENV})"
    return f"{script}: skipped, research data not found: {value}"
