"""The lattice for spacings as real files carry them (issue 22, section 1).

Spacings are drawn as the decimals and fractions headers mean (0.8, 0.9375, 1.2, 55/64),
with per-axis aspect up to 4, then stored as float32 or perturbed by 1e-6 relative noise;
the factors are compared with a brute force over every factor tuple, in exact fractions,
that shares no code with the search it checks.
"""

from __future__ import annotations

import itertools
import math
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from napari_swa_imesh.mesh import mesh_labels
from napari_swa_imesh.mesh.checks._checks import check_mesh
from napari_swa_imesh.mesh.mesher import _templates
from napari_swa_imesh.mesh.mesher._lattice import (
    ASPECT_LIMIT,
    MAX_FACTOR,
    aspect_bounds,
    choose_lattice,
    lattice_choices,
    subdivision_factors,
)
from napari_swa_imesh.mesh.model._quality import (
    dihedral_angles,
    radius_edge_ratio,
    triangle_angles,
)

DENOMINATORS = (1, 2, 4, 5, 8, 10, 16, 20, 32, 64)
LIMITS = (1.0, 1.1, 1.2, ASPECT_LIMIT, 1.3, 1.5, 2.0)


@st.composite
def exact_spacings(draw, d=None):
    """Spacings m / q as headers write them, largest over smallest at most 4; their ratios
    are fractions of denominator <= 150 (the ones the tolerance reads back exactly)."""
    d = draw(st.sampled_from((2, 3))) if d is None else d
    q = draw(st.sampled_from(DENOMINATORS))
    smallest = draw(st.integers(max(1, q // 4), min(150, 8 * q)))
    top = 4 * smallest
    m = [smallest] + [draw(st.integers(smallest, top)) for _ in range(d - 1)]
    order = draw(st.permutations(range(d)))
    return tuple(Fraction(m[i], q) for i in order)


@st.composite
def boundary_spacings(draw):
    """(spacing, limit) whose voxels cut into some cells of residual aspect exactly the
    limit: where a float comparison flips under float32 rounding or noise."""
    d = draw(st.sampled_from((2, 3)))
    limit = draw(st.sampled_from(LIMITS[1:]))
    a = Fraction(limit).limit_denominator(1000)
    n = [draw(st.integers(1, 4)) for _ in range(d)]
    big = draw(st.lists(st.booleans(), min_size=d, max_size=d)
               .filter(lambda b: any(b) and not all(b)))
    c = Fraction(draw(st.sampled_from((1, 3, 5, 15))), draw(st.sampled_from((4, 8, 10, 16))))
    spacing = tuple(k * c * (a if up else 1) for k, up in zip(n, big))
    assume(max(spacing) / min(spacing) <= 4)
    return spacing, limit


def brute_force(spacing, limit) -> tuple[int, int, Fraction] | None:
    """(cells, residual aspect) of the best admissible tuples, and the set of them."""
    s = [Fraction(v) for v in spacing]
    a = Fraction(limit).limit_denominator(1000)
    best = None
    for f in itertools.product(range(1, MAX_FACTOR + 1), repeat=len(s)):
        h = [v / n for v, n in zip(s, f)]
        aspect = max(h) / min(h)
        if aspect <= a:
            key = (math.prod(f), aspect)
            best = key if best is None or key < best else best
    return best


def noisy(spacing, rng_seed: int, how: str) -> tuple[float, ...]:
    exact = np.array([float(v) for v in spacing])
    if how == "float32":
        return tuple(float(v) for v in exact.astype(np.float32))
    rng = np.random.default_rng(rng_seed)
    return tuple(float(v) for v in exact * (1 + rng.uniform(-1e-6, 1e-6, exact.size)))


@settings(max_examples=80, deadline=None)
@given(st.one_of(st.tuples(exact_spacings(), st.sampled_from(LIMITS)), boundary_spacings()),
       st.integers(0, 2**31), st.sampled_from(("float32", "noise")))
def test_factors_survive_float32_and_noise_and_permute_with_the_axes(case, seed, how):
    spacing, limit = case
    try:
        exact = subdivision_factors([float(v) for v in spacing], max_aspect=limit)
    except ValueError:
        assert brute_force(spacing, limit) is None     # refused only when nothing fits
        return
    assert subdivision_factors(noisy(spacing, seed, how), max_aspect=limit) == exact
    rng = np.random.default_rng(seed)
    perm = rng.permutation(len(spacing))
    permuted = tuple(noisy(spacing, seed, how)[i] for i in perm)
    assert subdivision_factors(permuted, max_aspect=limit) == tuple(exact[i] for i in perm)


@settings(max_examples=60, deadline=None)
@given(st.one_of(st.tuples(exact_spacings(), st.sampled_from(LIMITS)), boundary_spacings()))
def test_factors_are_the_fewest_cells_within_the_limit_and_its_bound_holds(case):
    spacing, limit = case
    reference = brute_force(spacing, limit)
    try:
        got = subdivision_factors([float(v) for v in spacing], max_aspect=limit)
    except ValueError:
        assert reference is None
        return
    h = [Fraction(v) / n for v, n in zip(spacing, got)]
    aspect = max(h) / min(h)
    # the fewest cells of every tuple up to MAX_FACTOR, and of those the smallest aspect
    assert (math.prod(got), aspect) == reference
    assert aspect <= Fraction(limit).limit_denominator(1000)
    # the bound stated for the limit holds for the cells chosen (it grows with the aspect)
    d = len(spacing)
    stated = aspect_bounds(d, limit)
    actual = aspect_bounds(d, float(aspect))
    assert actual["worst_ratio"] <= stated["worst_ratio"] + 1e-12
    assert actual["min_angle"] >= stated["min_angle"] - 1e-12


@settings(max_examples=40, deadline=None)
@given(exact_spacings())
def test_the_choices_table_is_a_strict_trade_off_that_contains_every_limit(spacing):
    rows = lattice_choices([float(v) for v in spacing], max_rows=20)
    cells = [r["cells_per_voxel"] for r in rows]
    aspects = [r["residual_aspect"] for r in rows]
    assert cells == sorted(cells) and len(set(cells)) == len(cells)
    assert all(a > b for a, b in itertools.pairwise(aspects))
    assert rows[0]["factors"] == (1,) * len(spacing)
    for limit in LIMITS:
        try:
            chosen = subdivision_factors([float(v) for v in spacing], max_aspect=limit)
        except ValueError:
            continue
        row = next((r for r in rows if r["residual_aspect"] <= limit * (1 + 1e-9)), None)
        if row is not None:       # the table may stop at max_rows or the factors
            assert row["factors"] == chosen


@pytest.mark.parametrize("spacing,factors", [
    ((0.9375, 0.9375, 1.5), (1, 1, 2)),              # the clinical MR protocol: 1.25
    ((0.9, 1.1, 2.0), (1, 1, 2)),                    # 1.1 / 0.9 = 1.22
    ((1.0, 0.800000011920929, 1.2), (2, 2, 3)),      # float32 0.8: cells 0.5, 0.4, 0.4
    ((1.0, 0.8, 1.2000000476837158), (2, 2, 3)),
    ((2.5, 1.0, 1.0), (2, 1, 1)),
    ((8.0, 1.0, 1.0), (7, 1, 1)),                    # 8 / 6 = 1.33 > 1.25
])
def test_the_issue_spacings_take_the_fewest_cells(spacing, factors):
    assert subdivision_factors(spacing) == factors
    # the old 1.2 limit is one option away, and its factors are never fewer
    assert math.prod(subdivision_factors(spacing, max_aspect=1.2)) >= math.prod(factors)


def test_the_default_limit_keeps_the_issue_bound_and_is_near_the_largest_that_does():
    b = aspect_bounds(3, ASPECT_LIMIT)
    assert b["worst_ratio"] <= 1.40 and b["min_angle"] >= 29.0
    over = aspect_bounds(3, 1.28)
    assert over["worst_ratio"] > 1.40 or over["min_angle"] < 29.0


@pytest.mark.parametrize("bad", [0.9, float("nan"), float("inf"), True, "1.3"])
def test_a_bad_max_aspect_is_refused(bad):
    with pytest.raises(ValueError, match="max_aspect must be a finite number >= 1"):
        choose_lattice((1.0, 1.0, 2.0), max_aspect=bad)


def test_max_aspect_with_no_subdivision_is_refused():
    with pytest.raises(ValueError, match="give one or the other"):
        choose_lattice((1.0, 1.0, 2.0), subdivide=False, max_aspect=1.3)


def small_labels(rng, d: int) -> np.ndarray:
    shape = tuple(int(n) for n in rng.integers(2, 7 if d == 3 else 12, size=d))
    lab = rng.integers(0, 3, size=shape)
    lab[rng.random(shape) < 0.5] = 1
    return lab.astype(np.uint8)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(exact_spacings(), st.sampled_from((1.2, ASPECT_LIMIT, 1.5)), st.integers(0, 2**31),
       st.booleans())
def test_meshes_pass_the_checks_within_the_bound_and_cells_cap_the_elements(
        spacing, limit, seed, f32):
    rng = np.random.default_rng(seed)
    d = len(spacing)
    lab = small_labels(rng, d)
    s = noisy(spacing, seed, "float32" if f32 else "noise")
    try:
        lattice = choose_lattice(s, max_aspect=limit)
    except ValueError:
        return
    mesh = mesh_labels(lab, spacing=s, max_aspect=limit)
    assert check_mesh(mesh, lab).all_passed
    info = mesh.recipe.lattice.describe()
    assert tuple(info["factors"]) == lattice.factors and info["max_aspect"] == limit
    assert info["residual_aspect"] <= limit * (1 + 1e-5)
    bound = aspect_bounds(d, limit * (1 + 1e-5))
    ratio = radius_edge_ratio(mesh.points, mesh.cells)
    assert ratio.max() <= bound["worst_ratio"] + 1e-9
    lo, hi = (dihedral_angles if d == 3 else triangle_angles)(mesh.points, mesh.cells)
    assert lo.min() >= bound["min_angle"] - 1e-9 and hi.max() <= bound["max_angle"] + 1e-9
    # the elements are no more than the chosen cells allow: at most the leaf table's 40
    # tetrahedra (8 triangles in 2-D) per lattice cell
    n_cells = lab.size * math.prod(lattice.cells_per_voxel)
    assert mesh.n_cells <= (40 if d == 3 else 8) * n_cells


def test_vertices_numbered_by_search_are_the_prefix_sum_numbers(monkeypatch):
    # a large, mostly empty lattice takes the search; forced here on a small one
    lab = np.ones((6, 5, 6), np.uint8)        # few leaves: the lattice is mostly empty
    lab[2, 3, 1] = 2
    lab[4:, :2, 3:] = 0
    dense = mesh_labels(lab, spacing=(1.0, 0.8, 1.2), refine=1)
    calls = {"prefix sum": 0, "search": 0}

    def cumsum(a, *args, **kwargs):
        calls["prefix sum"] += np.asarray(a).dtype == bool      # over the lattice flags
        return np.cumsum(a, *args, **kwargs)

    def searchsorted(a, v, *args, **kwargs):
        calls["search"] += np.ndim(v) == 3                      # a block of element keys
        return np.searchsorted(a, v, *args, **kwargs)

    class Spy:                      # numpy as the template module sees it
        def __getattr__(self, name):
            return {"cumsum": cumsum, "searchsorted": searchsorted}.get(name) \
                or getattr(np, name)

    monkeypatch.setattr(_templates, "DENSE_RANK_LIMIT", 0)
    monkeypatch.setattr(_templates, "np", Spy())
    sparse = mesh_labels(lab, spacing=(1.0, 0.8, 1.2), refine=1)
    assert calls["search"] > 0 and calls["prefix sum"] == 0
    assert np.array_equal(dense.points, sparse.points)
    assert np.array_equal(dense.cells, sparse.cells)


@settings(max_examples=60, deadline=None)
@given(exact_spacings(), st.integers(0, 4))
def test_refinement_counts_the_subdivision_and_reaches_its_size_with_the_fewest_levels(
        spacing, refine):
    s = [float(v) for v in spacing]
    lattice = choose_lattice(s, refine=refine)
    cells = lattice.cells_per_voxel
    # every cell at most 2^-refine voxels along every axis ...
    assert min(cells) >= 1 << refine
    # ... and one level fewer would leave some axis coarser than that
    assert lattice.refine == 0 or min(cells) >> 1 < 1 << refine
    assert lattice.factors == subdivision_factors(s)
