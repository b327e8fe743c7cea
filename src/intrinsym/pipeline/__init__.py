"""End-to-end detection: shape -> samples -> geodesics -> descriptors -> MRF -> BP ->
extraction -> global map.

:func:`detect` matches a shape to itself (partial intrinsic symmetries); :func:`match`
matches shape A to shape B (the paper's ambiguous two-shape case). Both return a
:class:`~intrinsym.result.result.Result`. The steps between (:func:`pairwise_model`,
:func:`unary_model`, :func:`solve_bp`, :func:`extraction_support`,
:func:`extract_symmetries`, :func:`intrinsym.globalmap.globalmap.choose_global_map`) can run
alone: they take the sampled problem (:class:`intrinsym.problem.Problem`, from
:func:`intrinsym.problem.sampled`) or arrays, and return arrays.

Modules: :mod:`~intrinsym.pipeline.inputs` (parameters, working size, samples),
:mod:`~intrinsym.pipeline.stages` (the stages shared by both),
:mod:`~intrinsym.pipeline.self_matching` (:func:`detect`, :func:`prepare`) and
:mod:`~intrinsym.pipeline.two_shapes` (:func:`match`, :func:`invert_part_match`).
"""

from .inputs import check_machine, min_vertices, resolve_params, sample_pair
from .self_matching import detect, prepare
from .stages import (
    BPOutcome,
    Pairwise,
    decide_identity,
    extract_result,
    extract_symmetries,
    extraction_support,
    pairwise_model,
    solve_bp,
    unary_model,
)
from .two_shapes import COVER_SPACINGS, checked_symmetry, invert_part_match, match, part_params, part_target_params

__all__ = [
    "COVER_SPACINGS",
    "BPOutcome",
    "Pairwise",
    "check_machine",
    "checked_symmetry",
    "decide_identity",
    "detect",
    "extract_result",
    "extract_symmetries",
    "extraction_support",
    "invert_part_match",
    "match",
    "min_vertices",
    "pairwise_model",
    "part_params",
    "part_target_params",
    "prepare",
    "sample_pair",
    "resolve_params",
    "solve_bp",
    "unary_model",
]
