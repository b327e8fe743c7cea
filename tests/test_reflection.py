"""The reflection test of the global/partial decision, on hand-checked maps of a planar
grid and on the bent ellipsoid's exact mirror."""

import numpy as np
import trimesh

from intrinsym.extract.reflection import reflection, returns, reversed_turns
from intrinsym.mesh.shape import Shape, vertex_normals

# a 5 x 5 grid of samples in the plane z = 0, 4-neighbour edges, normals +z
IJ = np.array([(i, j) for i in range(-2, 3) for j in range(-2, 3)])
POINTS = np.column_stack([IJ, np.zeros(len(IJ))]).astype(float)
NORMALS = np.tile([0.0, 0.0, 1.0], (len(IJ), 1))
EDGES = np.array([(a, b) for a in range(len(IJ)) for b in range(a + 1, len(IJ)) if np.abs(IJ[a] - IJ[b]).sum() == 1])


def grid_map(transform) -> np.ndarray:
    """Index of the grid point each grid point's transformed (i, j) lands on."""
    index = {tuple(ij): k for k, ij in enumerate(IJ)}
    return np.array([index[tuple(transform(i, j))] for i, j in IJ])


MIRROR = grid_map(lambda i, j: (-i, j))
HALF_TURN = grid_map(lambda i, j: (-i, -j))
QUARTER_TURN = grid_map(lambda i, j: (-j, i))
IDENTITY = np.arange(len(IJ))


def test_returns_marks_the_round_trips_that_end_at_their_start():
    assert returns(MIRROR, POINTS, POINTS, 0.5).all()
    assert returns(HALF_TURN, POINTS, POINTS, 0.5).all()  # of order two, like a reflection
    # twice a quarter turn is the half turn: only the centre comes back
    assert np.array_equal(np.flatnonzero(returns(QUARTER_TURN, POINTS, POINTS, 0.5)), [12])
    # sample (-2, -2) sent one step past its mirror image, onto (2, -1): its own trip and
    # the trip of (2, -2), whose image it is, end a step away
    moved = MIRROR.copy()
    moved[0] = MIRROR[1]
    back = returns(moved, POINTS, POINTS, 0.5)
    assert back.sum() == len(IJ) - 2 and returns(moved, POINTS, POINTS, 1.5).all()


def test_reversed_turns_tells_a_mirror_from_a_rotation():
    assert reversed_turns(MIRROR, EDGES, POINTS, POINTS, NORMALS, NORMALS).all()
    for rotation in (IDENTITY, HALF_TURN, QUARTER_TURN):
        assert not reversed_turns(rotation, EDGES, POINTS, POINTS, NORMALS, NORMALS).any()
    # the normals flipped at the images: a rotation seen from the other side turns around
    assert reversed_turns(HALF_TURN, EDGES, POINTS, POINTS, NORMALS, -NORMALS).all()


def test_reversed_turns_needs_a_clear_turn():
    # samples on a line: every pair of neighbours is parallel, so no sample has a turn
    line = np.column_stack([np.arange(5.0), np.zeros(5), np.zeros(5)])
    edges = np.array([(k, k + 1) for k in range(4)])
    assert not reversed_turns(np.arange(5)[::-1], edges, line, line, NORMALS[:5], NORMALS[:5]).any()


def test_reflection_is_the_share_that_returns_and_turns_around():
    assert reflection(MIRROR, EDGES, POINTS, POINTS, NORMALS, NORMALS, 0.5) == 1.0
    assert reflection(HALF_TURN, EDGES, POINTS, POINTS, NORMALS, NORMALS, 0.5) == 0.0
    assert reflection(QUARTER_TURN, EDGES, POINTS, POINTS, NORMALS, NORMALS, 0.5) == 0.0


def test_the_exact_mirror_of_a_curved_surface_is_a_reflection():
    # at 642 vertices (1,920 edges; the fixture's 2,562 took 0.9 s over their 7,680)
    from conftest import mirror_shape

    v, f, sym = mirror_shape(subdivisions=3)
    normals = vertex_normals(Shape(v, f))
    edges = trimesh.Trimesh(v, f, process=False).edges_unique
    assert reflection(sym, edges, v, v, normals, normals, 1e-6) == 1.0
    assert not reversed_turns(np.arange(len(v)), edges, v, v, normals, normals).any()
