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

import importlib.resources
from pathlib import Path

from ._version import __version__


def example_path() -> Path:
    """Path of the shipped example mesh (Keenan Crane's spot, public domain)."""
    return Path(str(importlib.resources.files("intrinsym") / "data" / "spot.obj"))


from .errors import InputError, IntrinsymError, ParameterError, ResourceError  # noqa: E402
from .evaluate import MapScores, MarginalScores, load_symmetry_map, score_map, score_marginals  # noqa: E402
from .extract import Extraction, ExtractParams, Symmetry  # noqa: E402
from .io import load  # noqa: E402
from .params import Params, make_params  # noqa: E402
from .pipeline import detect, match  # noqa: E402
from .progress import BPIteration, StageDone  # noqa: E402
from .result import Result  # noqa: E402
from .runinfo import RunInfo  # noqa: E402
from .shape import Shape  # noqa: E402

__all__ = [
    "BPIteration",
    "ExtractParams",
    "Extraction",
    "InputError",
    "IntrinsymError",
    "MapScores",
    "MarginalScores",
    "ParameterError",
    "Params",
    "ResourceError",
    "Result",
    "RunInfo",
    "Shape",
    "StageDone",
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
