"""Adaptive refinement: mesh a label image again, one lattice level finer where asked.

A solver marks the elements where its error indicator is largest (simulate's flux-jump
indicator); :func:`refine_marked` meshes the labels as the first mesh was (its lattice,
exclusions, size cap, periodic faces) on a lattice twice as fine, each leaf that holds a
marked element cut once into 2^d. The
tree is balanced again and cut by the same templates, so conformity, exact material volumes
and the quality bound of the lattice all hold as for any other IMESH mesh.
"""

from __future__ import annotations

import time

import numpy as np

from ..._region_tree import RegionTree
from ..model._recipe import Adapted
from ..model._types import Mesh
from ._balance import balance_tree
from ._imesh import _mesh_arguments, _mesh_tree, _names
from ._lattice import MAX_REFINE, Lattice, finer_tree, lattice_tree, split_box_faces, split_leaves

__all__ = ["refine_marked"]


def refine_marked(labels, mesh: Mesh, marked: np.ndarray) -> Mesh:
    """The IMESH mesh of `labels`, refined once more in the cells of marked elements.

    Parameters
    ----------
    labels : (M, N[, P]) array_like of int
        The label image `mesh` was made from (checked again here).
    mesh : Mesh
        A template mesh of `labels` from :func:`mesh_labels` (its ``recipe`` records the
        lattice, exclusions, size cap and periodic faces), in index space (no coarsening).
    marked : (n_cells,) array_like of bool
        Elements of `mesh` to refine.

    Returns
    -------
    Mesh
        On the lattice one refine level finer; ``recipe.adapted`` counts the steps, the
        marked elements and the leaves split.

    Raises
    ------
    ValueError
        For a mesh that is not a template mesh of these labels, a wrong-length mask, a
        mesh adapted before (refine it with the tree :func:`_refine_marked` returned), or
        a lattice already at the finest refine level.
    """
    return _refine_marked(labels, mesh, marked)[0]


def _refine_marked(labels, mesh: Mesh, marked: np.ndarray, tree: RegionTree | None = None
                   ) -> tuple[Mesh, RegionTree]:
    """:func:`refine_marked`, with the (unbalanced) tree `mesh` was cut from when known
    (required for a mesh adapted before: its tree is not the labels' own); returns the
    new mesh and its tree, for the next step."""
    recipe = mesh.recipe
    coarse = None if recipe is None else recipe.lattice
    if recipe is None or not recipe.remeshable or coarse is None:
        raise ValueError("adaptive refinement needs a template mesh made from the labels by "
                         "mesh_labels (not read from a file, not coarsened).")
    marked = np.asarray(marked, dtype=bool)
    if marked.shape != (mesh.n_cells,):
        raise ValueError(f"marked needs one flag per element ({mesh.n_cells}), not shape "
                         f"{marked.shape}.")
    spacing = tuple(float(s) for s in mesh.spacing)
    lab, _, exclude = _mesh_arguments(labels, method="template", exclude=recipe.exclude,
                                      spacing=spacing)
    if tuple(lab.shape) != tuple(mesh.shape):
        raise ValueError(f"the labels have shape {lab.shape} but the mesh was made from "
                         f"{tuple(mesh.shape)}: pass the labels the mesh was made from.")
    if coarse.refine >= MAX_REFINE:
        raise ValueError(f"the mesh is at refine level {MAX_REFINE} already, the finest; "
                         "it cannot be refined further.")
    fine = Lattice(spacing, coarse.factors, coarse.refine + 1, coarse.max_aspect)
    max_size, periodic = recipe.max_size, recipe.periodic

    t0 = time.perf_counter()
    if tree is None:
        if recipe.adapted is not None:
            raise ValueError("this mesh was adapted before, so its tree is not the labels' "
                             "own: pass the tree the last step returned.")
        tree = lattice_tree(lab, coarse, exclude=exclude, max_size=max_size,
                            periodic=periodic)
    # the balanced tree the mesh was cut from (balancing is deterministic): its leaves are
    # what the elements' "leaf" numbers index
    bal = balance_tree(tree, connectivity=max(1, lab.ndim - 1))
    leaf = np.asarray(mesh.cell_data["leaf"])
    if (leaf.max(initial=-1) >= len(bal.level)
            or not np.array_equal(bal.label[leaf], mesh.material)):
        raise ValueError("the mesh does not match the tree of these labels: pass the labels "
                         "the mesh was made from, and a mesh that was not modified.")
    split = np.zeros(len(bal.level), dtype=bool)
    split[leaf[marked]] = True
    tree = _split_once(bal, split, periodic)
    seconds = {"tree": time.perf_counter() - t0}
    before = recipe.adapted
    adapted = Adapted(steps=(0 if before is None else before.steps) + 1,
                      marked_elements=int(marked.sum()), split_leaves=int(split.sum()),
                      from_refine=coarse.refine if before is None else before.from_refine)
    out = _mesh_tree(tree, method="template", exclude=exclude, spacing=fine.step,
                     material_names=_names(mesh.material_names), connectivity=None,
                     report_face_balance=False, seconds=seconds, periodic=periodic,
                     image=(tuple(lab.shape), spacing), lattice=fine, max_size=max_size,
                     adapted=adapted)
    out.world = mesh.world              # the same image, so the same place in the world
    return out, tree


def _split_once(bal: RegionTree, split: np.ndarray, periodic: bool) -> RegionTree:
    """`bal` on the lattice twice as fine, each leaf in `split` cut once into 2^d."""
    finer = finer_tree(bal, 1)
    strides = np.cumprod((1,) + finer.padded_shape[:0:-1])[::-1].astype(np.int64)

    def key(origin: np.ndarray, size: np.ndarray) -> np.ndarray:
        # (origin, side) of a leaf as one integer: a marked leaf's children have its
        # corner but half its side, so they are not split again
        return (origin @ strides) * 64 + np.log2(size).astype(np.int64)

    marked = key(finer.origin[split], np.left_shift(1, finer.level[split].astype(np.int64)))
    finer = split_leaves(finer, lambda origin, size: np.isin(key(origin, size), marked))
    return split_box_faces(finer) if periodic else finer
