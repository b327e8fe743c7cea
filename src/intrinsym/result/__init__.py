"""What a run produced and its folder: the :class:`Result`, its record, its exports.

:mod:`.result` is the :class:`Result` and its folder (``result.npz``, ``run.json``,
``symmetries.json``, the maps); :mod:`.runinfo` what a run records about itself;
:mod:`.modes` the two answers of a match; :mod:`.export` a saved symmetry as vertex
colours (PLY, trimesh, polyscope) with the colours of :mod:`.coloring`.
"""

from __future__ import annotations

from .export import export_ply, to_trimesh
from .modes import Modes, two_modes
from .result import Result
from .runinfo import RunInfo

__all__ = ["Modes", "Result", "RunInfo", "export_ply", "to_trimesh", "two_modes"]
