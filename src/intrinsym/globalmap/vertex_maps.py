"""Symmetries extended from the samples to every input vertex.

:func:`vertex_map` gives each input vertex the image of the source sample whose
geodesic Voronoi cell holds it; :func:`fitted_vertex_map` refines that by local linear
fits (beyond the paper); :func:`carried_to_components` carries a dense map onto the
connected components the model does not see; :func:`inverse_vertex_map` inverts a map of
a part into its whole, "no match" where the part has no counterpart.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..extract.support import SourceGraph, Support
from ..extract.symmetry import ExtractParams, Symmetry

#: A carried component moves as the mapped vertices within this distance of it do
#: (sqrt(area) units, beyond its own radius): about the default sample spacing, a patch
#: around it curved enough to fix the motion
#: (:func:`intrinsym.globalmap.vertex_maps.carried_to_components`).
CARRY_REACH = 0.05
#: ... and at least this many of them (the nearest).
CARRY_MIN = 20


def vertex_map(symmetry: Symmetry, vertex_source: np.ndarray, target_vertex: np.ndarray, n_source: int) -> np.ndarray:
    """Extend a symmetry to every input vertex.

    Each input vertex takes the image of the source sample whose geodesic Voronoi cell
    holds it.

    Parameters
    ----------
    symmetry : Symmetry
    vertex_source : (N,) int64
        Source sample owning every input vertex (-1 where none).
    target_vertex : (T,) int64
        Input vertex (of the target shape) of every target sample.
    n_source : int

    Returns
    -------
    (N,) int64
        Target input vertex of every input vertex, -1 where the symmetry says nothing.
    """
    image = np.append(symmetry.image(n_source), -1)
    sample = image[np.where(vertex_source >= 0, vertex_source, n_source)]
    return np.where(sample >= 0, np.asarray(target_vertex)[np.maximum(sample, 0)], -1).astype(np.int64)


def _members(owner: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Indices grouped by owner: ``order[bounds[i]:bounds[i + 1]]`` are those with
    ``owner == i`` (entries -1 belong to none)."""
    order = np.argsort(owner, kind="stable")
    return order, np.searchsorted(owner[order], np.arange(n + 1))


def fitted_vertex_map(
    symmetry: Symmetry,
    support: Support,
    edges: np.ndarray,
    source_points: np.ndarray,
    target_points: np.ndarray,
    target_vertex: np.ndarray,
    params: ExtractParams = ExtractParams(),
) -> np.ndarray:
    """Extend a symmetry to every input vertex through local linear fits (beyond the paper).

    :func:`vertex_map` gives every vertex of a sample's Voronoi cell the sample's image,
    so parts are resolved only to the sample spacing. Here a mapped sample s with
    at least two mapped neighbours n fits the linear map L (least squares, minimum norm)
    with L (p_n - p_s) = q_f(n) - q_f(s); when every neighbour's residual is at most
    ``params.vertex_fit`` times its edge, each vertex x of the cell goes to the target
    vertex nearest q_f(s) + L (x - p_s) among those in the cells of the targets within
    ``support.targets.radius`` of f(s). The other vertices keep :func:`vertex_map`.

    Parameters
    ----------
    symmetry : Symmetry
    support : Support
        Needs ``source_mesh_vertices`` and ``target_mesh_vertices``; without them (or with
        ``params.vertex_fit`` 0) this is :func:`vertex_map`.
    edges : (E, 2) int64
    source_points, target_points : (S, 3), (T, 3) float64
        Sample positions in the frame of the support's vertices.
    target_vertex : (T,) int64
    params : ExtractParams

    Returns
    -------
    (N_a,) int64
        Target input vertex of every source input vertex, -1 where the symmetry says
        nothing.
    """
    n_s = len(source_points)
    out = vertex_map(symmetry, support.vertex_source, target_vertex, n_s)
    if params.vertex_fit <= 0 or support.source_mesh_vertices is None or support.target_mesh_vertices is None:
        return out
    graph = SourceGraph.from_edges(edges, support.edge_length, n_s)
    image = symmetry.image(n_s)
    cell_order, cell_bounds = _members(np.asarray(support.vertex_source), n_s)
    target_order, target_bounds = _members(np.asarray(support.vertex_target), len(target_points))
    t = support.targets
    for s in np.flatnonzero(image >= 0):
        cell = cell_order[cell_bounds[s] : cell_bounds[s + 1]]
        nbr = graph.neighbour[graph.ptr[s] : graph.ptr[s + 1]]
        nbr = nbr[image[nbr] >= 0]
        if len(nbr) < 2 or not len(cell):
            continue
        d = source_points[nbr] - source_points[s]
        e = target_points[image[nbr]] - target_points[image[s]]
        lin = np.linalg.lstsq(d, e, rcond=None)[0]
        if np.max(np.linalg.norm(d @ lin - e, axis=1) / np.linalg.norm(d, axis=1)) > params.vertex_fit:
            continue
        nearby = t.indices[t.indptr[image[s]] : t.indptr[image[s] + 1]]
        candidates = np.sort(np.concatenate([target_order[target_bounds[j] : target_bounds[j + 1]] for j in nearby]))
        y = target_points[image[s]] + (support.source_mesh_vertices[cell] - source_points[s]) @ lin
        out[cell] = candidates[cKDTree(support.target_mesh_vertices[candidates]).query(y)[1]]
    return out


def carried_to_components(
    positions: np.ndarray, component: np.ndarray, vertex_map: np.ndarray, held: np.ndarray
) -> np.ndarray:
    """A dense self-map carried onto the connected components the model does not see.

    Such a component (a tooth or an eye modelled apart, a scan's floating island) holds
    too few source samples for the marginals to say where it goes, and no geodesic
    reaches it. It moves with the surface around it, so it takes the rigid motion (a
    reflection allowed; least squares, Kabsch) that best carries the mapped vertices of
    the held components near it onto their images: those within ``CARRY_REACH`` of it,
    beyond its own radius, and at least ``CARRY_MIN``. It goes onto the component
    nearest its moved copy (the mean distance from each vertex of either to the other: a
    tooth onto the mirror tooth, not onto the tooth beside it nor onto the gum around
    it) among those within reach but the ones that surface and its image lie on, each
    vertex to the vertex of that component nearest its moved position.

    Parameters
    ----------
    positions : (N, 3) float array
        Vertex positions (sqrt(area) units).
    component : (N,) int array
        Connected component of every vertex.
    vertex_map : (N,) int64
        Image of every vertex, -1 for none.
    held : (N,) bool
        Vertices of the components whose map stays; the others are carried.

    Returns
    -------
    (N,) int64
        ``vertex_map`` with every vertex of a carried component re-mapped (-1 where no
        component lies within reach of its moved copy); unchanged when every vertex is
        held, or fewer than four held vertices are mapped.
    """
    out = np.array(vertex_map, dtype=np.int64)
    anchors = np.flatnonzero(held & (out >= 0))
    if held.all() or len(anchors) < 4:
        return out
    anchor_tree = cKDTree(positions[anchors])
    labels, label = np.unique(component, return_inverse=True)
    order, bounds = _members(label.ravel(), len(labels))
    parts = [order[bounds[i] : bounds[i + 1]] for i in range(len(labels))]
    centres = np.array([positions[m].mean(axis=0) for m in parts])
    radii = np.array([np.linalg.norm(positions[m] - c, axis=1).max() for m, c in zip(parts, centres, strict=True)])
    centre_tree = cKDTree(centres)
    trees: dict[int, cKDTree] = {}
    for i in np.unique(label[~held]):
        members = parts[i]
        near = anchor_tree.query_ball_point(centres[i], radii[i] + CARRY_REACH)
        if len(near) < CARRY_MIN:
            near = anchor_tree.query(centres[i], k=min(CARRY_MIN, len(anchors)))[1]
        x = positions[anchors[near]]
        y = positions[out[anchors[near]]]
        u, _, vt = np.linalg.svd((x - x.mean(axis=0)).T @ (y - y.mean(axis=0)))
        moved = (positions[members] - x.mean(axis=0)) @ (u @ vt) + y.mean(axis=0)
        # the components within reach of the moved one, but the surface that carries it
        carrier = set(label[anchors[near]]) | set(label[out[anchors[near]]])
        middle = moved.mean(axis=0)
        options = [
            j
            for j in centre_tree.query_ball_point(middle, radii[i] + radii.max() + CARRY_REACH)
            if j not in carrier and np.linalg.norm(centres[j] - middle) <= radii[i] + radii[j] + CARRY_REACH
        ]
        if not options:
            out[members] = -1
            continue
        moved_tree = cKDTree(moved)
        fits = []
        for j in options:
            if j not in trees:
                trees[j] = cKDTree(positions[parts[j]])
            # both ways: a tooth moved into a larger part lies near it, not the part near the tooth
            forward = trees[j].query(moved)
            fits.append((forward[0].mean() + moved_tree.query(positions[parts[j]])[0].mean(), forward[1]))
        best = int(np.argmin([cost for cost, _ in fits]))
        out[members] = parts[options[best]][fits[best][1]]
    return out


def inverse_vertex_map(
    image: np.ndarray,
    vertices: np.ndarray,
    vertex_area: np.ndarray,
    part_area: float,
    reach: float,
    centres: np.ndarray | None = None,
) -> np.ndarray:
    """A map of a part into its whole, inverted: "no match" where the part has no counterpart.

    The part's counterpart on the whole has the part's area (the match is near
    isometric), and lies where the part's vertices map: the whole's vertices nearest an
    image (straight line), up to ``part_area`` of them and none farther than ``reach``
    from every image, take the part vertex whose image lies nearest; the others, cut away
    on the part, take -1 ("no match"). ``reach`` keeps a map that collapses the part onto
    a small region from claiming the whole's vertices around it. Among the part vertices
    that share an image, the first of ``centres`` (a map extended from samples sends each
    sample's cell to one vertex: the sample stands for it), else the lowest index.

    Parameters
    ----------
    image : (M,) int array
        The map being inverted: vertex of the whole of every part vertex, -1 for none.
    vertices : (N, 3) float array
        Positions of the whole's vertices.
    vertex_area : (N,) float array
        Area each of them stands for (:func:`intrinsym.mesh.shape.vertex_areas`), in the
        square of the positions' unit.
    part_area : float
        The part's area, in the same unit.
    reach : float
        The farthest a vertex of the counterpart lies from an image, in the positions' unit.
    centres : (S,) int array, optional
        Part vertices preferred among those that share an image.

    Returns
    -------
    (N,) int64
        Part vertex of every vertex of the whole, -1 where it has no counterpart.
    """
    image = np.asarray(image, dtype=np.int64)
    out = np.full(len(vertices), -1, dtype=np.int64)
    first = np.zeros(len(image), dtype=bool) if centres is None else np.isin(np.arange(len(image)), centres)
    order = np.argsort(~first, kind="stable")  # the centres first, each group by index
    hit, at = np.unique(image[order], return_index=True)
    keep = hit >= 0
    hit, owner = hit[keep], order[at[keep]]
    if not len(hit):
        return out
    dist, nearest = cKDTree(np.asarray(vertices, dtype=np.float64)[hit]).query(vertices)
    rank = np.argsort(dist, kind="stable")
    count = np.searchsorted(np.cumsum(np.asarray(vertex_area, dtype=np.float64)[rank]), part_area, side="right")
    covered = rank[: min(count, int(np.sum(dist <= reach)))]
    out[covered] = owner[nearest[covered]]
    return out
