"""Resolve the short cross-references the docstrings use, so ``-n`` checks the rest.

The docstrings name their neighbours as a reader of the source sees them:
``:func:`read_affine``` inside :mod:`napari_swa_imesh.io`, ``:func:`_adapt.refine_within```
inside :mod:`napari_swa_imesh.simulate`. Sphinx looks a reference up by its exact dotted
name only, so on the pages of a package's face (where the object is documented under the
package, not its private module) such names are reported missing. This extension, on a
missing Python reference:

* links it when exactly one documented object's full name ends with the reference's
  public part (``refine_within`` of ``_adapt.refine_within``, ``read_affine``);
* leaves it as plain code when it names an object that exists in the library but is not
  on the site (a private module's function, a module constant): looked up from the
  module (and class) the reference stands in, so the name is checked all the same;
* otherwise returns nothing, and Sphinx warns as usual (a build error under ``-W``): a
  misspelt or stale name.
"""

from __future__ import annotations

import importlib
import inspect
import sys

from sphinx.addnodes import pending_xref
from sphinx.application import Sphinx


def _public_tail(target: str) -> str:
    parts = target.split(".")
    while parts and parts[0].startswith("_"):
        parts.pop(0)
    return ".".join(parts)


def _missing(app: Sphinx, env, node: pending_xref, contnode):
    if node.get("refdomain") != "py":
        return None
    target = node.get("reftarget", "")
    domain = env.get_domain("py")
    tail = _public_tail(target.lstrip(".~"))
    if tail:
        hits = [name for name in domain.objects if name == tail or name.endswith("." + tail)]
        # one object documented twice (a package's face and its private module) is one hit
        public = sorted({h for h in hits if not any(p.startswith("_") for p in h.split("."))})
        if len(public) == 1:
            name = public[0]
            found = domain.resolve_xref(env, node["refdoc"], app.builder, "obj", name, node,
                                        contnode)
            if found is not None:
                return found
    if _exists(node.get("py:module"), node.get("py:class"), target.lstrip(".~")):
        return contnode
    return None


def _lookup(scope, dotted: str):
    obj = scope
    for part in dotted.split("."):
        nxt = getattr(obj, part, None)
        if nxt is None and inspect.ismodule(obj):
            try:                      # a submodule its package does not import
                nxt = importlib.import_module(f"{obj.__name__}.{part}")
            except ImportError:
                nxt = None
        if nxt is None and inspect.isclass(obj):
            # a field or an attribute the methods set (``self.classes_ = ...``)
            fields = {**getattr(obj, "__dataclass_fields__", {}),
                      **getattr(obj, "__annotations__", {})}
            try:
                source = inspect.getsource(obj)
            except (OSError, TypeError):
                source = ""
            if part in fields or f"self.{part} =" in source:
                return part
        if nxt is None:
            return None
        obj = nxt
    return obj


def _exists(module: str | None, cls: str | None, target: str) -> bool:
    """Whether `target` names something in the library: seen from the class and module
    the reference stands in, from their package's modules, or as a full dotted name."""
    if not target:
        return False
    root = (module or target).split(".")[0]
    scopes = []
    if module:
        try:
            scopes.append(importlib.import_module(module))
        except ImportError:
            return False
        if cls:
            owner = _lookup(scopes[0], cls)
            if owner is not None:
                scopes.insert(0, owner)
    try:
        scopes.append(importlib.import_module(root))
    except ImportError:
        return False
    dotted = target[len(root) + 1:] if target.startswith(root + ".") else target
    if any(_lookup(scope, dotted) is not None for scope in scopes):
        return True
    # a name of a sibling module (``_lattice.choose_lattice``), wherever in the package
    # that module lives: the docstrings name modules as their neighbours see them
    first, _, rest = dotted.partition(".")
    for name, loaded in sorted(sys.modules.items()):
        if loaded is None or not name.startswith(root + "."):
            continue
        if _lookup(loaded, dotted) is not None:
            return True
        if rest and name.endswith("." + first) and _lookup(loaded, rest) is not None:
            return True
    return False


def setup(app: Sphinx) -> dict:
    app.connect("missing-reference", _missing)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
