"""intrinsym: partial intrinsic symmetries of 3D shapes.

The model of Lasowski et al., "A Probabilistic Framework for Partial Intrinsic Symmetries
in Geometric Data" (ICCV 2009): an MRF over correspondences with a spin-image NMI unary
and a truncated geodesic pairwise term, whose marginals are computed by loopy
sum-product belief propagation with an exact sparse message.

>>> import intrinsym
>>> result = intrinsym.detect(intrinsym.example_path(), n_source=60, n_target=600)
>>> result.marginals.shape
(60, 600)
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

__version__ = "0.1.0"


def example_path() -> Path:
    """Path of the shipped example mesh (Keenan Crane's spot, public domain)."""
    return Path(str(resources.files("intrinsym") / "data" / "spot.obj"))


from .evaluate import MapScores, MarginalScores, load_symmetry_map, score_map, score_marginals  # noqa: E402
from .extract import Extraction, ExtractParams, Symmetry  # noqa: E402
from .mesh import InputError, Shape, load  # noqa: E402
from .pipeline import Params, ParameterError, Result, detect, make_params, match  # noqa: E402

__all__ = [
    "ExtractParams",
    "Extraction",
    "InputError",
    "MapScores",
    "MarginalScores",
    "ParameterError",
    "Params",
    "Result",
    "Shape",
    "Symmetry",
    "__version__",
    "detect",
    "example_path",
    "load",
    "load_symmetry_map",
    "make_params",
    "match",
    "score_map",
    "score_marginals",
]
