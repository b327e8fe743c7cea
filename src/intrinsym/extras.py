"""The optional parts of the install and the one-line error a missing one gives.

``pip install intrinsym`` holds what ``detect``, ``match`` and ``evaluate`` use;
``[batch]`` adds Dask and the summary table's libraries (``intrinsym batch``), ``[viz]``
matplotlib (figures: ``render``, ``--figures``, ``curve.png``, the batch report),
``[gpu]`` CuPy and ``[polyscope]`` the viewer window. Their modules are imported where
they are used, never when :mod:`intrinsym` is.
"""

from __future__ import annotations

import importlib

from .errors import MissingExtraError

#: The modules each extra installs that intrinsym imports (bokeh, in ``[batch]`` for the
#: Dask dashboard, is optional to Dask itself).
EXTRAS: dict[str, tuple[str, ...]] = {
    "batch": ("dask", "distributed", "pandas", "pyarrow"),
    "viz": ("matplotlib",),
}


def available(extra: str) -> bool:
    """Whether every module of ``extra`` (a key of :data:`EXTRAS`) imports."""
    try:
        for name in EXTRAS[extra]:
            importlib.import_module(name)
    except ImportError:
        return False
    return True


def require(extra: str, what: str) -> None:
    """Raise :class:`~intrinsym.errors.MissingExtraError` (one line naming ``what`` and
    the extra to install) unless :func:`available`."""
    if not available(extra):
        raise MissingExtraError(f"{what} needs the [{extra}] extra: pip install 'intrinsym[{extra}]'")
