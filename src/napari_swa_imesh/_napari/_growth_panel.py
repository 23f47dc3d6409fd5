"""The Simulate tab's reaction-diffusion section: tumour growth (Fisher-KPP) or drug
delivery on the tab's mesh, D per material from the tab's material table, a time slider
over the result shown on the mesh's boundary and interface faces.

Thin: the run is :func:`napari_swa_imesh.simulate.growth_steps` in the tab's task panel
(progress per accepted step, Cancel between steps); the field is a Surface layer whose
vertex values the slider swaps.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from magicgui.widgets import ComboBox, FloatSpinBox, LineEdit, PushButton, Slider, SpinBox

from ..mesh import shown_faces
from ..simulate import growth_steps, growth_table
from ._dock import Fold, wrapped_label
from ._layers import MESH_KEY
from ._tasks import notify_error

if TYPE_CHECKING:
    from ..simulate import GrowthResult

__all__ = ["GROWTH_KEY", "GrowthPanel", "MODELS"]

GROWTH_KEY = "swa_imesh_growth"
#: shown text -> the library's model
MODELS = {"fisher-kpp: tumour growth": "fisher-kpp",
          "drug: delivery with decay": "drug"}
COLORMAP = "magma"


class GrowthPanel:
    """Controls, run and display of a reaction-diffusion run on the tab's mesh.

    Parameters
    ----------
    host : SimulateWidget
        The tab: its mesh picker, material table, task panel and viewer.
    """

    def __init__(self, host):
        self.host = host
        self.result: GrowthResult | None = None
        self.layer = None
        self._faces: np.ndarray | None = None
        self.model_combo = ComboBox(label="model", choices=list(MODELS))
        self.rate = FloatSpinBox(label="rate rho", value=1.0, min=0.0, max=1e6, step=0.1,
                                 tooltip="Fisher-KPP proliferation rate (per unit time).")
        self.decay = FloatSpinBox(label="decay lambda", value=1.0, min=0.0, max=1e6,
                                  step=0.1, visible=False,
                                  tooltip="Drug uptake/decay rate (per unit time).")
        self.seed = LineEdit(label="seed x,y[,z]:r", value="",
                             tooltip="Ball where c = 1 at t = 0, in the mesh file's "
                                     "coordinates (x = column); empty: the box centre, "
                                     "radius a tenth of the box.")
        self.fixed = LineEdit(label="fixed", value="xmin=1", visible=False,
                              tooltip="Drug: fixed values on box faces or materials, "
                                      "comma separated: xmin=1, 4=0.5.")
        self.kill = LineEdit(label="kill windows", value="",
                             tooltip="start:end:rate, comma separated: kill rates over "
                                     "time windows (chemotherapy cycles).")
        self.duration = FloatSpinBox(label="duration", value=10.0, min=1e-9, max=1e9)
        self.saves = SpinBox(label="saved times", value=20, min=1, max=1000)
        self.run_button = PushButton(text="Run reaction-diffusion")
        self.summary = wrapped_label()
        self.time_slider = Slider(label="time", value=0, min=0, max=0, enabled=False)
        self.time_note = wrapped_label()
        self.fold = Fold("reaction-diffusion (tumour growth, drug)",
                         [self.model_combo, self.rate, self.decay, self.seed, self.fixed,
                          self.kill, self.duration, self.saves, self.run_button,
                          self.summary, self.time_slider, self.time_note])
        self.model_combo.changed.connect(self._on_model_changed)
        self.run_button.changed.connect(self.run)
        self.time_slider.changed.connect(self.show_time)

    @property
    def model(self) -> str:
        return MODELS[self.model_combo.value]

    def _on_model_changed(self, *_) -> None:
        fisher = self.model == "fisher-kpp"
        self.rate.visible, self.decay.visible, self.fixed.visible = fisher, not fisher, \
            not fisher
        self.host.table.setHorizontalHeaderLabels(["material", "name", "k or diffusivity D"])

    def _options(self, mesh) -> dict:
        """The keyword arguments of growth_steps from the controls (ValueError if bad)."""
        diffusivity = {}
        for label, value in self.host.table.conductivity().items():
            if not np.isscalar(value):
                raise ValueError(f"the diffusivity of material {label} must be one number, "
                                 f"not {value!r}.")
            diffusivity[label] = float(value)
        options = {"diffusivity": diffusivity, "model": self.model,
                   "duration": float(self.duration.value),
                   "saves": int(self.saves.value), "kill": _kill(self.kill.value)}
        seed = self.seed.value.strip()
        if seed:
            centre, sep, radius = seed.partition(":")
            try:
                options["seed"] = (tuple(float(v) for v in centre.split(",")), float(radius))
            except ValueError:
                raise ValueError(f"seed {seed!r} is not x,y[,z]:r.") from None
        elif self.model == "fisher-kpp":
            lo, hi = mesh.image_box()
            world = np.r_[(lo + hi) / 2, 1.0]
            centre = (world[:-1][::-1] if mesh.world is None
                      else (mesh.world @ world)[:mesh.ndim])
            options["seed"] = (tuple(centre), float(np.max(hi - lo)) / 10)
        if self.model == "fisher-kpp":
            options["rate"] = float(self.rate.value)
        else:
            options["decay"] = float(self.decay.value)
            fixed = {}
            for item in filter(None, (t.strip() for t in self.fixed.value.split(","))):
                key, sep, text = item.partition("=")
                try:
                    fixed[key.strip()] = float(text)
                except ValueError:
                    raise ValueError(f"fixed {item!r} is not FACE=VALUE or "
                                     "MATERIAL=VALUE.") from None
            options["fixed"] = fixed
        return options

    def run(self, *_):
        """Run the model on the tab's mesh in the task panel's worker."""
        layer = self.host.mesh_combo.value
        if layer is None:
            notify_error("no mesh to simulate on: mesh a Labels layer first (mesh widget).")
            return None
        mesh = layer.metadata[MESH_KEY]
        try:
            options = self._options(mesh)
        except ValueError as exc:
            notify_error(f"{exc} Edit it in the tab.")
            return None

        diffusivity = options.pop("diffusivity")
        source = mesh
        picked = self.host.labels_combo.value
        if picked is not None and tuple(picked.data.shape) == tuple(mesh.shape):
            # the labels: materials of D = 0 left out, the front's elements refined
            source = np.asarray(picked.data)
            options["spacing"] = mesh.spacing or None
            options["material_names"] = dict(mesh.material_names)
            options["exclude"] = () if mesh.recipe is None else mesh.recipe.exclude

        def steps():
            result = yield from growth_steps(source, diffusivity, **options)
            return result, shown_faces(result.mesh.cells, result.mesh.material)[0]

        worker = self.host.tasks.run(steps, title="Reaction-diffusion",
                                     on_result=lambda out: self._show_result(layer, *out))
        if worker is not None:          # a run that fails must not leave the last one shown
            self.summary.value = ""
            self.time_slider.enabled = False
        return worker

    def _show_result(self, mesh_layer, result: GrowthResult, faces: np.ndarray) -> None:
        self.result, self._faces = result, faces
        self.summary.value = result.describe().splitlines()[0]
        self.time_slider.max = len(result.times) - 1
        self.time_slider.enabled = True
        if self.layer is not None and self.layer in self.host.viewer.layers:
            self.host.viewer.layers.remove(self.layer)
        top = 1.0 if result.model == "fisher-kpp" else max(float(result.values.max()), 1e-12)
        self.layer = self.host.viewer.add_surface(
            (result.mesh.points, faces, result.values[-1]), name="c", colormap=COLORMAP,
            contrast_limits=(0.0, top), translate=mesh_layer.translate,
            affine=mesh_layer.affine.affine_matrix, shading="none",
            metadata={GROWTH_KEY: result.model})
        self._table = growth_table(result)
        with self.time_slider.changed.blocked():
            self.time_slider.value = len(result.times) - 1
        self.show_time()

    def show_time(self, *_) -> None:
        """Show the saved time the slider points at."""
        if self.result is None or self.layer is None:
            return
        k = int(self.time_slider.value)
        self.layer.data = (self.result.mesh.points, self._faces, self.result.values[k])
        self.time_note.value = (f"t = {self.result.times[k]:g}: volume with c > 0.5 "
                                f"{self._table['volume'][k]:.4g}, amount "
                                f"{self.result.amount[k]:.4g}")


def _kill(text: str) -> list[tuple[float, float, float]]:
    out = []
    for item in filter(None, (t.strip() for t in text.split(","))):
        try:
            a, b, r = (float(v) for v in item.split(":"))
        except ValueError:
            raise ValueError(f"kill window {item!r} is not start:end:rate.") from None
        out.append((a, b, r))
    return out
