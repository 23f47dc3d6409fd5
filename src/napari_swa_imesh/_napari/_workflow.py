"""The main widget (Layers > Segment): Samples | RES | Classify | Mesh | Simulate tabs kept in
step."""

from __future__ import annotations

from typing import TYPE_CHECKING

from qtpy.QtWidgets import QTabWidget, QVBoxLayout, QWidget

from ._classify_widget import METHOD_REFERENCE, ClassifyWidget
from ._help import explain_terms
from ._mesh_widget import MeshWidget
from ._res_widget import ResWidget
from ._samples_widget import SamplesWidget
from ._simulate_widget import SimulateWidget

if TYPE_CHECKING:
    import napari

__all__ = ["WorkflowWidget"]


class WorkflowWidget(QWidget):
    """The pipeline in five tabs: samples, RES, classification, mesh, simulation.

    The tabs are the plugin's five widgets; this one only passes choices along: the
    samples layer to the RES and classify tabs, the chosen scale to the samples checks and
    the classifier, the classify tab's scale to the samples checks, the classification to
    the mesher, the mesh to the simulation.
    """

    def __init__(self, napari_viewer: napari.viewer.Viewer, parent: QWidget | None = None):
        super().__init__(parent)
        self.viewer = napari_viewer
        self.samples = SamplesWidget(napari_viewer)
        self.res = ResWidget(napari_viewer)
        self.classify = ClassifyWidget(napari_viewer)
        self.mesh = MeshWidget(napari_viewer)
        self.simulate = SimulateWidget(napari_viewer)
        self.tabs = QTabWidget()
        for widget, title in ((self.samples, "Samples"), (self.res, "RES"),
                              (self.classify, "Classify"), (self.mesh, "Mesh"),
                              (self.simulate, "Simulate")):
            self.tabs.addTab(widget, title)   # each tab scrolls its own content
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(self.tabs)

        self.samples.samples_layer_changed.connect(self._on_samples_layer)
        self.res.scale_chosen.connect(self.classify.set_scale)
        self.res.scale_chosen.connect(self.samples.set_scale)
        self.classify.scale_combo.changed.connect(self._on_classify_scale)
        self.classify.method_combo.changed.connect(self._on_classify_method)
        self.classify.labels_ready.connect(self.mesh.select_labels)
        self.mesh.mesh_ready.connect(self.simulate.select_mesh)
        self._on_samples_layer(self.samples.samples_layer())
        explain_terms(self)    # the tab titles (RES) too

    def _on_classify_method(self, value: str) -> None:
        # the RES tab suggests a scale the chosen method can train at (its next compute)
        self.res.method = "reference" if value == METHOD_REFERENCE else "recommended"

    def _on_classify_scale(self, scale: int | None) -> None:
        # the samples tab flags boxes at the scale the next run will use
        if scale is not None:
            self.samples.set_scale(scale)

    def _on_samples_layer(self, layer) -> None:
        if layer is None:
            return
        image = self.samples.image_layer()
        self.res.select_layers(image=image, samples=layer)
        self.classify.select_layers(image=image, samples=layer)
