"""The in-memory shape: a validated triangle mesh or point cloud, its cleaning and geometry.

:func:`from_arrays` builds a :class:`Shape` from arrays and checks them, :func:`clean`
repairs it (merges duplicate vertices, drops degenerate and duplicate faces and
unreferenced vertices), and :func:`surface_area` and :func:`vertex_normals` give its
basic geometry. Problems are reported as :class:`~intrinsym.errors.InputError`.
Files are read by :func:`intrinsym.mesh.io.load`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.csgraph import (
    breadth_first_order,
    connected_components,
    minimum_spanning_tree,
)
from scipy.spatial import cKDTree

from ..errors import InputError, path_label

MERGE_TOLERANCE = 1e-9
"""Vertices closer than this fraction of the bounding-box diagonal are merged."""
MAX_COORDINATE = 1e50
"""Largest accepted coordinate magnitude (keeps squared areas far from overflow)."""
DEGENERATE_RATIO = 1e-12
"""Triangles whose height over their longest edge is below this fraction of
that edge's length are treated as having zero area."""


@dataclass(frozen=True, eq=False)
class Shape:
    """A triangle mesh or a point cloud.

    Attributes
    ----------
    vertices : np.ndarray
        (N, 3) float64 vertex coordinates, in the file's units and in its order
        (:func:`~intrinsym.mesh.io.load`): a result's vertex indices index these.
    faces : np.ndarray or None
        (F, 3) int64 vertex indices of the triangles, or None for a point
        cloud.
    path : str
        Where the shape came from ("" if it was built in memory).

    Notes
    -----
    Shapes built by :func:`from_arrays`, :func:`~intrinsym.mesh.io.load` and :func:`clean` hold
    read-only copies of their arrays, so a shape cannot change after it has
    been validated. Equality and hashing are by identity.
    """

    vertices: np.ndarray
    faces: np.ndarray | None
    path: str = ""

    @property
    def is_cloud(self) -> bool:
        """True if the shape is a point cloud (has no faces)."""
        return self.faces is None


# ----------------------------------------------------------------------------
# construction and validation
# ----------------------------------------------------------------------------


def from_arrays(vertices, faces=None, path: str = "") -> Shape:
    """Build a validated :class:`Shape` from arrays.

    Parameters
    ----------
    vertices : array_like
        (N, 3) real coordinates; N >= 4, all finite.
    faces : array_like or None
        (F, 3) integer vertex indices in ``[0, N)`` with F >= 1, or None for a
        point cloud. Float arrays holding whole numbers are accepted.
    path : str
        Where the data came from; used in error messages and stored on the
        shape.

    Returns
    -------
    Shape
        A shape with read-only float64 vertices and int64 faces (copies of the
        inputs).

    Raises
    ------
    InputError
        If the arrays have the wrong shape or type, contain NaN/inf, have
        fewer than 4 points, or a face index is out of range.
    """
    label = path_label(path)
    if np.iscomplexobj(vertices):
        raise InputError(f"{label}: vertex coordinates are complex numbers, expected real numbers")
    try:
        verts = np.array(vertices, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise InputError(f"{label}: vertices are not a numeric array ({err})") from None
    if verts.ndim != 2 or verts.shape[1] != 3:
        raise InputError(f"{label}: vertices must be an (N, 3) array, got shape {verts.shape}")
    finite = np.isfinite(verts).all(axis=1)
    if not finite.all():
        bad = np.flatnonzero(~finite)
        raise InputError(f"{label}: {bad.size} vertices have NaN or infinite coordinates (first: vertex {bad[0]})")
    largest = float(np.abs(verts).max(initial=0.0))
    if largest > MAX_COORDINATE:
        raise InputError(
            f"{label}: coordinates as large as {largest:.3g} are out of range "
            f"(the limit is {MAX_COORDINATE:.0e}); rescale the shape"
        )
    n = verts.shape[0]
    if n < 4:
        raise InputError(f"{label}: only {n} points; at least 4 are needed")
    verts.setflags(write=False)
    if faces is None:
        return Shape(vertices=verts, faces=None, path=os.fsdecode(path))
    return Shape(vertices=verts, faces=_validated_faces(faces, n, label), path=os.fsdecode(path))


def _validated_faces(faces, n_vertices: int, label: str) -> np.ndarray:
    """Check an (F, 3) index array against N vertices; return a read-only int64 copy."""
    arr = np.asarray(faces)
    if arr.dtype.kind == "f":
        if not np.isfinite(arr).all() or not np.array_equal(arr, np.round(arr)):
            raise InputError(f"{label}: face indices must be whole numbers")
    elif arr.dtype.kind not in "iu":
        raise InputError(f"{label}: face indices must be integers, got dtype {arr.dtype}")
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise InputError(f"{label}: faces must be an (F, 3) array of triangles, got shape {arr.shape}")
    if arr.shape[0] == 0:
        raise InputError(f"{label}: the mesh has no faces (use faces=None for a point cloud)")
    lo, hi = arr.min(), arr.max()
    if lo < 0 or hi >= n_vertices:
        bad = lo if lo < 0 else hi
        raise InputError(f"{label}: face index {int(bad)} out of range (the shape has {n_vertices} vertices)")
    out = np.array(arr, dtype=np.int64)
    out.setflags(write=False)
    return out


# ----------------------------------------------------------------------------
# cleaning
# ----------------------------------------------------------------------------


def _unique_rows(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Group equal rows of an (n, c) array (a faster ``np.unique(axis=0)``).

    Returns
    -------
    first : np.ndarray
        (u,) int64 index of the first occurrence of every distinct row, in
        lexicographic order of the rows.
    inverse : np.ndarray
        (n,) int64 group of every row, indexing ``first``.
    """
    order = np.lexsort(rows.T[::-1])  # stable: equal rows keep their input order
    ordered = rows[order]
    starts = np.ones(len(rows), dtype=bool)
    starts[1:] = (ordered[1:] != ordered[:-1]).any(axis=1)
    inverse = np.empty(len(rows), dtype=np.int64)
    inverse[order] = np.cumsum(starts) - 1
    return order[starts], inverse


def _merge_vertices(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge exact duplicates and vertices within MERGE_TOLERANCE x bbox diagonal.

    Returns
    -------
    merged : np.ndarray
        (M, 3) coordinates; each group is represented by its lowest-index
        member, and groups keep the order of their first member.
    vertex_map : np.ndarray
        (N,) int64 index into ``merged`` for every input vertex.
    """
    first_copy, inverse = _unique_rows(vertices)  # -0.0 == 0.0 here, as wanted
    unique = vertices[first_copy]
    diagonal = float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0)))
    pairs = cKDTree(unique).query_pairs(MERGE_TOLERANCE * diagonal, output_type="ndarray")
    if len(pairs):
        graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(unique), len(unique)))
        _, group_of_unique = connected_components(graph, directed=False)
    else:
        group_of_unique = np.arange(len(unique))
    group = group_of_unique[inverse]
    _, first = np.unique(group, return_index=True)  # lowest input index of every group
    n_groups = len(first)
    order = np.argsort(first, kind="stable")
    rank = np.empty(n_groups, dtype=np.int64)
    rank[order] = np.arange(n_groups, dtype=np.int64)
    return vertices[first[order]], rank[group]


def clean(shape: Shape) -> tuple[Shape, np.ndarray]:
    """Repair a shape so that downstream geometry is well defined.

    Merges exactly duplicate vertices and near-duplicates (closer than 1e-9
    of the bounding-box diagonal). For meshes it then drops degenerate faces
    (a repeated vertex, or zero area: height over the longest edge below
    1e-12 of its length),
    duplicate faces (same vertex set, whatever the order or orientation;
    the first is kept) and vertices referenced by no face, and winds the faces
    consistently (:func:`orient_faces`). Several connected components are
    kept. Surviving vertices and faces keep their relative order, so a clean
    input comes back unchanged.

    Parameters
    ----------
    shape : Shape
        Mesh or point cloud.

    Returns
    -------
    cleaned : Shape
        The repaired shape (same ``path``).
    vertex_map : np.ndarray
        (N_input,) int64: for every input vertex, the index of the cleaned
        vertex that represents it. A dropped unreferenced vertex maps to the
        nearest kept vertex.

    Raises
    ------
    InputError
        If nothing usable is left (no valid face, or fewer than 4 vertices).
    """
    label = path_label(shape.path)
    merged, vertex_map = _merge_vertices(np.asarray(shape.vertices, dtype=np.float64))
    if shape.faces is None:
        if len(merged) < 4:
            raise InputError(
                f"{label}: only {len(merged)} distinct points after merging duplicates; at least 4 are needed"
            )
        return from_arrays(merged, None, shape.path), vertex_map

    faces = vertex_map[np.asarray(shape.faces)]
    distinct = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    corners = merged[faces]
    edges = corners[:, [1, 2, 0]] - corners
    twice_area = np.linalg.norm(np.cross(edges[:, 0], edges[:, 2]), axis=1)
    longest_sq = (edges**2).sum(axis=2).max(axis=1)
    valid = distinct & (twice_area > DEGENERATE_RATIO * longest_sq)  # 2A / L^2 = height / L
    faces = faces[valid]
    if len(faces) == 0:
        raise InputError(
            f"{label}: no usable faces: all {len(shape.faces)} faces are degenerate (zero area or repeated vertices)"
        )
    first, _ = _unique_rows(np.sort(faces, axis=1))
    faces = orient_faces(faces[np.sort(first)])

    used = np.zeros(len(merged), dtype=bool)
    used[faces.ravel()] = True
    if used.sum() < 4:
        raise InputError(
            f"{label}: only {int(used.sum())} distinct vertices left after cleaning; at least 4 are needed"
        )
    new_index = np.cumsum(used) - 1
    if not used.all():
        kept = np.flatnonzero(used)
        _, nearest = cKDTree(merged[kept]).query(merged[~used])
        new_index[~used] = new_index[kept[nearest]]
    cleaned = from_arrays(merged[used], new_index[faces], shape.path)
    return cleaned, new_index[vertex_map]


def orient_faces(faces: np.ndarray) -> np.ndarray:
    """The faces wound consistently: two faces that share an edge run it in opposite
    directions.

    Meshes from scans and exports are not always wound consistently, and the vertex
    normals follow the winding (:func:`vertex_normals`), so do the spin images and the
    reflection test of the global/partial decision (:mod:`intrinsym.extract.reflection`;
    measured in docs/results.md, "Robustness to real-scan defects"). The
    faces connected across manifold edges (shared by exactly two faces) are made
    consistent along a breadth-first tree of that adjacency, and each such set keeps the
    winding most of its faces had (the first face's on a tie). Written here rather than
    with ``trimesh.repair.fix_winding``, which needs networkx and visits the face pairs
    in a Python loop: this is a few vectorised passes.

    Parameters
    ----------
    faces : (F, 3) int array
        Triangles with three distinct vertices, no two with the same vertex set.

    Returns
    -------
    (F, 3) int array
        ``faces`` itself when it is wound consistently already; else a copy in which
        some faces have their vertex order reversed. A non-orientable part (a Moebius
        strip) keeps one seam of faces that disagree.
    """
    f = np.asarray(faces)
    n_faces = len(f)
    if n_faces < 2:
        return faces
    tail = f.ravel().astype(np.int64)
    head = f[:, [1, 2, 0]].ravel().astype(np.int64)
    key = np.minimum(tail, head) * (int(f.max()) + 1) + np.maximum(tail, head)
    order = np.argsort(key, kind="stable")
    # runs of equal keys: an edge shared by exactly two faces joins them
    start = np.flatnonzero(np.r_[True, key[order[1:]] != key[order[:-1]]])
    size = np.diff(np.r_[start, len(order)])
    a, b = order[start[size == 2]], order[start[size == 2] + 1]
    same = tail[a] == tail[b]  # both run it the same way: one of the two must turn
    if not same.any():
        return faces
    fa, fb = a // 3, b // 3
    n_parts, part = connected_components(
        coo_matrix((np.ones(len(fa)), (fa, fb)), shape=(n_faces, n_faces)), directed=False
    )
    # node n_faces is a root joined to one face of every part, so that one breadth-first
    # search reaches them all; the weight is 1 + (the two faces disagree)
    first = np.unique(part, return_index=True)[1]
    rows = np.r_[fa, fb, np.full(n_parts, n_faces)]
    cols = np.r_[fb, fa, first]
    weight = np.r_[1 + same, 1 + same, np.ones(n_parts, dtype=np.int64)]
    graph = csr_matrix((weight, (rows, cols)), shape=(n_faces + 1, n_faces + 1))
    _, parent = breadth_first_order(graph, n_faces, directed=True, return_predecessors=True)
    parent[n_faces] = n_faces
    children = np.arange(n_faces)
    turn = np.zeros(n_faces + 1, dtype=np.int64)
    turn[children] = np.asarray(graph[parent[children], children]).ravel() - 1
    # pointer jumping: turn[v] becomes the parity of the disagreements from v to the root
    while (parent != n_faces).any():
        turn ^= turn[parent]
        parent = parent[parent]
    turn = turn[:n_faces].astype(bool)
    turn ^= (2 * np.bincount(part, weights=turn, minlength=n_parts) > np.bincount(part, minlength=n_parts))[part]
    out = f.copy()
    out[turn] = out[turn][:, ::-1]
    return out


# ----------------------------------------------------------------------------
# geometry
# ----------------------------------------------------------------------------


def _sixth_neighbour_squared(vertices: np.ndarray) -> np.ndarray:
    """(N,) squared distance from every point to its 6th nearest other point."""
    k = min(7, len(vertices))
    distances, _ = cKDTree(vertices).query(vertices, k=k)
    return distances[:, -1] ** 2


def _triangle_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F,) area of every triangle."""
    corners = vertices[np.asarray(faces)]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    return 0.5 * np.linalg.norm(cross, axis=1)


def surface_area(shape: Shape) -> float:
    """Total surface area, in squared file units.

    Parameters
    ----------
    shape : Shape
        Mesh or point cloud.

    Returns
    -------
    float
        For a mesh, the sum of the triangle areas. For a point cloud an
        *estimate*: the sum over points of ``pi * r6**2 / 6``, where ``r6`` is
        the distance to the 6th nearest other point. This is unbiased for
        uniformly random (Poisson) sampling of a smooth surface; it
        underestimates regular grids (by up to ~40% on a hexagonal lattice)
        and is skewed by duplicate points, so call it on a cleaned cloud.
    """
    vertices = np.asarray(shape.vertices, dtype=np.float64)
    if shape.faces is None:
        return float(np.pi * np.sum(_sixth_neighbour_squared(vertices)) / 6.0)
    return float(_triangle_areas(vertices, shape.faces).sum())


def vertex_areas(shape: Shape) -> np.ndarray:
    """Area each vertex stands for, in squared file units; they sum to :func:`surface_area`.

    Computed here rather than by trimesh (``faces_sparse @ area_faces / 3``, which the
    tests check it against) so that a point cloud gets the estimate of
    :func:`surface_area` and a mesh needs no Trimesh object.

    Parameters
    ----------
    shape : Shape
        Mesh or point cloud with N vertices.

    Returns
    -------
    (N,) float64
        For a mesh, a third of the area of every triangle around the vertex (0 for a
        vertex no triangle uses); for a point cloud, ``pi * r6**2 / 6`` as in
        :func:`surface_area`.
    """
    vertices = np.asarray(shape.vertices, dtype=np.float64)
    if shape.faces is None:
        return np.pi * _sixth_neighbour_squared(vertices) / 6.0
    faces = np.asarray(shape.faces, dtype=np.int64)
    thirds = np.repeat(_triangle_areas(vertices, faces) / 3.0, 3)
    return np.bincount(faces.ravel(), weights=thirds, minlength=len(vertices))


def vertex_normals(shape: Shape, k: int = 12) -> np.ndarray:
    """Unit normal at every vertex.

    Parameters
    ----------
    shape : Shape
        Mesh or point cloud with N vertices.
    k : int
        Point clouds only: number of nearest neighbours used to fit the
        tangent plane (clipped to N - 1); must be >= 2.

    Returns
    -------
    np.ndarray
        (N, 3) float64 unit vectors.

    Notes
    -----
    Meshes: area-weighted face normals summed at the vertices, so the
    orientation follows the face winding. A vertex whose sum vanishes (e.g.
    unreferenced) takes the normal of the nearest vertex with a valid one,
    or (0, 0, 1) if there is none.

    Point clouds (Hoppe et al. 1992): the normal is the smallest principal
    direction of the point and its k nearest neighbours. Orientation is made
    consistent by propagation along a minimum spanning tree of the kNN graph
    with edge weights ``1 - |n_i . n_j|``; each connected component is then
    flipped so that most of its normals point away from its centroid.
    """
    if k < 2:
        raise ValueError(f"k must be at least 2, got {k}")
    vertices = np.asarray(shape.vertices, dtype=np.float64)
    if shape.faces is None:
        return _cloud_normals(vertices, k)
    return _mesh_normals(vertices, np.asarray(shape.faces))


def _mesh_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals (N, 3) of a triangle mesh."""
    n = len(vertices)
    corners = vertices[faces]
    face_normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    flat = faces.ravel()
    sums = np.stack(
        [np.bincount(flat, weights=np.repeat(face_normals[:, c], 3), minlength=n) for c in range(3)],
        axis=1,
    )
    length = np.linalg.norm(sums, axis=1)
    valid = length > 0
    normals = np.zeros_like(sums)
    normals[valid] = sums[valid] / length[valid, None]
    if not valid.all():
        if valid.any():
            _, nearest = cKDTree(vertices[valid]).query(vertices[~valid])
            normals[~valid] = normals[np.flatnonzero(valid)[nearest]]
        else:
            normals[:] = (0.0, 0.0, 1.0)
    return normals


def _cloud_normals(points: np.ndarray, k: int) -> np.ndarray:
    """PCA normals (N, 3) of a point cloud, consistently oriented (see vertex_normals)."""
    n = len(points)
    k = min(k, n - 1)
    _, neighbours = cKDTree(points).query(points, k=k + 1)
    patches = points[neighbours]
    patches = patches - patches.mean(axis=1, keepdims=True)
    covariance = np.einsum("nki,nkj->nij", patches, patches)
    _, eigenvectors = np.linalg.eigh(covariance)
    normals = eigenvectors[:, :, 0]

    # kNN graph; weights 2 - |n_i.n_j| give the same spanning tree as 1 - |n_i.n_j|
    # but are never zero, which sparse graphs would read as a missing edge.
    rows = np.repeat(np.arange(n), k + 1)
    cols = neighbours.ravel()
    keep = rows != cols
    rows, cols = rows[keep], cols[keep]
    weights = 2.0 - np.abs(np.einsum("ij,ij->i", normals[rows], normals[cols]))
    tree = minimum_spanning_tree(coo_matrix((weights, (rows, cols)), shape=(n, n)).tocsr())
    n_components, component = connected_components(tree, directed=False)

    # Root every component's tree at a virtual node n, so one BFS gives all parents.
    _, roots = np.unique(component, return_index=True)
    tree = tree.tocoo()
    forest = coo_matrix(
        (
            np.concatenate([tree.data, np.ones(n_components)]),
            (
                np.concatenate([tree.row, np.full(n_components, n)]),
                np.concatenate([tree.col, roots]),
            ),
        ),
        shape=(n + 1, n + 1),
    ).tocsr()
    _, predecessors = breadth_first_order(forest, n, directed=False, return_predecessors=True)
    parent = predecessors[:n].copy()
    parent[roots] = roots

    # sign[i]: flip of i relative to parent[i]; pointer jumping turns it into the
    # flip relative to the component root in O(log depth) vectorised steps.
    sign = np.where(np.einsum("ij,ij->i", normals, normals[parent]) < 0, -1.0, 1.0)
    while not np.array_equal(parent, parent[parent]):
        sign = sign * sign[parent]
        parent = parent[parent]
    normals = normals * sign[:, None]

    counts = np.bincount(component, minlength=n_components)
    centroids = (
        np.stack(
            [np.bincount(component, weights=points[:, c], minlength=n_components) for c in range(3)],
            axis=1,
        )
        / counts[:, None]
    )
    outward = np.einsum("ij,ij->i", normals, points - centroids[component]) > 0
    votes = np.bincount(component, weights=np.where(outward, 1.0, -1.0), minlength=n_components)
    return normals * np.where(votes < 0, -1.0, 1.0)[component, None]
