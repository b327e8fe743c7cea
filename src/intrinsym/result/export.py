"""A saved result's symmetry as vertex colours: a PLY file, a trimesh object, a polyscope view.

The colours are those of :func:`intrinsym.result.coloring.vertex_colors`; the vertices are the
input's, in its order (``symmetry_map.npy`` indexes them: docs/format.md#vertex-order).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import IO, Any

import numpy as np

from ..errors import InputError
from ..evaluation.evaluate import load_confidence, load_symmetry_map
from ..files import atomic_write
from ..mesh.io import load
from ..mesh.shape import Shape
from .coloring import MODES, as_rgba8, vertex_colors

#: What ``intrinsym show`` needs, and how to get it.
POLYSCOPE_MISSING = "intrinsym show needs polyscope: pip install 'intrinsym[polyscope]'"


def saved_maps(out_dir: str | os.PathLike, shape: Shape) -> tuple[np.ndarray, np.ndarray | None]:
    """``symmetry_map.npy`` and ``symmetry_confidence.npy`` (None when absent) of a result
    folder, checked against ``shape``'s vertex count."""
    out = Path(out_dir)
    n = len(shape.vertices)
    if not (out / "symmetry_map.npy").is_file():
        raise InputError(f"{out}: no symmetry_map.npy (rerun intrinsym detect; match results have none)")
    m = load_symmetry_map(out / "symmetry_map.npy", n, allow_missing=True)
    conf = out / "symmetry_confidence.npy"
    return m, load_confidence(conf, n) if conf.is_file() else None


def to_trimesh(
    shape: Shape, symmetry_map: np.ndarray, confidence: np.ndarray | None = None, color: str = "side"
) -> Any:
    """A ``trimesh.Trimesh`` (a ``trimesh.PointCloud`` for a cloud) of ``shape``'s vertices in
    their order, coloured by ``color`` (one of :data:`intrinsym.result.coloring.MODES`), with the
    map and the confidence in ``metadata``."""
    import trimesh

    rgba = as_rgba8(vertex_colors(shape, symmetry_map, color, confidence))
    meta = {"symmetry_map": np.asarray(symmetry_map), "symmetry_confidence": confidence, "color": color}
    if shape.faces is None:
        return trimesh.PointCloud(shape.vertices, colors=rgba, metadata=meta)
    return trimesh.Trimesh(shape.vertices, shape.faces, vertex_colors=rgba, process=False, metadata=meta)


def write_ply(obj: Any, path: str | os.PathLike) -> Path:
    """Write a :func:`to_trimesh` object as a binary PLY with its vertex colours (atomically)."""
    data = obj.export(file_type="ply")

    def write(f: IO[bytes]) -> None:
        f.write(data)

    atomic_write(path, write, binary=True)
    return Path(path)


def export_ply(
    out_dir: str | os.PathLike, ply: str | os.PathLike, color: str = "side", mesh: str | None = None
) -> Path:
    """``intrinsym export``: a result folder's symmetry as a coloured PLY of its input.

    Parameters
    ----------
    out_dir : path
        A folder written by ``intrinsym detect``.
    ply : path
        The PLY file to write.
    color : str
        One of :data:`intrinsym.result.coloring.MODES`.
    mesh : path, optional
        The mesh of the result (default: the input named in ``run.json``).
    """
    if color not in MODES:
        raise InputError(f"--color {color!r}: expected one of {', '.join(MODES)}")
    shape = load(mesh if mesh is not None else _input_of(out_dir))
    m, conf = saved_maps(out_dir, shape)
    if color == "confidence" and conf is None:
        raise InputError(f"{out_dir}: no symmetry_confidence.npy for --color confidence")
    return write_ply(to_trimesh(shape, m, conf, color), ply)


def _input_of(out_dir: str | os.PathLike) -> str:
    """The input named in the folder's ``run.json``."""
    from .result import Result

    return Result.load(out_dir).info.input


def show(out_dir: str | os.PathLike, mesh: str | None = None) -> None:
    """``intrinsym show``: the result's symmetry in a polyscope window (side, partner and
    confidence colours as quantities to switch between)."""
    try:
        import polyscope as ps
    except ImportError:
        raise InputError(POLYSCOPE_MISSING) from None
    shape = load(mesh if mesh is not None else _input_of(out_dir))
    m, conf = saved_maps(out_dir, shape)
    ps.init()
    if shape.faces is None:
        view = ps.register_point_cloud("input", shape.vertices)
    else:
        view = ps.register_surface_mesh("input", shape.vertices, shape.faces)
    for mode in MODES:
        if mode != "confidence" or conf is not None:
            view.add_color_quantity(mode, vertex_colors(shape, m, mode, conf), enabled=mode == "side")
    ps.show()
