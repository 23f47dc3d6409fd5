"""One report of an up-scaling run: per material its signature and conductivity, then k_eff.

A row per material joins what segmentation measured (the signatures table that
``swa-imesh segment --signatures`` writes: tile-moment means and deviations) to what the
simulation used and found (the volume fraction of the image box, the conductivity), and
the effective conductivity per axis (and the periodic tensor) follows the table. Rows are
matched by label, and a signature row without a label by its name; a name that disagrees
with the mesh's name for the same label is refused (the signatures belong to another
labelling), and a material on one side only is kept with empty cells and named in a
warning, never shifted onto another row.

Files: ``.csv`` (the material table, a blank line, then the k_eff block: header
``quantity,x,y(,z)``, rows ``k_eff``, ``reuss``, ``voigt``, with the certified interval
``lower``, ``upper`` and ``gap``, and ``tensor_<axis>``),
``.json`` (:meth:`SimulationReport.summary`, also in ``simulate --json``) and ``.md``.
"""

from __future__ import annotations

import csv
import io as _io
import json
import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..io import atomic_write, check_writable
from ._conductivity import conductivity_tensors

__all__ = ["REPORT_SUFFIXES", "SimulationReport", "check_report_path", "match_signatures",
           "read_signatures", "simulation_report", "write_report"]

REPORT_SUFFIXES = (".csv", ".json", ".md")
_FIRST = ("label", "name", "volume_fraction", "conductivity")


def _number(text: str):
    """CSV cell -> int, float (empty or "nan": NaN) or the text itself."""
    text = text.strip()
    if not text:
        return float("nan")
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        return text


def read_signatures(path) -> list[dict]:
    """Read a per-material table (``swa-imesh segment --signatures``) from CSV.

    Parameters
    ----------
    path : str or Path
        CSV with a header; a ``label`` column (integer) and/or a ``name`` column identify
        each row, the other columns are kept as numbers (empty cells: NaN).

    Returns
    -------
    list of dict
        One row per material, keys in the file's column order.

    Raises
    ------
    ValueError
        A file that is not such a table: no ``label`` or ``name`` column, no row, a row
        with neither or with another number of cells, a label that is not a whole number.
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"no signatures file at {p}; give the CSV that swa-imesh "
                                "segment --signatures writes.")
    try:
        text = p.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise ValueError(f"{p.name} is not a text (CSV) file; give the signatures CSV "
                         "that swa-imesh segment --signatures writes.") from None
    lines = csv.reader(_io.StringIO(text))
    columns = [c.strip() for c in next(lines, [])]
    if not {"label", "name"} & set(columns):
        raise ValueError(f"{p.name} has no 'label' or 'name' column (columns: "
                         f"{', '.join(columns) or 'none'}); give the signatures CSV that "
                         "swa-imesh segment --signatures writes.")
    try:
        rows = _signature_rows(p.name, columns, lines)
    except csv.Error as exc:
        raise ValueError(f"{p.name} is not a readable CSV table ({exc}); give the "
                         "signatures CSV that swa-imesh segment --signatures writes.") from None
    if not rows:
        raise ValueError(f"{p.name} has a header but no material rows.")
    return rows


def _signature_rows(name: str, columns: list[str], lines) -> list[dict]:
    rows = []
    for n, cells in enumerate(lines, start=2):
        if not any(c.strip() for c in cells):
            break                     # a blank line ends the table (a report's first block)
        if len(cells) != len(columns):
            raise ValueError(f"{name} line {n} has {len(cells)} cells for "
                             f"{len(columns)} columns; fix the row or write the file again.")
        row = {}
        for key, value in zip(columns, (c.strip() for c in cells)):
            if key == "label":
                if value and not value.lstrip("-").isdigit():
                    raise ValueError(f"{name} line {n}: label {value!r} is not a whole "
                                     "number.")
                row[key] = int(value) if value else None
            elif key == "name":
                row[key] = value
            else:
                row[key] = _number(value)
        if row.get("label") is None and not row.get("name"):
            raise ValueError(f"{name} line {n} has neither a label nor a name; give every "
                             "material one.")
        rows.append(row)
    return rows


def match_signatures(signatures: Sequence[Mapping], names: Mapping[int, str]
                     ) -> tuple[dict[int, dict], list[dict]]:
    """Key signature rows by material label: by their label, else by their name.

    Parameters
    ----------
    signatures : sequence of mapping
        Rows with ``label`` (int or None) and/or ``name``.
    names : mapping of int to str
        The mesh's material names.

    Returns
    -------
    by_label : dict of int to dict
        Rows that name a label (given, or found from the name).
    unmatched : list of dict
        Rows with a name only, not among `names`.

    Raises
    ------
    ValueError
        A label or name given twice, or a row whose name disagrees with the mesh's name
        for its label.

    Examples
    --------
    >>> by_label, rest = match_signatures([{"label": 2, "name": "grass"},
    ...                                    {"label": None, "name": "brick"}], {1: "brick"})
    >>> sorted(by_label), rest
    ([1, 2], [])
    """
    by_name = {str(v): int(k) for k, v in names.items() if str(v)}
    by_label: dict[int, dict] = {}
    unmatched, seen_names = [], set()
    for row in signatures:
        label, name = row.get("label"), str(row.get("name") or "")
        if name:
            if name in seen_names:
                raise ValueError(f"the signatures give material {name!r} twice; keep one "
                                 "row per material.")
            seen_names.add(name)
        if label is None:
            if name not in by_name:
                unmatched.append(dict(row))
                continue
            label = by_name[name]
        label = int(label)
        if label in by_label:
            raise ValueError(f"the signatures give material {label} twice; keep one row "
                             "per material.")
        known = str(names.get(label, ""))
        if name and known and name != known:
            raise ValueError(f"the signatures name material {label} {name!r} but the mesh "
                             f"names it {known!r}: they belong to another labelling. Use "
                             "the signatures of these labels, or material names that agree.")
        by_label[label] = {**row, "label": label}
    return by_label, unmatched


def _conductivity_value(tensor: np.ndarray):
    """A (d, d) tensor in x, y(, z) order as given: a number, the diagonal, or rows."""
    d = len(tensor)
    if np.array_equal(tensor, tensor[0, 0] * np.eye(d)):
        return float(tensor[0, 0])
    if np.array_equal(tensor, np.diag(np.diag(tensor))):
        return [float(v) for v in np.diag(tensor)]
    return [[float(v) for v in row] for row in tensor]


def _text(value, digits: int = 6) -> str:
    """A table cell: numbers to `digits` significant digits, NaN and None empty, lists as
    the command line's comma form (``1,2,3``; a tensor row by row)."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    if isinstance(value, (list, tuple)):
        return ",".join(_text(v, digits) for v in np.ravel(np.asarray(value, dtype=object)))
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    return str(value)


def _plain(value):
    """JSON value: NaN to None, numpy scalars to Python ones."""
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


@dataclass
class SimulationReport:
    """Per-material rows (signature, fraction, conductivity) and the effective conductivity.

    Attributes
    ----------
    materials : list of dict
        One row per material (sorted by label; rows without one last), keys in
        :attr:`columns` order: ``label``, ``name``, ``volume_fraction`` (of the image
        box; NaN when not in the mesh), ``conductivity`` (a number, the diagonal or the
        tensor rows in x, y(, z) order; None when not in the mesh), then the signature
        columns (NaN when the material has no signature).
    columns : list of str
    k_eff : dict of str to float
        Per axis solved (x = column, y = row, z = plane).
    bounds : dict of str to (float, float)
        Reuss and Voigt means per axis.
    tensor : (d, d) ndarray or None
        The periodic protocol's tensor (x, y(, z) order; NaN columns not solved).
    axes : tuple of str
        x, y(, z): the mesh's axes.
    protocol : str
    order : int
    warnings : list of str
        Materials on one side only (signatures or mesh), in words, and an interval left
        wider than its target.
    interval : dict of str to (float, float)
        The certified (lower, upper) bounds of k_eff per axis (mixed protocol).
    """

    materials: list[dict]
    columns: list[str]
    k_eff: dict[str, float]
    bounds: dict[str, tuple[float, float]]
    tensor: np.ndarray | None
    axes: tuple[str, ...]
    protocol: str = "mixed"
    order: int = 1
    warnings: list[str] = field(default_factory=list)
    interval: dict[str, tuple[float, float]] = field(default_factory=dict)

    def summary(self) -> dict:
        """Plain JSON (NaN as null): ``materials``, ``k_eff``, ``bounds``, ``tensor``,
        ``protocol``, ``order``, ``warnings``."""
        out = {"materials": [{k: _plain(r.get(k)) for k in self.columns}
                             for r in self.materials],
               "k_eff": {a: _plain(v) for a, v in self.k_eff.items()},
               "bounds": {a: {"reuss": lo, "voigt": hi} for a, (lo, hi) in self.bounds.items()},
               "protocol": self.protocol, "order": self.order,
               "warnings": list(self.warnings)}
        if self.interval:
            out["interval"] = {a: {"lower": lo, "upper": hi, "gap": (hi - lo) / lo}
                               for a, (lo, hi) in self.interval.items()}
        if self.tensor is not None:
            out["tensor"] = _plain(self.tensor.tolist())
        return out

    def effective_rows(self, digits: int = 6) -> list[list[str]]:
        """The k_eff block: ``quantity, x, y(, z)`` then k_eff, Reuss, Voigt (and the
        tensor rows), as text cells with `digits` significant digits."""
        rows = [["quantity", *self.axes]]
        for name, values in (("k_eff", {a: self.k_eff.get(a) for a in self.axes}),
                             ("reuss", {a: self.bounds[a][0] for a in self.bounds}),
                             ("voigt", {a: self.bounds[a][1] for a in self.bounds})):
            rows.append([name] + [_text(values.get(a), digits) for a in self.axes])
        if self.interval:
            for name, pick in (("lower", lambda lo, hi: lo), ("upper", lambda lo, hi: hi),
                               ("gap", lambda lo, hi: (hi - lo) / lo)):
                rows.append([name] + [_text(pick(*self.interval[a]), digits)
                                      if a in self.interval else "" for a in self.axes])
        if self.tensor is not None:
            rows += [[f"tensor_{a}"] + [_text(float(v), digits) for v in row]
                     for a, row in zip(self.axes, self.tensor)]
        return rows

    def table_rows(self, digits: int = 6) -> list[list[str]]:
        """The material table as text cells (`digits` significant digits), header first."""
        return [list(self.columns)] + [[_text(r.get(k), digits) for k in self.columns]
                                       for r in self.materials]

    def csv_text(self) -> str:
        """The ``.csv`` file: the material table, a blank line, the k_eff block (numbers
        to 15 significant digits)."""
        buf = _io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        writer.writerows(self.table_rows(15))
        buf.write("\n")
        writer.writerows(self.effective_rows(15))
        return buf.getvalue()

    def markdown(self) -> str:
        """The ``.md`` file: both tables as Markdown, then the warnings."""
        def table(rows):
            lines = ["| " + " | ".join(rows[0]) + " |", "|" + "---|" * len(rows[0])]
            return lines + ["| " + " | ".join(r) + " |" for r in rows[1:]]

        lines = [f"# Effective conductivity ({self.protocol} protocol, P{self.order})", "",
                 "## Materials", "", *table(self.table_rows()), "",
                 "## Effective conductivity (x = column, y = row, z = plane)", "",
                 *table(self.effective_rows())]
        if self.warnings:
            lines += ["", "## Warnings", ""] + [f"- {w}" for w in self.warnings]
        return "\n".join(lines) + "\n"

    def describe(self) -> str:
        """The material table as aligned text (what ``simulate --signatures`` prints)."""
        rows = self.table_rows()
        widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
        return "\n".join("  ".join(c.rjust(w) for c, w in zip(r, widths)).rstrip()
                         for r in rows)


def simulation_report(result, conductivity: Mapping,
                      signatures: Sequence[Mapping] | None = None) -> SimulationReport:
    """Join a k_eff run with the per-material signatures of the image.

    Parameters
    ----------
    result : SimulationResult
        What :func:`~napari_swa_imesh.simulate.simulate` returned.
    conductivity : mapping
        The conductivity table the run was given (by label or name, as for ``simulate``).
    signatures : sequence of mapping, optional
        Per-material rows (:func:`read_signatures`, or ``SegmentationResult.signatures``);
        matched by ``label``, else by ``name``.

    Returns
    -------
    SimulationReport
        A material on one side only gets a row with empty cells and a warning (also
        issued as a ``UserWarning``).

    Raises
    ------
    ValueError
        A signature row whose name disagrees with the mesh's name for its label, or a
        label or name given twice (:func:`match_signatures`); a conductivity table that
        does not fit the mesh.

    Examples
    --------
    Brick (k = 1) and grass (k = 3) in series along x: k_eff is their harmonic mean.

    >>> import numpy as np
    >>> from napari_swa_imesh.simulate import simulate
    >>> labels = np.ones((4, 8), dtype=np.uint8); labels[:, 4:] = 2
    >>> result = simulate(labels, {1: 1.0, 2: 3.0}, axes="x")
    >>> rows = [{"label": 1, "name": "brick", "tiles": 3},
    ...         {"label": 2, "name": "grass", "tiles": 5}]
    >>> print(simulation_report(result, {1: 1.0, 2: 3.0}, rows).csv_text())
    label,name,volume_fraction,conductivity,tiles
    1,brick,0.5,1,3
    2,grass,0.5,3,5
    <BLANKLINE>
    quantity,x,y
    k_eff,1.5,
    reuss,1.5,
    voigt,2,
    lower,1.5,
    upper,1.5,
    gap,0,
    <BLANKLINE>
    """
    mesh = result.mesh
    names = {int(k): str(v) for k, v in mesh.material_names.items()}
    materials = sorted(int(m) for m in result.volume_fractions)
    tensors = conductivity_tensors(conductivity, materials, mesh.ndim, names)
    by_label, unmatched = match_signatures(signatures or [], names)
    extra: list[str] = []
    for row in list(by_label.values()) + unmatched:
        extra += [k for k in row if k not in _FIRST and k not in extra]

    notes = []
    rows = []
    for label in sorted(set(materials) | set(by_label)):
        sig = by_label.get(label)
        name = names.get(label) or (str(sig.get("name") or "") if sig else "")
        row = {"label": label, "name": name}
        if label in result.volume_fractions:
            row["volume_fraction"] = float(result.volume_fractions[label])
            row["conductivity"] = _conductivity_value(
                tensors[materials.index(label)][::-1, ::-1])
        else:
            row["volume_fraction"], row["conductivity"] = float("nan"), None
            notes.append(f"material {label}" + (f" ({name})" if name else "") + " has a "
                         "signature but is not in the mesh (excluded, or absent from the "
                         "labels): its row has no volume fraction or conductivity.")
        if sig is None and signatures:
            notes.append(f"material {label}" + (f" ({name})" if name else "") + " is in "
                         "the mesh but has no signature: its signature cells are empty.")
        row.update({k: (sig or {}).get(k, float("nan")) for k in extra})
        rows.append(row)
    for sig in unmatched:
        notes.append(f"the signature of {sig['name']!r} matches no material of the mesh "
                     "(no label, and no mesh material of that name): listed without one.")
        rows.append({"label": None, "name": sig["name"], "volume_fraction": float("nan"),
                     "conductivity": None, **{k: sig.get(k, float("nan")) for k in extra}})
    for note in notes:
        warnings.warn(note, UserWarning, stacklevel=2)
    notes = notes + list(getattr(result, "warnings", []))
    axes = ("x", "y", "z")[:mesh.ndim]
    tensor = None if result.tensor is None else np.asarray(result.tensor, dtype=np.float64)
    return SimulationReport(materials=rows, columns=[*_FIRST, *extra],
                            k_eff=dict(result.k_eff), bounds=dict(result.bounds),
                            tensor=tensor, axes=axes, protocol=result.protocol,
                            order=result.order, warnings=notes,
                            interval=dict(getattr(result, "interval", {})))


def check_report_path(path, *, force: bool = False) -> Path:
    """A report file name, checked before any work: suffix and writability."""
    p = Path(path)
    if p.suffix.lower() not in REPORT_SUFFIXES:
        raise ValueError(f"cannot write a report to {p.name!r}: use "
                         f"{', '.join(REPORT_SUFFIXES)} (a table, JSON or Markdown).")
    return check_writable(p, force=force)


def write_report(report: SimulationReport, path, *, force: bool = False) -> Path:
    """Write `report` as ``.csv``, ``.json`` or ``.md`` (by the suffix of `path`).

    Parameters
    ----------
    report : SimulationReport
    path : str or Path
    force : bool
        Replace an existing file.

    Returns
    -------
    Path
    """
    p = check_report_path(path, force=force)
    suffix = p.suffix.lower()
    text = (report.csv_text() if suffix == ".csv" else report.markdown() if suffix == ".md"
            else json.dumps(report.summary(), indent=1) + "\n")
    with atomic_write([p], force=force) as (tmp,):
        tmp.write_text(text, encoding="utf-8")
    return p
