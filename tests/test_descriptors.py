"""Spin images, NMI and spectral signatures on analytic and hand-checked cases."""

import numpy as np
import pytest
import trimesh
from scipy.spatial.distance import cdist

from conftest import unit_sphere
from intrinsym import pipeline
from intrinsym.mesh.shape import from_arrays
from intrinsym.spectral.laplacian import eigenpairs
from intrinsym.unary.descriptors import (
    heat_kernel_signature,
    hks_times,
    nmi,
    quantize,
    spin_images,
    wave_kernel_signature,
    wks_energies,
)


def _grid_plane(n: int = 81, half: float = 1.0) -> np.ndarray:
    x, y = np.meshgrid(np.linspace(-half, half, n), np.linspace(-half, half, n))
    return np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])


def test_plane_spin_image_is_one_row_band():
    # Every point of a plane has beta = 0: the image is the band of rows straddling
    # beta = 0 (rows 7 and 8 of 16, centres -r/16 and +r/16, half the mass each).
    cloud = _grid_plane()
    img = spin_images(np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]), cloud, radius=0.5, bins=16)[0]
    assert img.sum() == pytest.approx(1.0)
    rows = img.sum(axis=1)
    assert rows[7] == pytest.approx(0.5) and rows[8] == pytest.approx(0.5)
    assert np.delete(rows, [7, 8]).max() == 0.0
    # alpha is the in-plane distance: the mass grows outwards like the circumference.
    cols = img.sum(axis=0)
    assert cols[12] > cols[4] > cols[0]


def test_spin_image_of_a_sphere_point_has_mass_below_the_tangent_plane_only():
    sphere = trimesh.creation.icosphere(subdivisions=5)
    p = np.array([[0.0, 0.0, 1.0]])
    img = spin_images(p, p, np.asarray(sphere.vertices), radius=0.5, bins=16)[0]
    # beta = -|x - p|^2 / 2 <= 0 on the unit sphere: rows above beta = +r/16 stay empty.
    assert img[9:].sum() == 0.0
    assert img[:8].sum() > 0.5


def test_quantize_levels_by_image_maximum():
    images = np.array([[0.0, 0.5, 1.0, 0.74], [0.0, 0.0, 0.0, 0.0], [2.0, 1.0, 0.0, 0.0]])
    q = quantize(images, levels=4)
    assert q.tolist() == [[0, 2, 3, 2], [0, 0, 0, 0], [3, 2, 0, 0]]
    assert quantize(images * 1000.0, levels=4).tolist() == q.tolist()
    with pytest.raises(ValueError):
        quantize(images, levels=0)


def test_nmi_identical_relabelled_and_independent_images():
    rng = np.random.default_rng(0)
    a = rng.integers(0, 8, size=(1, 256)).astype(np.uint8)
    relabel = np.array([3, 1, 7, 0, 2, 6, 4, 5], dtype=np.uint8)[a]
    noise = rng.integers(0, 8, size=(1, 256)).astype(np.uint8)
    s = nmi(a, np.vstack([a, relabel, noise]), levels=8)[0]
    assert s[0] == pytest.approx(1.0) and s[1] == pytest.approx(1.0)
    assert s[2] < 0.2


def test_nmi_matches_hand_computed_entropies():
    # a = [0,0,1,1], b = [0,1,0,1]: independent, H1 = H2 = ln 2, H12 = ln 4 -> NMI' = 0.
    # a against c = [0,0,0,1]: H12 = -(2 ln(1/2) + 2 ln(1/4)) / 4 ... computed below.
    a = np.array([[0, 0, 1, 1]], dtype=np.uint8)
    b = np.array([[0, 1, 0, 1], [0, 0, 0, 1]], dtype=np.uint8)
    s = nmi(a, b, levels=2)[0]
    assert s[0] == pytest.approx(0.0, abs=1e-6)
    h = lambda p: -sum(x * np.log(x) for x in p if x > 0)  # noqa: E731
    h1, h2, h12 = h([0.5, 0.5]), h([0.75, 0.25]), h([0.5, 0.25, 0.25])
    assert s[1] == pytest.approx((h1 + h2 - h12) / h12, rel=1e-6)


@pytest.mark.parametrize("signature", ["wks", "hks"])
def test_spectral_signatures_are_constant_on_a_sphere(signature):
    # Every point of a sphere is equivalent; with whole eigenspaces (l <= 5: 36 modes)
    # the signatures cannot depend on the point, up to the mesh's discretisation.
    v, f = unit_sphere()
    evals, evecs = eigenpairs(v, f, 36)
    if signature == "wks":
        energies, sigma = wks_energies(evals, 50)
        sig = wave_kernel_signature(evals, evecs, energies, sigma)
    else:
        sig = heat_kernel_signature(evals, evecs, hks_times(evals, 50))
    assert sig.shape == (len(v), 50)
    assert np.ptp(sig, axis=0).max() < 0.05
    # ... whereas a truncation inside an eigenspace (l = 5 split) makes them vary.
    if signature == "wks":
        cut = wave_kernel_signature(evals[:30], evecs[:, :30], *wks_energies(evals[:30], 50))
        assert np.ptp(cut, axis=0).max() > 5 * np.ptp(sig, axis=0).max()


def test_signatures_are_reflection_invariant(mirror):
    v, f, sym = mirror
    evals, evecs = eigenpairs(v, f, 40)
    energies, sigma = wks_energies(evals, 40)
    wks = wave_kernel_signature(evals, evecs, energies, sigma)
    hks = heat_kernel_signature(evals, evecs, hks_times(evals, 40))
    for sig in (wks, hks):
        err = np.abs(sig - sig[sym]).max(axis=1)
        spread = np.ptp(sig, axis=0).max()
        assert np.median(err) < 1e-3 * spread
        # and it tells points apart: the mirror image is nearer than most other points
        # (cdist: the same distances as the broadcast norm, without its 160 MB temporary)
        far = cdist(sig, sig[:200])
        assert np.median(far) > 100 * np.median(err)


def test_signatures_are_scale_free_after_unit_area_normalisation(mirror):
    v, f, _ = mirror
    out = []
    for factor in (1.0, 1000.0):
        # a working size the mesh has (2,562 vertices): the default's 8,000 subdivided it, which
        # happens after the normalisation under test, and tripled the eigenpairs' time
        surf = pipeline.prepare(from_arrays(v * factor, f), n_source=40, n_target=400)
        assert not surf.subdivided
        evals, evecs = eigenpairs(surf.shape.vertices, surf.shape.faces, 30)
        energies, sigma = wks_energies(evals, 30)
        out.append(
            (
                wave_kernel_signature(evals, evecs, energies, sigma),
                heat_kernel_signature(evals, evecs, hks_times(evals, 30)),
            )
        )
    for a, b in zip(*out, strict=True):
        np.testing.assert_allclose(a, b, atol=1e-6)
