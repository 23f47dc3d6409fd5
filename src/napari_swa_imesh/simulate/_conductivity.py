"""Conductivity per material: parsing, checks, and the axis convention.

Users give conductivities in the mesh-file frame, x = column, y = row(, z = plane), the
order FE tools and ``k_eff`` reports use. Inside, tensors are kept in the image's axis
order (plane, row, column), the order of ``Mesh.points``; the two differ by reversing
both tensor axes.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

__all__ = ["AXIS_NAMES", "axis_names", "conductivity_tensors", "is_isotropic",
           "material_label", "parse_conductivity_args"]

AXIS_NAMES = ("x", "y", "z")


def axis_names(ndim: int) -> tuple[str, ...]:
    """Names of the image axes (plane, row, column) in the FE frame: ``('z', 'y', 'x')``.

    Examples
    --------
    >>> axis_names(2)
    ('y', 'x')
    """
    return AXIS_NAMES[:ndim][::-1]


CONDUCTIVITY_RANGE = (1e-30, 1e30)
"""Accepted conductivity values (eigenvalues of a tensor), as :data:`SPACING_RANGE
<napari_swa_imesh._validation.SPACING_RANGE>` for lengths: the solver's inner products
hold squares of conductivities times lengths, which overflow float64 (about 1e308) for
values near 1e100 even at contrast 1; k = 1e-30 and 1e30 solve to 1e-13 with spacings
of 1e-30 and 1e30."""


def _as_tensor(value, ndim: int, where: str) -> np.ndarray:
    """One material's conductivity as a (d, d) tensor in the x, y(, z) frame."""
    if isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{where} must be a number, {ndim} numbers or a {ndim}x{ndim} "
                         f"tensor, not {value!r}.")
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{where} must be a number, {ndim} numbers or a {ndim}x{ndim} "
                         f"tensor, not {value!r}.") from None
    if arr.ndim == 0:
        tensor = np.diag(np.full(ndim, float(arr)))
    elif arr.shape == (ndim,):
        tensor = np.diag(arr)
    elif arr.shape == (ndim, ndim):
        tensor = arr.copy()
    else:
        raise ValueError(f"{where} must be a number, {ndim} numbers (x, y{', z' * (ndim > 2)})"
                         f" or a {ndim}x{ndim} tensor; got shape {arr.shape}.")
    if not np.all(np.isfinite(tensor)):
        raise ValueError(f"{where} is not finite ({value!r}); give a positive finite number.")
    if not np.allclose(tensor, tensor.T, rtol=1e-12, atol=0):
        raise ValueError(f"{where} must be a symmetric tensor.")
    eigen = np.linalg.eigvalsh(tensor)
    if eigen.min() <= 0:
        raise ValueError(f"{where} must be positive (a positive number or a positive "
                         f"definite tensor), not {value!r}.")
    lo, hi = CONDUCTIVITY_RANGE
    if eigen.min() < lo or eigen.max() > hi:
        raise ValueError(f"{where} is {value!r}, outside {lo:g} .. {hi:g}: the solver "
                         "multiplies conductivities with each other and with lengths, "
                         "which beyond that range leaves float64; express the "
                         "conductivities in other units (k_eff scales with them).")
    return tensor


def material_label(key, names: Mapping[int, str] | None = None) -> int | None:
    """The material a key names: a material name, an integer label or its text; None for
    anything else.

    Examples
    --------
    >>> material_label("bone", {3: "bone"}), material_label("2"), material_label(True)
    (3, 2, None)
    """
    if isinstance(key, str):
        by_name = {str(v): int(k) for k, v in (names or {}).items()}
        if key in by_name:
            return by_name[key]
        return int(key) if key.lstrip("-").isdigit() else None
    if isinstance(key, (int, np.integer)) and not isinstance(key, bool):
        return int(key)
    return None


def conductivity_tensors(conductivity: Mapping, materials, ndim: int,
                         names: Mapping[int, str] | None = None) -> np.ndarray:
    """Conductivity tensors of `materials`, in the image's axis order.

    Parameters
    ----------
    conductivity : mapping of int or str to float, (d,) or (d, d) array_like
        Per material (by label or by name): a number (isotropic), ``d`` numbers (the
        diagonal in x, y(, z) order) or a symmetric positive definite tensor in the
        x, y(, z) frame.
    materials : sequence of int
        The materials present in the mesh; each needs a conductivity.
    ndim : int
        2 or 3.
    names : mapping of int to str, optional
        Material names, so that `conductivity` can name materials.

    Returns
    -------
    tensors : (n_materials, d, d) ndarray of float64
        In the image's axis order (plane, row, column), row i for ``materials[i]``.

    Examples
    --------
    >>> conductivity_tensors({1: 2.0, 2: [1.0, 3.0]}, [1, 2], 2)[1]   # x=1, y=3
    array([[3., 0.],
           [0., 1.]])
    """
    if not isinstance(conductivity, Mapping) or not conductivity:
        raise ValueError("conductivity must map every material (label or name) to a value, "
                         "e.g. {1: 1.0, 2: 10.0}.")
    table: dict[int, np.ndarray] = {}
    for key, value in conductivity.items():
        label = material_label(key, names)
        if label is None:
            known = ", ".join(f"{k} ({v})" for k, v in sorted((names or {}).items())) or \
                ", ".join(str(m) for m in materials)
            raise ValueError(f"conductivity names material {key!r}, which is not in the "
                             f"mesh; the materials are {known}.")
        if label in table:
            raise ValueError(f"material {label} is given a conductivity twice.")
        table[label] = _as_tensor(value, ndim, f"the conductivity of material {key}")
    materials = [int(m) for m in materials]
    missing = [m for m in materials if m not in table]
    if len(materials) > 64 and len(missing) > 32:
        raise ValueError(f"the input has {len(materials)} distinct values, {len(missing)} of "
                         "them without a conductivity: is it an image rather than a label "
                         "image? Segment it first (swa-imesh segment) and simulate the labels.")
    if missing:
        named = ", ".join(f"{m}" + (f" ({names[m]})" if names and m in names else "")
                          for m in missing)
        raise ValueError(f"material {named} has no conductivity; give one for every "
                         f"material in the mesh ({', '.join(map(str, materials))}).")
    extra = sorted(set(table) - set(materials))
    if extra:
        raise ValueError(f"conductivity names material {extra[0]}, which is not in the "
                         f"mesh; the materials are {', '.join(map(str, materials))}.")
    xyz = np.stack([table[m] for m in materials])
    return np.ascontiguousarray(xyz[:, ::-1, ::-1])


#: one material's conductivity as the command line gives it: a number, a diagonal, a tensor
_Given = float | list[float] | list[list[float]]


def parse_conductivity_args(items: list[str]) -> dict[str, _Given]:
    """``['1=1', 'bone=10', '3=0.1,0.2,0.3']`` -> ``{'1': 1.0, 'bone': 10.0, '3': [...]}``.

    A comma list is the diagonal in x, y(, z) order; ``d*d`` numbers are a full tensor
    row by row.
    """
    out: dict[str, _Given] = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or not key or not text:
            raise ValueError(f"--conductivity takes MATERIAL=VALUE pairs such as 1=0.5 or "
                             f"bone=10, not {item!r}.")
        try:
            numbers = [float(t) for t in text.split(",")]
        except ValueError:
            raise ValueError(f"--conductivity {item!r}: {text!r} is not a number or a "
                             "comma list of numbers.") from None
        if key in out:
            raise ValueError(f"--conductivity gives material {key} twice.")
        if len(numbers) in (4, 9):
            d = int(round(len(numbers) ** 0.5))
            out[key] = np.reshape(numbers, (d, d)).tolist()
        else:
            out[key] = numbers[0] if len(numbers) == 1 else numbers
    return out


def is_isotropic(tensors: np.ndarray) -> bool:
    """True when every tensor is a multiple of the identity."""
    d = tensors.shape[-1]
    iso = tensors[:, 0, 0][:, None, None] * np.eye(d)
    return bool(np.array_equal(tensors, iso))
