"""A dense map carried onto the connected components the model does not see, and a
part's map into its whole inverted."""

from __future__ import annotations

import numpy as np
import trimesh
from scipy.spatial import cKDTree

import intrinsym
from conftest import mirror_shape
from intrinsym.globalmap.globalmap import carried_map
from intrinsym.globalmap.vertex_maps import carried_to_components, inverse_vertex_map
from intrinsym.mesh.shape import from_arrays
from intrinsym.surface import prepare


def _with_loose_parts() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The mirror-symmetric bent ellipsoid with four small spheres apart from it: two
    mirror "eyes" above its surface, a tooth on the mirror plane, and a larger "gum"
    beside the left eye.

    Returns vertices, faces, the mirror image of every vertex (x -> -x, exact) and the
    component of every vertex (0 the body, 1 / 2 the eyes, 3 the tooth, 4 the gum).
    """
    body, faces, body_sym = mirror_shape()
    ball = trimesh.creation.icosphere(subdivisions=2)  # symmetric under x -> -x
    bv, bf = np.asarray(ball.vertices), np.asarray(ball.faces)
    top = body[np.argmax(body[:, 2] - 10 * np.abs(body[:, 0] - 0.25))]  # a point on top, right of the plane
    parts = [(0.06, top * [1, 1, 1] + [0, 0, 0.1]), (0.06, top * [-1, 1, 1] + [0, 0, 0.1])]
    parts += [(0.05, [0.0, top[1] + 0.3, top[2] + 0.1]), (0.15, top * [-1, 1, 1] + [-0.2, 0, 0.1])]
    vertices, all_faces, sym, component = [body], [faces], [body_sym], [np.zeros(len(body), dtype=np.int64)]
    n, ball_sym = len(body), cKDTree(bv).query(bv * [-1, 1, 1])[1]
    starts = []
    for i, (radius, centre) in enumerate(parts):
        starts.append(n)
        vertices.append(bv * radius + centre)
        all_faces.append(bf + n)
        component.append(np.full(len(bv), i + 1))
        n += len(bv)
    # the eyes swap, the tooth maps onto itself, the gum has no mirror part (itself)
    eye_a, eye_b, tooth, gum = starts
    sym += [ball_sym + eye_b, ball_sym + eye_a, ball_sym + tooth, np.arange(len(bv)) + gum]
    return np.vstack(vertices), np.vstack(all_faces), np.concatenate(sym), np.concatenate(component)


def test_loose_parts_take_the_mirror_of_the_surface_around_them():
    v, _, sym, component = _with_loose_parts()
    held = component == 0
    start = np.where(held, sym, -1)
    out = carried_to_components(v, component, start, held)
    np.testing.assert_array_equal(out[held], sym[held])  # the held map stays
    # the eyes swap vertex for vertex, the tooth maps onto its own mirror, not the gum beside
    for part in (1, 2, 3):
        np.testing.assert_array_equal(out[component == part], sym[component == part])


def test_a_loose_part_lands_on_its_mirror_when_that_one_is_held():
    # the right eye holds samples (its map stays), the left one does not
    v, _, sym, component = _with_loose_parts()
    held = np.isin(component, [0, 2])
    out = carried_to_components(v, component, np.where(held, sym, -1), held)
    np.testing.assert_array_equal(out[component == 1], sym[component == 1])
    np.testing.assert_array_equal(out[held], sym[held])


def test_a_part_with_nothing_within_reach_gets_no_image():
    v, _, sym, component = _with_loose_parts()
    held = component == 0
    far = v.copy()
    far[component == 1] += [0.0, 0.0, 5.0]  # the left eye floats far above the body: no mirror part there
    out = carried_to_components(far, component, np.where(held, sym, -1), held)
    assert (out[component == 1] == -1).all()
    np.testing.assert_array_equal(out[component == 3], sym[component == 3])


def test_nothing_to_carry():
    v, _, sym, component = _with_loose_parts()
    everything = np.ones(len(v), dtype=bool)
    np.testing.assert_array_equal(carried_to_components(v, component, sym, everything), sym)
    # too few mapped vertices to fix a motion: unchanged
    held = component == 0
    few = np.full(len(v), -1)
    few[:3] = sym[:3]
    np.testing.assert_array_equal(carried_to_components(v, component, few, held), few)


def test_carried_map_counts_only_what_it_carries():
    v, f, sym, component = _with_loose_parts()
    surface = prepare(from_arrays(v, f))
    body = np.flatnonzero(component == 0)
    start = np.where(component == 0, sym, -1)
    # three samples on the body: the four small parts are carried onto their mirrors
    out, loose = carried_map(surface, surface.vertex_map[body[:3]], start)
    np.testing.assert_array_equal(loose, component > 0)
    for part in (1, 2, 3):
        np.testing.assert_array_equal(out[component == part], sym[component == part])
    # two: no component holds enough samples to carry the others by
    out, loose = carried_map(surface, surface.vertex_map[body[:2]], start)
    assert not loose.any()
    np.testing.assert_array_equal(out, start)
    # a connected shape: nothing carried, whatever the samples
    mv, mf, msym = mirror_shape()
    out, loose = carried_map(prepare(from_arrays(mv, mf)), np.arange(2), msym)
    assert not loose.any()
    np.testing.assert_array_equal(out, msym)


def test_detect_carries_the_global_map_onto_parts_without_samples():
    v, f, sym, component = _with_loose_parts()
    result = intrinsym.detect((v, f), n_source=60, n_target=600, seed=0)
    image = result.symmetry_map()
    assert result.info.global_map is not None and result.info.global_map.carried > 0
    # each loose part lands on its mirror part (the eyes on each other, the tooth on itself)
    for part in (1, 2, 3):
        assert np.mean(component[image[component == part]] == component[sym[component == part]]) > 0.95
    # a vertex no sample's cell reaches is as sure as the nearest vertex a cell holds
    conf = result.symmetry_confidence()
    seen = result.support.vertex_source >= 0
    assert not seen.all()
    nearest = cKDTree(v[seen]).query(v[~seen])[1]
    np.testing.assert_array_equal(conf[~seen], conf[seen][nearest])


def _strip() -> tuple[np.ndarray, np.ndarray]:
    """100 vertices along x in [0, 1), 0.01 apart, each standing for an area of 0.01."""
    return np.column_stack([np.arange(100) * 0.01, np.zeros(100), np.zeros(100)]), np.full(100, 0.01)


def test_the_inverse_covers_the_parts_area_near_its_images():
    """A part of area 0.5 (and half a vertex) whose 25 vertices map, a little compressed, onto x in [0, 0.36]
    of the strip: its counterpart is the half nearest the images (x < 0.5, the images
    spread to the part's area), the rest "no match"; each covered vertex takes the part
    vertex whose image lies nearest."""
    whole, area = _strip()
    image = np.arange(25) * 3 // 2  # x = 0.00, 0.01, 0.03, ... 0.36
    out = inverse_vertex_map(image, whole, area, 0.505, reach=0.2)
    assert np.all(out[:50] >= 0) and np.all(out[50:] == -1)
    assert np.array_equal(out[image], np.arange(25))
    # the reach stops a collapsed map: within 0.025 of the images only
    assert np.array_equal(inverse_vertex_map(image, whole, area, 0.505, reach=0.025) >= 0, np.arange(100) <= 38)
    # and the part's area a spread one: a part of area 0.2 covers the 20 vertices nearest
    assert np.sum(inverse_vertex_map(image, whole, area, 0.205, reach=0.2) >= 0) == 20


def test_the_inverse_prefers_the_centres_among_part_vertices_sharing_an_image():
    whole, area = _strip()
    image = np.array([5, 5, 5, -1, 40])
    assert inverse_vertex_map(image, whole, area, 0.02, reach=0.1)[5] == 0  # the lowest index
    out = inverse_vertex_map(image, whole, area, 0.02, reach=0.1, centres=np.array([2, 4]))
    assert out[5] == 2 and out[40] == 4 and np.sum(out >= 0) == 2
    assert np.all(inverse_vertex_map(np.full(5, -1), whole, area, 0.5, reach=0.1) == -1)
