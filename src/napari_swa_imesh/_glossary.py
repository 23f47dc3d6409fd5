"""The project's words, each defined once in one line.

The command line prints these where a term appears in its output (``swa-imesh glossary``
lists them all) and the napari widgets use them as tooltips, so a term reads the same
everywhere. Plain module: no Qt, no napari.
"""

from __future__ import annotations

import re

__all__ = ["GLOSSARY", "define", "terms_in", "glossary_text"]

GLOSSARY: dict[str, str] = {
    "SWA": "Stochastic wavelet analysis: each tile (or window) of the image is described by "
           "the statistics of its grey levels, and a classifier trained on sample boxes "
           "labels it with a material.",
    "IMESH": "Image meshing on a balanced 2^d-tree: blocks split until one material fills "
             "each, neighbours differ at most 2:1 in size, and each block is filled with "
             "template triangles or tetrahedra, so boundaries follow the voxels exactly.",
    "RES": "Representative elementary scale: the tile size 2^j px from which a material's "
           "tile statistics stop changing with size and from tile to tile; the scale to "
           "classify at.",
    "eps_l": "Leave-one-out (here cross-validated) error of the classifier on the training "
             "tiles or pixels of the sample boxes, in percent.",
    "eps_m": "Modified error -#F x eps_l / 100 (eq. 2.35, #F = number of features): eps_l "
             "charged for the feature count, to compare feature sets; closer to 0 is better.",
    "radius-to-edge ratio": "Element quality: circumradius over shortest edge (1/sqrt(3) for "
                            "an equilateral triangle); IMESH bounds its worst value, "
                            "sqrt(5)/2 = 1.118.",
    "k_eff": "Effective conductivity: the single conductivity of a uniform block that "
             "carries the same total flux as the meshed materials under the same boundary "
             "conditions.",
    "P1": "Finite elements with linear shape functions (unknowns at the mesh vertices).",
    "P2": "Finite elements with quadratic shape functions (unknowns at vertices and edge "
          "midpoints): more accurate on the same mesh, about 8x the unknowns in 3-D.",
    "Doerfler": "Doerfler (bulk) marking for adaptive refinement: refine the fewest elements "
                "whose error estimates add up to a set fraction of the total.",
    "mixed": "Mixed protocol: u = 0 and u = 1 on the two faces normal to the flow axis, no "
             "flux through the other faces; gives one k_eff per axis.",
    "periodic": "Periodic protocol: u = x.e plus a periodic fluctuation; gives the full "
                "effective conductivity tensor of a periodic sample.",
    "Dice": "Overlap of a material's labels with the truth, 2|A and B| / (|A| + |B|): 1 is "
            "perfect, 0 no overlap.",
    "GM": "Gaussian maximum-likelihood classifier: one Gaussian per material fitted on its "
          "training features (quadratic discriminant).",
}

# how each term is spelled where it appears in text (a pattern per term)
_SPELLINGS = {
    "SWA": r"\bSWA\b", "IMESH": r"\bIMESH\b", "RES": r"\bRES\b", "eps_l": r"\beps_l\b",
    "eps_m": r"\beps_m\b", "radius-to-edge ratio": r"radius[- ]to[- ]edge",
    "k_eff": r"\bk_eff\b", "P1": r"\bP1\b", "P2": r"\bP2\b", "Doerfler": r"\bDoerfler\b",
    "mixed": r"\bmixed\b", "periodic": r"\bperiodic\b", "Dice": r"\bDice\b", "GM": r"\bGM\b",
}


def define(term: str) -> str:
    """The one-line definition of `term` (a key of :data:`GLOSSARY`).

    Examples
    --------
    >>> define("eps_m").startswith("Modified error")
    True
    """
    try:
        return GLOSSARY[term]
    except KeyError:
        raise KeyError(f"{term!r} is not in the glossary; known: "
                       f"{', '.join(GLOSSARY)}.") from None


def terms_in(text: str) -> list[str]:
    """The glossary terms that appear in `text`, in glossary order.

    Examples
    --------
    >>> terms_in("k_eff by P1 (mixed)")
    ['k_eff', 'P1', 'mixed']
    """
    return [t for t in GLOSSARY if re.search(_SPELLINGS[t], text)]


def glossary_text(terms=None) -> str:
    """``term: definition`` lines for `terms` (default: all)."""
    return "\n".join(f"{t}: {define(t)}" for t in (GLOSSARY if terms is None else terms))


def add_command(subparsers) -> None:
    """Register ``swa-imesh glossary [TERM ...]`` on an argparse sub-parser group."""
    p = subparsers.add_parser(
        "glossary", help="one-line definitions of the terms the outputs use",
        description="Print the one-line definition of each term (default: all of them): "
                    + ", ".join(GLOSSARY) + ".")
    p.add_argument("terms", nargs="*", help="terms to define (default: all)")
    p.set_defaults(func=_run_glossary)


def _run_glossary(args) -> int:
    names = {t.lower(): t for t in GLOSSARY}
    unknown = [t for t in args.terms if t.lower() not in names]
    if unknown:
        raise ValueError(f"not in the glossary: {', '.join(unknown)}; known terms: "
                         f"{', '.join(GLOSSARY)}.")
    print(glossary_text([names[t.lower()] for t in args.terms] or None))
    return 0
