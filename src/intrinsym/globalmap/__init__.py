"""The dense global map: a symmetry of every vertex, chosen by the marginals (after the
paper's Sec. 5.1; the paper stops at the sampled symmetries).

:mod:`.globalmap` chooses among candidate maps (the extraction's, seeded ZoomOut's,
the spectral ones) by the marginal mass they keep; :mod:`.refine` refines a map by
geodesic trilateration and spectral descent; :mod:`.part_map` chooses a part's map
into its whole (the extraction's, a partial functional map's from :mod:`.partial_fmap`,
refined, or trilaterated by :mod:`.part_trilateration`, or located from a consistent
cluster of descriptor matches by :mod:`.part_hypothesis`, or blended from these by
:mod:`.part_blend`), in the order :mod:`.part_chain` runs them; :mod:`.vertex_maps` extends a sampled
symmetry to every input vertex; :mod:`.confidence` measures how far the marginals
support a map (and calibrates it); :mod:`.distortion` how far a map is from an isometry,
without ground truth.
"""

from __future__ import annotations

from .confidence import calibration_report, kept_mass, map_mass
from .distortion import DistortionScores, local_distortion, map_distortion
from .globalmap import GlobalMap, choose_global_map, supported_map
from .refine import spectral_descent, trilaterate
from .vertex_maps import fitted_vertex_map, vertex_map

__all__ = [
    "DistortionScores",
    "GlobalMap",
    "calibration_report",
    "choose_global_map",
    "fitted_vertex_map",
    "kept_mass",
    "local_distortion",
    "map_distortion",
    "map_mass",
    "spectral_descent",
    "supported_map",
    "trilaterate",
    "vertex_map",
]
