"""What a run starts from: its parameters resolved and checked against the machine,
its working size and its samples."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from ..errors import ParameterError
from ..mesh.shape import Shape
from ..mrf import bp
from ..params import WORK_PER_SAMPLE, Params, make_params
from ..surface import Surface, sample, serves
from ..surface import prepare as prepare_surface


def resolve_params(params: Params | None, preset: str, **common: Any) -> Params:
    """``params`` (or the preset's) with the common keywords that are not None applied."""
    if params is not None and preset != "default":
        raise ParameterError("give params or a preset, not both")
    base = params if params is not None else make_params(preset)
    return dataclasses.replace(base, **{k: v for k, v in common.items() if v is not None})


def check_machine(p: Params) -> None:
    """Raise :class:`ParameterError` when this machine cannot run ``p`` (a GPU backend
    without a GPU, or with a schedule it does not run)."""
    if p.backend == "gpu":
        try:
            bp.resolve_backend(p.backend, p.schedule)
        except ValueError as err:
            raise ParameterError(str(err)) from None


def min_vertices(p: Params) -> int:
    """The working size ``p`` asks for: a mesh with fewer vertices is subdivided until it
    has this many (``WORK_PER_SAMPLE`` times the larger sample count; 0 when neither is
    given)."""
    return WORK_PER_SAMPLE * max(p.n_source or 0, p.n_target or 0)


def working_surface(shape: Shape | Surface, p: Params) -> Surface:
    """The working surface of an input for a run with parameters ``p``: a shape prepared
    (:func:`~intrinsym.surface.prepare`) for their working size, or a
    :class:`~intrinsym.surface.Surface` given, not prepared again.

    Raises
    ------
    ParameterError
        A Surface prepared for another working size.
    """
    if not isinstance(shape, Surface):
        return prepare_surface(shape, min_vertices(p))
    if not serves(shape, min_vertices(p)):
        raise ParameterError(
            f"the surface was prepared for a working size of {shape.min_vertices} vertices (it has "
            f"{len(shape.shape.vertices)}); n_source={p.n_source}, n_target={p.n_target} need "
            f"{min_vertices(p)}: prepare it with these parameters, intrinsym.prepare(shape, params)"
        )
    return shape


def sample_pair(src: Surface, tgt: Surface, p: Params) -> tuple[np.ndarray, np.ndarray]:
    """Working vertices of the source samples (on ``src``, seed ``p.seed + 1``) and of the
    target samples (on ``tgt``, seed ``p.seed``): those of a run with parameters ``p``."""
    return sample(src, p.n_source, p.source_spacing, p.seed + 1), sample(tgt, p.n_target, p.target_spacing, p.seed)
