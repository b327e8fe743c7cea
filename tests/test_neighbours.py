import numpy as np
import pytest
from scipy.spatial import cKDTree

from intrinsym.mesh import generated as shapes
from intrinsym.mrf import bp
from intrinsym.spectral import laplacian, neighbours


def _exact(query, basis):
    return cKDTree(basis).query(query)[1]


def _dense(xp_name):
    def search(query, basis):
        xp = np if xp_name == "numpy" else pytest.importorskip("cupy")
        return neighbours.dense_nearest_rows(query, basis, xp)

    return search


#: The clustered CPU search and the dense one, in NumPy and (with a GPU) in CuPy.
SEARCHES = [
    pytest.param(neighbours.nearest_rows, id="clusters"),
    pytest.param(_dense("numpy"), id="dense-numpy"),
    pytest.param(
        _dense("cupy"), id="dense-cupy", marks=pytest.mark.skipif(not bp.gpu_available(), reason="no usable GPU")
    ),
]


@pytest.mark.parametrize("n_clusters", [None, 1, 7, 1500])
def test_unstructured_rows_match_a_kd_tree(n_clusters):
    # Gaussian rows in 12 dimensions: no surface to exploit, the pruning still exact
    rng = np.random.default_rng(0)
    basis, query = rng.normal(size=(1500, 12)), rng.normal(size=(900, 12))
    got = neighbours.nearest_rows(query, basis, n_clusters=n_clusters)
    np.testing.assert_array_equal(got, _exact(query, basis))


@pytest.mark.parametrize("search", SEARCHES)
def test_a_functional_maps_point_map_matches_a_kd_tree(search):
    # eigenfunction rows of a star (a surface in 30 dimensions) under the functional map
    # of its rotation, fitted by least squares, plus noise: the case the clusters are for
    shape = shapes.star(arms=5, resolution=16)
    _, evecs = laplacian.eigenpairs(shape.vertices, shape.faces, 31)
    basis = evecs[:, 1:]
    C = np.linalg.lstsq(basis, basis[shape.symmetries[0]], rcond=None)[0]
    query = basis @ C + 0.02 * np.random.default_rng(1).normal(size=basis.shape)
    np.testing.assert_array_equal(search(query, basis), _exact(query, basis))


@pytest.mark.parametrize("search", SEARCHES)
def test_rows_far_from_the_origin_do_not_lose_their_nearest_neighbour(search):
    # |x|^2 / 2 - q.x in float32 cancels when the rows' norm dwarfs their spacing
    rng = np.random.default_rng(2)
    basis = 1000.0 + rng.uniform(size=(2000, 8))
    query = 1000.0 + rng.uniform(size=(500, 8))
    x32, q32 = basis.astype(np.float32), query.astype(np.float32)
    float32_products = np.argmin(0.5 * np.einsum("ij,ij->i", x32, x32) - q32 @ x32.T, axis=1)
    exact = _exact(query, basis)
    assert np.mean(float32_products != exact) > 0.1
    np.testing.assert_array_equal(search(query, basis), exact)


@pytest.mark.parametrize("scale", [0.9, 1.0])
def test_exact_ties_go_to_the_smallest_row(scale):
    # every row three times, in different clusters; at scale 1 the queries are rows
    # (distance 0, where the bound has no relative slack to spare)
    basis = np.repeat(np.eye(4) * 1000.0, 3, axis=0)
    got = neighbours.nearest_rows(np.eye(4) * 1000.0 * scale, basis, n_clusters=6)
    np.testing.assert_array_equal(got, [0, 3, 6, 9])


@pytest.mark.parametrize("search", SEARCHES[1:])
def test_the_dense_search_hands_unclear_queries_to_the_exact_one(search, monkeypatch):
    # duplicated rows tie exactly, rows 1e-13 apart tie within rounding: both go to the
    # clustered search, which returns the smallest of the tied rows; blocks of 7 queries
    rng = np.random.default_rng(3)
    basis = rng.normal(size=(300, 6))
    basis = np.vstack([basis, basis[:20], basis[20:40] + 1e-13])
    query = np.vstack([basis[:40], rng.normal(size=(60, 6))])
    monkeypatch.setattr(neighbours, "DENSE_BLOCK_BYTES", 7 * 8 * len(basis))
    got = search(query, basis)
    np.testing.assert_array_equal(got[:40], np.arange(40))
    np.testing.assert_array_equal(got, neighbours.nearest_rows(query, basis))


@pytest.mark.parametrize("search", SEARCHES[1:])
def test_the_dense_search_resolves_near_ties_the_products_cannot(search):
    """Queries all but halfway between two rows 1e4 from the origin, nearer one of them
    by a margin far below the products' rounding, get their exact nearest row.

    Rows x0 (each coordinate 1e4 + U(-1, 1)) and x1 = x0 + u, u a random unit vector
    (and two decoys 5 away); the queries are x0 + (0.5 + delta) u + s, s orthogonal to u,
    |delta| in [1e-9, 1e-8] of either sign, so |q - x0|^2 - |q - x1|^2 = 2 delta: the
    nearest row is x1 exactly when delta > 0 (the queries' coordinates are rounded by
    2e-12, far below delta). The product values |x|^2 / 2 - q.x are about -1.5e8, rounded
    in steps of 3e-8 or more, while the two rows' values differ by delta: their argmin is
    a coin toss, which the fast path alone gets wrong for 77 of the 200 queries (measured;
    in none of them are the two values equal). The float64 squared distances taken from
    the differences, exact here, rank them as delta says."""
    rng = np.random.default_rng(0)
    x0 = 1.0e4 + rng.uniform(-1.0, 1.0, 3)
    u = rng.normal(size=3)
    u /= np.linalg.norm(u)
    basis = np.vstack([x0, x0 + u, x0 - 5.0 * u, x0 + 5.0 * np.roll(u, 1)])
    delta = rng.choice([-1.0, 1.0], 200) * rng.uniform(1e-9, 1e-8, 200)
    side = rng.uniform(-0.3, 0.3, (200, 3))
    side -= (side @ u)[:, None] * u
    query = x0 + (0.5 + delta)[:, None] * u + side
    truth = (delta > 0).astype(np.int64)
    brute = np.argmin(((query[:, None, :] - basis[None]) ** 2).sum(axis=2), axis=1)
    np.testing.assert_array_equal(brute, truth)
    np.testing.assert_array_equal(search(query, basis), truth)


def test_shapes_are_checked():
    assert neighbours.nearest_rows(np.empty((0, 3)), np.ones((5, 3))).shape == (0,)
    with pytest.raises(ValueError, match="rows"):
        neighbours.nearest_rows(np.ones((4, 3)), np.ones((5, 2)))
    with pytest.raises(ValueError, match="rows"):
        neighbours.nearest_rows(np.ones((4, 3)), np.empty((0, 3)))


@pytest.mark.parametrize("parallel_queries", [1, 10**9])
def test_one_index_serves_every_leading_column_count(parallel_queries, monkeypatch):
    # ZoomOut searches the first k columns of one index for k = 3 .. 12; on threads
    # (every block) and serially the same rows as a k-d tree of those columns
    monkeypatch.setattr(neighbours, "PARALLEL_QUERIES", parallel_queries)
    shape = shapes.star(arms=5, resolution=16)
    basis = laplacian.eigenpairs(shape.vertices, shape.faces, 13)[1][:, 1:]
    query = basis[shape.symmetries[0]] + 0.01 * np.random.default_rng(4).normal(size=basis.shape)
    index = neighbours.row_index(basis, n_clusters=40)
    for k in range(3, 13):
        got = neighbours.nearest_rows(query[:, :k], index)
        np.testing.assert_array_equal(got, _exact(query[:, :k], basis[:, :k]))


def test_an_index_is_searched_in_at_most_its_columns():
    index = neighbours.row_index(np.ones((5, 3)))
    assert neighbours.search_rows(index) is index
    assert neighbours.search_rows(index, "gpu") is index.basis
    with pytest.raises(ValueError, match="k <= K"):
        neighbours.nearest_rows(np.ones((4, 4)), index)
    with pytest.raises(ValueError, match="rows"):
        neighbours.row_index(np.empty((0, 3)))
