"""Shapes whose symmetries are known exactly, with ground-truth maps and part labels.

* :func:`cuboctahedron`: the surface of the cuboctahedron, uniformly subdivided; its 48
  symmetries (the octahedral group) permute the 12 vertices.
* :func:`star`: a thick star-shaped plate with k rounded arms; symmetries: the dihedral
  group of order 2k times the flip of the plate.
* :func:`lantern`: a four-armed star in two frames whose arms are bent differently (the
  paper's ambiguous two-shape case); vertex i of one frame corresponds to vertex i and
  to its images under the arm rotations in the other.
* :func:`figure`: a mirror-symmetric articulated figure (head, two arms, two legs) with
  its limbs posed differently: the left/right map is a near-isometry.
* :func:`partial`: an irregular, asymmetric body carrying two identical limbs; its only
  symmetry is partial (limb to limb), so its map is -1 off the limbs.

Every triangulation is invariant under the symmetry group (each quad is split into four
triangles about its centre), so the maps are exact vertex permutations, found by
applying each isometry and matching vertices to 1e-9. A partial symmetry is a map that
holds -1 for every vertex outside its parts (as ``symmetry_map.npy`` does). Bending (posing) moves vertices but
keeps the indexing, so the maps of the unposed shape stay the ground truth. Shapes are
centred at the origin, in arbitrary units (the pipeline normalises the area).
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import numpy as np
from scipy.spatial import cKDTree

from ..files import atomic_write

NAMES = ("cuboctahedron", "star", "lantern", "figure", "partial")
#: Accepted range of each option of :func:`generate`: the cuboctahedron has about
#: 64 4^subdivisions vertices (6: 262146, and 47 maps of them), the others about
#: arms x resolution^2 x 20.
LIMITS = {"subdivisions": (0, 6), "resolution": (2, 100), "arms": (2, 32)}


@dataclass(frozen=True)
class GeneratedShape:
    """A triangle mesh with its ground truth.

    Attributes
    ----------
    name : str
    vertices : (N, 3) float64
    faces : (F, 3) int64
    symmetries : (K, N) int64
        Every non-identity ground-truth symmetry: vertex i maps to ``symmetries[k, i]``,
        -1 where a partial symmetry gives i no image. The first is the principal one (a
        rotation by one arm, the figure's mirror, the partial shape's limb swap).
    labels : (N,) int64
        Part label of every vertex (1, 2, ...; 0 = in no part): the cuboctahedron's 12
        vertex neighbourhoods, the arms, the figure's limbs (1/2 arms, 3/4 legs, 5 head),
        the partial shape's two limbs.
    """

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    symmetries: np.ndarray
    labels: np.ndarray


def _split_quads(vertices: np.ndarray, quads: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Triangulate quads (Q, 4), counter-clockwise, into four triangles about a new centre vertex each."""
    centre = vertices[quads].mean(axis=1)
    c = len(vertices) + np.arange(len(quads))
    tris = np.concatenate([np.column_stack([quads[:, i], quads[:, (i + 1) % 4], c]) for i in range(4)])
    return np.vstack([vertices, centre]), tris


def _subdivide(vertices: np.ndarray, faces: np.ndarray, times: int) -> tuple[np.ndarray, np.ndarray]:
    """Midpoint (1-to-4) subdivision, ``times`` times; preserves every symmetry of the mesh."""
    v, f = vertices, faces
    for _ in range(times):
        edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        uniq, inv = np.unique(edges, axis=0, return_inverse=True)
        mid = len(v) + inv.reshape(3, -1).T
        v = np.vstack([v, v[uniq].mean(axis=1)])
        a, b, c = f.T
        ab, bc, ca = mid.T
        f = np.concatenate([np.column_stack(t) for t in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))])
    return v, f


def _vertex_maps(vertices: np.ndarray, transforms: list) -> np.ndarray:
    """(K, N) vertex permutation of each isometry (callable on (N, 3) arrays)."""
    tree = cKDTree(vertices)
    maps = []
    for transform in transforms:
        dist, idx = tree.query(transform(vertices))
        if dist.max() > 1e-9 * max(1.0, np.abs(vertices).max()):
            raise AssertionError("the triangulation is not invariant under a claimed symmetry")
        maps.append(idx)
    return np.asarray(maps, dtype=np.int64)


def cuboctahedron(subdivisions: int = 3) -> GeneratedShape:
    """The cuboctahedron's surface, 1-to-4 subdivided ``subdivisions`` times.

    Vertices (+-1, +-1, 0) and permutations; 8 triangles and 6 squares (each square split
    about its centre). ``subdivisions`` 3 gives 1026 vertices, 4 gives 4098.
    """
    corners = np.array(
        [
            p
            for axis in range(3)
            for p in np.insert(np.array([[1, 1], [1, -1], [-1, 1], [-1, -1]], float), axis, 0.0, axis=1)
        ]
    )
    quads, tris = [], []
    for axis in range(3):
        for sign in (1.0, -1.0):
            face = np.flatnonzero(np.isclose(corners[:, axis], sign))
            centre = corners[face].mean(axis=0)
            u = corners[face] - centre
            e1 = np.eye(3)[(axis + 1) % 3]
            e2 = np.cross(sign * np.eye(3)[axis], e1)
            quads.append(face[np.argsort(np.arctan2(u @ e2, u @ e1))])
    for sx in (1, -1):
        for sy in (1, -1):
            for sz in (1, -1):
                octant = np.flatnonzero(corners @ np.array([sx, sy, sz]) > 1.5)
                c = corners[octant]
                normal = np.array([sx, sy, sz], float)
                if np.dot(np.cross(c[1] - c[0], c[2] - c[0]), normal) < 0:
                    octant = octant[[0, 2, 1]]
                tris.append(octant)
    v, f = _split_quads(corners, np.array(quads))
    v, f = _subdivide(v, np.vstack([f, np.array(tris)]), subdivisions)
    group = []
    for perm in ([0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]):
        for signs in np.array(np.meshgrid([1, -1], [1, -1], [1, -1])).T.reshape(-1, 3):
            if perm != [0, 1, 2] or np.any(signs < 0):
                group.append(lambda x, p=perm, s=signs: x[:, p] * s)
    labels = np.zeros(len(v), dtype=np.int64)
    dist, idx = cKDTree(corners).query(v)
    labels[dist < 0.35] = idx[dist < 0.35] + 1
    return GeneratedShape("cuboctahedron", v, f, _vertex_maps(v, group), labels)


def _latlon_mesh(
    ring: np.ndarray, pole: float, north: float | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Close a latitude-longitude grid of vertices (n_lat, n_lon, 3) into a triangle mesh.

    Vertices: the grid (row-major), the poles (0, 0, -pole) and (0, 0, north) (``north``
    defaults to ``pole``), then one centre per quad (:func:`_split_quads`); the poles
    are fanned to the first and last row.

    Returns
    -------
    vertices (N, 3), faces (F, 3), quads (Q, 4): the grid quads (row-major), whose
    centres are vertices ``n_lat * n_lon + 2 + q``.
    """
    n_lat, n_lon = ring.shape[:2]
    v = np.vstack([ring.reshape(-1, 3), [[0.0, 0.0, -pole], [0.0, 0.0, pole if north is None else north]]])
    south, north = n_lat * n_lon, n_lat * n_lon + 1
    idx = np.arange(n_lat * n_lon).reshape(n_lat, n_lon)
    nxt = np.roll(idx, -1, axis=1)
    quads = np.stack([idx[:-1], nxt[:-1], nxt[1:], idx[1:]], axis=-1).reshape(-1, 4)
    caps = np.concatenate(
        [
            np.column_stack([nxt[0], idx[0], np.full(n_lon, south)]),
            np.column_stack([idx[-1], nxt[-1], np.full(n_lon, north)]),
        ]
    )
    v, f = _split_quads(v, quads)
    return v, np.vstack([f, caps]), quads


def _lobed(
    lobes: np.ndarray, length: float, width: float, n_lon: int, n_lat: int, thickness: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A closed plate whose outline in the xy-plane has a rounded arm at each angle of ``lobes``.

    Latitude-longitude grid: vertex (lat, lon) sits at r(lon) cos(lat) (cos lon, sin lon)
    in xy and thickness * sin(lat) in z, with r = 1 + length * sum of Gaussian bumps of
    angular width ``width`` at the lobe angles; poles are single vertices. Any rotation
    or reflection that permutes the lobes and maps the longitude grid to itself (n_lon
    a multiple of the symmetry's order) is a symmetry of the mesh.

    Returns
    -------
    vertices (N, 3), faces (F, 3), arm (N,) int64: the nearest lobe of each vertex
    (1-based) where the vertex lies farther than 1 + length / 3 from the z-axis and is
    not equally near two lobes, else 0.
    """
    lon = 2 * np.pi * np.arange(n_lon) / n_lon
    lat = np.pi * (np.arange(1, n_lat) / n_lat - 0.5)
    gap = np.angle(np.exp(1j * (lon[:, None] - lobes[None, :])))
    bumps = np.exp(-((gap / width) ** 2))
    r = 1.0 + length * bumps.sum(axis=1)
    grid_lat, grid_lon = np.meshgrid(lat, np.arange(n_lon), indexing="ij")
    rr = r[grid_lon] * np.cos(grid_lat)
    ring = np.column_stack(
        [
            rr.ravel() * np.cos(lon[grid_lon.ravel()]),
            rr.ravel() * np.sin(lon[grid_lon.ravel()]),
            thickness * np.sin(grid_lat.ravel()),
        ]
    )
    v, f, _ = _latlon_mesh(ring.reshape(len(lat), n_lon, 3), thickness)
    angle = np.arctan2(v[:, 1], v[:, 0])
    gap = np.abs(np.angle(np.exp(1j * (angle[:, None] - lobes[None, :]))))
    nearest = gap.argmin(axis=1)
    two = np.sort(gap, axis=1)[:, :2] if len(lobes) > 1 else np.column_stack([gap[:, 0], gap[:, 0] + 1])
    # a vertex midway between two lobes belongs to neither, so that labels keep the symmetry
    clear = two[:, 1] - two[:, 0] > 1e-6
    radial = np.hypot(v[:, 0], v[:, 1])
    arm = np.where(clear & (radial > 1.0 + length / 3), nearest + 1, 0).astype(np.int64)
    return v, f, arm


def _rotation_z(angle: float):
    c, s = np.cos(angle), np.sin(angle)
    return lambda x: x @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]]).T


def _reflection(angle: float):
    """Reflection in the vertical plane at ``angle`` from the x-axis."""
    c, s = np.cos(2 * angle), np.sin(2 * angle)
    return lambda x: x @ np.array([[c, s, 0], [s, -c, 0], [0, 0, 1.0]]).T


def star(arms: int = 5, resolution: int = 12, length: float = 1.2) -> GeneratedShape:
    """A thick star-shaped plate with ``arms`` arms, 4 * arms symmetries.

    ``resolution`` sets grid cells per arm along the outline (latitude cells follow).
    """
    if arms < 2:
        raise ValueError("a star needs at least 2 arms")
    lobes = 2 * np.pi * np.arange(arms) / arms
    n_lon = 2 * arms * resolution
    v, f, arm = _lobed(lobes, length, 0.35, n_lon, max(6, resolution), 0.25)
    planar = [_rotation_z(2 * np.pi * k / arms) for k in range(arms)] + [
        _reflection(np.pi * k / arms) for k in range(arms)
    ]
    group = planar[1:] + [lambda x, g=g: g(x) * [1.0, 1.0, -1.0] for g in planar]
    return GeneratedShape(f"star{arms}", v, f, _vertex_maps(v, group), arm)


def bend(vertices: np.ndarray, direction: float, start: float, angle: float, span: float) -> np.ndarray:
    """Bend the part of a plate beyond ``start`` along ``direction`` out of the xy-plane.

    The mid-plane is rolled isometrically: along the arm's axis u (unit vector at angle
    ``direction``), the coordinate s = x.u beyond ``start`` is wrapped onto a circular
    arc of total angle ``angle`` over arc length ``span``, then continues straight;
    points off the mid-plane keep their normal offset. Thin plates bend near-isometrically.

    Parameters
    ----------
    vertices : (N, 3)
    direction, angle : float
        Radians.
    start, span : float
        Lengths along the arm.

    Returns
    -------
    (N, 3) float64, a bent copy.
    """
    u = np.array([np.cos(direction), np.sin(direction), 0.0])
    z = np.array([0.0, 0.0, 1.0])
    v = np.array(vertices, dtype=np.float64)
    if angle == 0:
        return v
    s = v @ u
    t = np.clip(s - start, 0.0, None)
    inside = np.minimum(t, span)
    kappa = angle / span
    phi = kappa * inside
    along = np.sin(phi) / kappa
    lift = (1.0 - np.cos(phi)) / kappa
    beyond = t - inside
    tangent = np.outer(np.cos(phi), u) + np.outer(np.sin(phi), z)
    normal = -np.outer(np.sin(phi), u) + np.outer(np.cos(phi), z)
    height = v @ z
    lateral = v - np.outer(s, u) - np.outer(height, z)
    moved = (
        lateral
        + np.outer(np.minimum(s, start), u)
        + np.outer(along, u)
        + np.outer(lift, z)
        + beyond[:, None] * tangent
        + height[:, None] * normal
    )
    return np.where((s > start)[:, None], moved, v)


def lantern(resolution: int = 12) -> tuple[GeneratedShape, GeneratedShape]:
    """Two frames of a four-armed star whose arms are bent by different angles.

    Frame A bends the arms by (0.9, 0.3, -0.6, 0) rad, frame B by (-0.4, 0.8, 0.2, -0.9).
    Both share the vertex indexing: vertex i of A corresponds to vertex i of B and to
    ``B.symmetries[k, i]`` (the 15 symmetries of the unbent four-armed star).
    """
    base = star(4, resolution)
    frames = []
    for name, angles in (("lantern_a", (0.9, 0.3, -0.6, 0.0)), ("lantern_b", (-0.4, 0.8, 0.2, -0.9))):
        v = base.vertices
        for k, a in enumerate(angles):
            v = bend(v, np.pi / 2 * k, 1.3, a, 0.6)
        frames.append(GeneratedShape(name, v, base.faces, base.symmetries, base.labels))
    return frames[0], frames[1]


def figure(resolution: int = 10) -> GeneratedShape:
    """A mirror-symmetric figure (head up, arms out, legs down) with its limbs posed.

    The outline has lobes at 90 deg (head), 15 and 165 deg (arms), 250 and 290 deg
    (legs); the mirror x -> -x swaps left and right. Each limb is then bent by a
    different angle, so the mirror is a near-isometry, not an extrinsic symmetry. The
    plate's front/back flip, alone and with the mirror, follows as the second and third
    map. Labels: 1 right arm, 2 left arm, 3 right leg, 4 left leg, 5 head.
    """
    lobes = np.radians([15.0, 165.0, 290.0, 250.0, 90.0])
    v, f, parts = _lobed(lobes, 1.2, 0.3, 8 * resolution, max(6, resolution), 0.22)
    mirror = _reflection(np.pi / 2)
    sym = _vertex_maps(v, [mirror, lambda x: x * [1.0, 1.0, -1.0], lambda x: mirror(x) * [1.0, 1.0, -1.0]])
    for direction, angle in zip(lobes[:4], (0.8, -0.3, 0.5, -0.7)):
        v = bend(v, direction, 1.35, angle, 0.5)
    return GeneratedShape("figure", v, f, sym, parts)


def _bump(t: np.ndarray) -> np.ndarray:
    """Smooth bump (1 - t^2)^3 of compact support |t| < 1."""
    return np.clip(1.0 - t**2, 0.0, None) ** 3


#: The body of :func:`partial`: (longitude, latitude, frequency, phase, amplitude) of
#: each plane wave a cos(f d.u + phase) over unit directions d, u (degrees, degrees,
#: radians^-1, radians, radius units), placed without any symmetry. Their sum bends the
#: whole body: no patch of it is a piece of a sphere (whose rotations are isometries).
BODY_WAVES = (
    (20.0, 50.0, 3.0, 0.4, 0.10),
    (140.0, -20.0, 4.0, 1.3, 0.08),
    (250.0, 10.0, 2.5, 2.1, 0.12),
    (310.0, -60.0, 3.5, 0.7, 0.08),
    (80.0, 80.0, 5.0, 2.9, 0.06),
    (200.0, -35.0, 4.5, 1.9, 0.07),
)

#: Limb collar of :func:`partial`, in units of the limb's elliptical radius: the body
#: is exactly a unit sphere out to COLLAR[0] (which holds the limb and its thumb) and
#: fully bent from COLLAR[1] on.
COLLAR = (1.3, 1.8)


def _body(direction: np.ndarray) -> np.ndarray:
    """(..., 3) unit directions -> (...) radius offset of the body of :func:`partial`."""
    out = np.zeros(direction.shape[:-1])
    for lon, lat, frequency, phase, amplitude in BODY_WAVES:
        lon, lat = np.radians(lon), np.radians(lat)
        axis = np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])
        out += amplitude * np.cos(frequency * (direction @ axis) + phase)
    return out


def partial(resolution: int = 16, length: float = 1.2, width: float = 0.4) -> GeneratedShape:
    """An asymmetric blob with two identical limbs; the limb swap is its only symmetry.

    A star-shaped surface over a latitude-longitude grid (``8 * resolution`` longitudes,
    ``4 * resolution`` latitude bands, poles single vertices, each quad split about its
    centre): radius 1 plus the waves of :data:`BODY_WAVES` (an irregular body, symmetric
    under no isometry, and without spherical patches) plus two limbs on the equator at
    longitudes 0 and 90 degrees. A limb is a radial paddle of ``length``, angular
    half-width ``width`` (radians) in longitude and 1.6 ``width`` in latitude, with a
    "thumb" of 0.6 ``length`` on one side, so that it has no (near-)symmetry of its own.
    The body's waves fade out over a collar around each limb (:data:`COLLAR`). The
    rotation by 90 degrees about z maps limb 1 and its collar onto limb 2 and its
    collar exactly (and grid vertices to grid vertices).

    Returns
    -------
    GeneratedShape
        ``symmetries`` (1, N): the involution limb 1 <-> limb 2 (rotation by +90 / -90
        degrees), -1 for every vertex off the limbs; ``labels`` 1 and 2 on the limbs
        (vertices where the limb's profile is positive), 0 elsewhere.
    """
    if resolution < 4:
        raise ValueError("partial needs resolution >= 4")
    n_lon, n_lat = 8 * resolution, 4 * resolution
    shift = 2 * resolution  # 90 degrees in longitude cells
    lon_i, lat_i = np.meshgrid(np.arange(n_lon), np.arange(1, n_lat), indexing="xy")
    lon, lat = 2 * np.pi * lon_i / n_lon, np.pi * (lat_i / n_lat - 0.5)
    direction = np.stack([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)], axis=-1)
    body = _body(direction)
    radius = np.ones(lon.shape)
    limb = np.zeros(lon.shape, dtype=np.int64)
    for k, start in enumerate((0, shift)):
        # longitude offset from the limb axis computed from integers: identical on both limbs
        offset = 2 * np.pi * ((lon_i - start + n_lon // 2) % n_lon - n_lon // 2) / n_lon
        spread = np.hypot(offset, lat / 1.6) / width
        profile = length * _bump(spread) + 0.6 * length * _bump(
            np.hypot(offset - 0.5 * width, lat - 0.9 * width) / (0.5 * width)
        )
        radius += profile
        body *= 1.0 - _bump(np.maximum(spread - COLLAR[0], 0.0) / (COLLAR[1] - COLLAR[0]))
        limb[profile > 0] = k + 1
    radius += body
    one = limb == 1
    if np.any(np.roll(limb, -shift, axis=1)[one] != 2) or np.any(np.roll(radius, -shift, axis=1)[one] != radius[one]):
        raise AssertionError("the body reaches a limb, or the limbs overlap")
    poles = 1.0 + _body(np.array([[0.0, 0.0, -1.0], [0.0, 0.0, 1.0]]))
    v, f, quads = _latlon_mesh(radius[..., None] * direction, poles[0], poles[1])
    idx = np.arange(limb.size).reshape(limb.shape)
    south, north = limb.size, limb.size + 1
    # labels: grid vertices by their profile, quad centres where all four corners agree
    corner = limb.ravel()[quads]
    labels = np.concatenate([limb.ravel(), [0, 0], np.where((corner == corner[:, :1]).all(axis=1), corner[:, 0], 0)])
    # the swap, combinatorially: +shift longitude cells on limb 1, -shift on limb 2
    grid = np.concatenate([idx.ravel(), [south, north]])
    rolled = {1: np.roll(idx, -shift, axis=1).ravel(), 2: np.roll(idx, shift, axis=1).ravel()}
    quad_of = np.full(limb.size, -1, dtype=np.int64)
    quad_of[quads[:, 0]] = np.arange(len(quads))
    sym = np.full(len(v), -1, dtype=np.int64)
    for k, image in rolled.items():
        on = np.flatnonzero(limb.ravel() == k)
        sym[grid[on]] = image[on]
        q = np.flatnonzero(labels[len(grid) :] == k)
        sym[len(grid) + q] = len(grid) + quad_of[image[quads[q, 0]]]
    return GeneratedShape("partial", v, f, sym[None, :], labels)


def generate(name: str, **options) -> GeneratedShape | tuple[GeneratedShape, GeneratedShape]:
    """The shape ``name`` (one of :data:`NAMES`) with its options."""
    builders: dict[str, Callable[..., GeneratedShape | tuple[GeneratedShape, GeneratedShape]]] = {
        "cuboctahedron": cuboctahedron,
        "star": star,
        "lantern": lantern,
        "figure": figure,
        "partial": partial,
    }
    if name not in builders:
        raise ValueError(f"unknown shape {name!r}; expected one of {', '.join(NAMES)}")
    for option, value in options.items():
        low, high = LIMITS.get(option, (None, None))
        if low is not None and high is not None and not low <= value <= high:
            raise ValueError(f"{option} must lie in [{low}, {high}], got {value} (the size grows with it)")
    return builders[name](**options)


def _save_array(f: IO[bytes], array: np.ndarray) -> None:
    np.save(f, array)


def save(shape: GeneratedShape, path: str | os.PathLike) -> list[Path]:
    """Write the mesh as OFF and its ground truth beside it (each file atomically).

    ``PATH`` (the mesh), ``STEM.sym.npy`` (the principal map, 0-based, as read by
    ``intrinsym evaluate --symmetry-map``), ``STEM.maps.npy`` (all maps, (K, N)) and
    ``STEM.labels.npy`` (part labels, as read by ``--labels``).

    Returns
    -------
    list of Path
        The files written.
    """
    mesh_path = Path(path)
    if mesh_path.suffix.lower() != ".off":
        raise ValueError(f"{mesh_path}: generated meshes are written as OFF; name the file *.off")

    def write_off(f) -> None:
        f.write(f"OFF\n{len(shape.vertices)} {len(shape.faces)} 0\n")
        np.savetxt(f, shape.vertices, fmt="%.17g")
        np.savetxt(f, np.column_stack([np.full(len(shape.faces), 3), shape.faces]), fmt="%d")

    stem = mesh_path.with_suffix("")
    files = {
        mesh_path: None,
        Path(f"{stem}.sym.npy"): shape.symmetries[0],
        Path(f"{stem}.maps.npy"): shape.symmetries,
        Path(f"{stem}.labels.npy"): shape.labels,
    }
    atomic_write(mesh_path, write_off)
    for file, array in list(files.items())[1:]:
        atomic_write(file, functools.partial(_save_array, array=array), binary=True)
    return list(files)
