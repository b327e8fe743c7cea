"""The spectral baseline (sign search + ZoomOut) against known symmetries."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from conftest import shared
from intrinsym.evaluation import evaluate
from intrinsym.mesh import generated as shapes
from intrinsym.mesh.io import load
from intrinsym.mesh.shape import clean, from_arrays
from intrinsym.spectral import spectral


def best_score(predicted, vertices, faces, maps) -> evaluate.MapScores:
    """The score of ``predicted`` against the ground-truth map it comes closest to."""
    shape = from_arrays(vertices, faces)
    return max((evaluate.score_map(predicted, shape, m) for m in maps), key=lambda s: s.within(0.05))


def test_isolated_eigenvalues_by_hand():
    evals = np.array([1.0, 1.01, 2.0, 3.0, 3.05, 5.0, 8.0])
    # 1 and 1.01, 3 and 3.05 are pairs within 5 %; the last has no known next neighbour
    assert spectral.isolated_eigenvalues(evals, 8).tolist() == [2, 5]
    assert spectral.isolated_eigenvalues(evals, 1).tolist() == [2]
    assert spectral.isolated_eigenvalues(evals, 8, min_gap=0.0).tolist() == [0, 1, 2, 3, 4, 5]


def test_sign_search_finds_the_planted_flip():
    # a point set symmetric under flipping its 2nd and 4th coordinates only
    rng = np.random.default_rng(2)
    half = rng.standard_normal((100, 5)) * [3.0, 2.0, 1.5, 1.0, 0.7]
    points = np.vstack([half, half * [1, -1, 1, -1, 1]])
    signs, residuals = spectral.sign_candidates(points, 3)
    assert signs.shape == (3, 5) and signs[0].tolist() == [1, -1, 1, -1, 1]
    assert residuals[0] == 0.0 and residuals[1] > 0.1
    with pytest.raises(ValueError, match="1 to 12"):
        spectral.sign_candidates(np.zeros((4, 13)), 1)


def test_distortion_is_zero_for_isometries_only():
    rng = np.random.default_rng(3)
    points = rng.standard_normal((40, 6))
    assert spectral.distortion(points, points) == 0.0
    orthogonal = np.linalg.qr(rng.standard_normal((6, 6)))[0]
    assert spectral.distortion(points, points @ orthogonal + 1.0) == pytest.approx(0.0, abs=1e-12)
    assert spectral.distortion(points, 2.0 * points) == pytest.approx(1.0)  # every distance doubles
    assert spectral.distortion(points, np.repeat(points[:20], 2, axis=0)) > 0.2  # a fold


def test_nearest_images_is_the_exact_nearest_neighbour():
    rng = np.random.default_rng(3)
    source, target = rng.normal(size=(700, 12)), rng.normal(size=(1500, 12))
    C = np.linalg.qr(rng.normal(size=(10, 10)))[0]
    expected = cKDTree(target[:, :10]).query(source[:, :10] @ C)[1]
    np.testing.assert_array_equal(spectral.nearest_images(source, target, C), expected)


def test_seed_map_leaves_out_the_pairs_it_cannot_explain():
    """Pairs of a known functional map with small noise, and a tenth of them wrong in
    the same way (a part mapped elsewhere as a whole): the trimmed fit recovers the map
    and names the wrong pairs; the plain least squares is pulled off."""
    rng = np.random.default_rng(5)
    source = rng.standard_normal((200, 8))
    truth = np.linalg.qr(rng.standard_normal((8, 8)))[0]
    target = source @ truth + 1e-3 * rng.standard_normal((200, 8))
    wrong = np.zeros(200, dtype=bool)
    wrong[rng.choice(200, 20, replace=False)] = True
    target[wrong] = source[wrong] @ np.linalg.qr(rng.standard_normal((8, 8)))[0]
    plain, all_kept = spectral.seed_map(source, target, trim=0.0)
    np.testing.assert_array_equal(plain, np.linalg.lstsq(source, target, rcond=None)[0])
    assert all_kept.all() and np.abs(plain - truth).max() > 0.05
    C, kept = spectral.seed_map(source, target)
    np.testing.assert_array_equal(kept, ~wrong)
    assert np.abs(C - truth).max() < 1e-3
    # noise alone: no pair is left out
    C, kept = spectral.seed_map(source, source @ truth + 1e-3 * rng.standard_normal((200, 8)))
    assert kept.all() and np.abs(C - truth).max() < 1e-3


@pytest.mark.parametrize("involution", [False, True])
def test_zoomout_recovers_a_mirror_from_a_noisy_start(mirror, involution):
    from intrinsym.spectral import laplacian

    v, f, sym = mirror
    _, evecs = laplacian.eigenpairs(v, f, 31)
    phi = evecs[:, 1:]
    samples = np.arange(0, len(v), 3)
    start = sym[samples].copy()
    wrong = np.random.default_rng(5).random(len(samples)) < 0.3
    start[wrong] = np.random.default_rng(6).integers(0, len(v), wrong.sum())
    images, C = spectral.zoomout(phi[samples], phi, start, 6, involution)
    assert C.shape == (30, 30)
    assert np.mean(images == sym[samples]) > 0.95
    # a mirror maps each (non-repeated) eigenfunction to +- itself: C is nearly diagonal
    assert np.linalg.norm(np.diag(C)) ** 2 > 0.9 * np.linalg.norm(C) ** 2
    if involution:  # the reversed pairs make C its own inverse (a mirror: C^2 = I)
        assert np.linalg.norm(C @ C - np.eye(30)) < 0.1 * np.sqrt(30)
        with pytest.raises(ValueError, match="self-maps"):
            spectral.seeded_functional_maps(
                v, evecs, samples, sym[samples], 6, 30, involutions=(True,), target_vertices=v, target_evecs=evecs
            )


def test_spectral_symmetry_finds_the_mirror(mirror):
    v, f, sym = mirror  # a bent ellipsoid whose only symmetry is x -> -x
    image = spectral.spectral_symmetry(v, f)
    assert image.dtype == np.int64 and image.shape == (len(v),)
    scores = best_score(image, v, f, [sym])
    assert scores.within(0.05) > 0.99 and scores.mean_error < 0.01
    assert np.mean(image == np.arange(len(v))) < 0.05  # not the identity
    # scale-free: the same map in millimetres
    assert np.mean(spectral.spectral_symmetry(v * 1000.0, f) == image) > 0.99


def test_spectral_symmetry_on_the_posed_figure():
    figure = shapes.figure(resolution=8)  # limbs bent differently: a near-isometry
    image = spectral.spectral_symmetry(figure.vertices, figure.faces, n_final=30)
    scores = best_score(image, figure.vertices, figure.faces, figure.symmetries)
    assert scores.within(0.10) > 0.95


def test_spectral_symmetry_on_an_ellipsoid_finds_one_of_its_seven_symmetries():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    v = sphere.vertices * [1.0, 1.6, 2.5]
    flips = [np.array(s) for s in np.ndindex(2, 2, 2)][1:]
    maps = [cKDTree(v).query(v * (1 - 2 * s))[1] for s in flips]
    image = spectral.spectral_symmetry(v, sphere.faces, n_final=30)
    assert best_score(image, v, sphere.faces, maps).within(0.05) > 0.99


def test_spectral_symmetry_checks_sizes(mirror):
    v, f, _ = mirror
    with pytest.raises(ValueError, match="n_samples"):
        spectral.spectral_symmetry(v, f, n_samples=20, n_final=30)


@pytest.mark.slow  # a real scan at the defaults (CI: -m slow); a posed shape by default: test_..._on_the_posed_figure
def test_spectral_symmetry_on_tosca_wolf():
    path = shared("tosca_sym/wolf0.off")
    shape = load(path)
    sym = evaluate.load_symmetry_map(path.with_name("wolf.sym"), len(shape.vertices))
    cleaned, vertex_map = clean(shape)
    assert len(cleaned.vertices) == len(shape.vertices) and np.array_equal(vertex_map, np.arange(len(sym)))
    image = spectral.spectral_symmetry(cleaned.vertices, cleaned.faces)
    assert evaluate.score_map(image, shape, sym).within(0.10) > 0.95


def test_seeded_symmetry_refines_sparse_noisy_pairs(mirror):
    from intrinsym.spectral import laplacian

    v, f, sym = mirror
    _, evecs = laplacian.eigenpairs(v, f, 31)
    rng = np.random.default_rng(7)
    source = np.arange(0, len(v), 40)
    # images only as precise as a sparse sampling (a random vertex within 0.1 of the
    # true one), and one pair in ten wrong
    near = cKDTree(v).query_ball_point(v[sym[source]], 0.1)
    target = np.array([rng.choice(n) for n in near])
    wrong = rng.random(len(source)) < 0.1
    target[wrong] = rng.integers(0, len(v), wrong.sum())
    image = spectral.seeded_symmetry(v, evecs, source, target, k_seed=6, n_final=30)
    assert image.dtype == np.int64 and image.shape == (len(v),)
    scores = best_score(image, v, f, [sym])
    assert scores.within(0.05) > 0.99 and scores.mean_error < 0.01
    # a subset of points mapped onto a subset of candidates: the nearest candidate
    # in the final spectral embedding, the same map where the candidate set is whole
    points, candidates = np.arange(0, len(v), 3), np.arange(1, len(v), 2)
    part = spectral.seeded_symmetry(v, evecs, source, target, k_seed=6, n_final=30, points=points)
    np.testing.assert_array_equal(part, image[points])
    sub = spectral.seeded_symmetry(v, evecs, source, target, k_seed=6, n_final=30, candidates=candidates)
    assert set(sub.tolist()) <= set(candidates.tolist())
    assert np.mean(np.linalg.norm(v[sub] - v[image], axis=1)) < 0.05
    with pytest.raises(ValueError, match="k_seed"):
        spectral.seeded_symmetry(v, evecs, source[:5], target[:5], k_seed=6)


def test_the_device_searches_give_the_cpu_maps(monkeypatch):
    """``device="gpu"`` runs the dense search (CuPy stood in for by NumPy here): ZoomOut's
    functional maps and the point maps are those of the CPU search, exactly. On the bent
    ellipsoid at 642 vertices, its 65 samples every 10th vertex (as every 40th of the
    fixture's 2,562: the searches took 3/4 of the time there)."""
    import sys

    from conftest import mirror_shape
    from intrinsym.spectral import laplacian, neighbours

    monkeypatch.setitem(sys.modules, "cupy", np)
    dense, searched = neighbours.dense_nearest_rows, []
    monkeypatch.setattr(neighbours, "dense_nearest_rows", lambda q, x, xp: searched.append(len(q)) or dense(q, x, xp))
    v, f, sym = mirror_shape(subdivisions=3)
    _, evecs = laplacian.eigenpairs(v, f, 31)
    source = np.arange(0, len(v), 10)
    fits = {
        device: spectral.seeded_functional_maps(
            v, evecs, source, sym[source], 6, 30, involutions=(True, False), device=device
        )
        for device in ("cpu", "gpu")
    }
    # the start and every ZoomOut level of both fits (k = 6..30) searched densely, the CPU run none
    assert len(searched) == 1 + 2 * 25
    for cpu, gpu in zip(fits["cpu"], fits["gpu"]):
        np.testing.assert_array_equal(cpu, gpu)
    points = np.arange(0, len(v), 3)
    images = [spectral.map_points(fits["cpu"][0], evecs, points, device=device) for device in ("cpu", "gpu")]
    np.testing.assert_array_equal(images[0], images[1])
    assert searched[-1] == len(points)
    assert best_score(spectral.map_points(fits["cpu"][0], evecs), v, f, [sym]).within(0.05) > 0.99


def test_seeded_symmetry_keeps_the_seeded_one_of_several_symmetries():
    """On an ellipsoid with seven symmetries, the pairs pick which one comes out."""
    from intrinsym.spectral import laplacian

    sphere = trimesh.creation.icosphere(subdivisions=3)
    v = sphere.vertices * [1.0, 1.6, 2.5]
    _, evecs = laplacian.eigenpairs(v, sphere.faces, 31)
    source = np.arange(0, len(v), 20)
    for flip in ([1, 0, 0], [0, 1, 0], [1, 1, 0], [1, 1, 1]):
        truth = cKDTree(v).query(v * (1 - 2 * np.array(flip)))[1]
        image = spectral.seeded_symmetry(v, evecs, source, truth[source], k_seed=6, n_final=30)
        assert evaluate.score_map(image, from_arrays(v, sphere.faces), truth).within(0.05) > 0.99


def test_seeded_map_between_two_shapes_recovers_a_vertex_permutation(mirror):
    """Two-shape form: the second shape is the first, rotated, scaled by 2 and with its
    vertices shuffled; sparse pairs of its mirror seed the map, which must come out as
    the mirror composed with the shuffle."""
    from intrinsym.spectral import laplacian

    v, f, sym = mirror
    rng = np.random.default_rng(3)
    order = rng.permutation(len(v))  # vertex i of the copy is vertex order[i] of v
    rot = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    w, g = 2.0 * v[order] @ rot.T, np.argsort(order)[f]
    _, ev = laplacian.eigenpairs(v, f, 31)
    _, ew = laplacian.eigenpairs(w, g, 31)
    truth = np.argsort(order)[sym]  # vertex of the copy that is the mirror image of vertex i of v
    source = np.arange(0, len(v), 40)
    image = spectral.seeded_symmetry(
        v, ev, source, truth[source], k_seed=6, n_final=30, target_vertices=w, target_evecs=ew
    )
    assert image.shape == (len(v),) and image.max() < len(w)
    assert np.median(np.linalg.norm(w[image] - w[truth], axis=1)) < 0.02 * 2.0 * np.ptp(v, axis=0).max()
    assert np.mean(image == truth) > 0.8
    with pytest.raises(ValueError, match="neither"):
        spectral.seeded_symmetry(v, ev, source, truth[source], k_seed=6, target_vertices=w)
