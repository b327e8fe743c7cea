"""The input shape: reading files, the validated mesh or point cloud, sampling it.

Pipeline stage 0 (before the paper's Sec. 3): a file or arrays become a :class:`Shape`
(:mod:`.io` reads OFF / OBJ / XYZ through :mod:`.io_text` and PLY through :mod:`.io_ply`;
:mod:`.shape` validates, cleans and measures it); :mod:`.sampling` picks the Poisson-disc
samples Ps and Pt (paper Sec. 4) and subdivides a coarse mesh. :mod:`.generated` makes
shapes whose symmetries are known exactly (the ground truth of the generated benchmarks).

The working surface the stages run on (cleaned, unit area, with its geodesic graph) is
:func:`intrinsym.prepare` (:mod:`intrinsym.surface`), above this package: it needs the
geodesics and the parameters.
"""

from __future__ import annotations

from .generated import GeneratedShape, generate
from .io import load
from .sampling import farthest_point_sampling, subdivide_to
from .shape import Shape, clean, from_arrays, surface_area, vertex_areas, vertex_normals

__all__ = [
    "GeneratedShape",
    "Shape",
    "clean",
    "farthest_point_sampling",
    "from_arrays",
    "generate",
    "load",
    "subdivide_to",
    "surface_area",
    "vertex_areas",
    "vertex_normals",
]
