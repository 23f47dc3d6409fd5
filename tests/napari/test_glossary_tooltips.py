"""Every glossary term a widget shows is defined in its tooltip, from the one glossary the
command line prints (issue 23: SWA, IMESH, RES, eps_l, eps_m, radius-to-edge ratio, k_eff,
P1/P2, Doerfler, protocol names)."""

import pytest
from qtpy.QtCore import QEvent, Qt
from qtpy.QtGui import QHelpEvent
from qtpy.QtWidgets import QAbstractButton, QApplication, QComboBox, QGroupBox, QLabel, QTabWidget

from napari_swa_imesh._glossary import define, terms_in
from napari_swa_imesh._napari._classify_widget import ClassifyWidget
from napari_swa_imesh._napari._mesh_widget import MeshWidget
from napari_swa_imesh._napari._res_widget import ResWidget
from napari_swa_imesh._napari._samples_widget import SamplesWidget
from napari_swa_imesh._napari._simulate_widget import SimulateWidget
from napari_swa_imesh._napari._workflow import WorkflowWidget

# each widget with terms it must show (so the test cannot pass on a widget showing none)
WIDGETS = {WorkflowWidget: {"RES", "k_eff", "P1", "P2", "mixed", "periodic",
                            "radius-to-edge ratio"},
           SamplesWidget: set(), ResWidget: {"RES"}, ClassifyWidget: {"RES", "GM", "Dice"},
           MeshWidget: {"radius-to-edge ratio"},
           SimulateWidget: {"k_eff", "P1", "P2", "mixed", "periodic"}}


def shown_texts(root):
    """(text, tooltip) of every label, button, group title, combo item and tab."""
    out = []
    for w in [root, *root.findChildren(QLabel), *root.findChildren(QAbstractButton),
              *root.findChildren(QGroupBox)]:
        text = w.title() if isinstance(w, QGroupBox) else getattr(w, "text", lambda: "")()
        out.append((text, w.toolTip()))
    for combo in root.findChildren(QComboBox):
        for i in range(combo.count()):
            out.append((combo.itemText(i), str(combo.itemData(i, Qt.ToolTipRole) or "")))
    for tabs in root.findChildren(QTabWidget):
        for i in range(tabs.count()):
            out.append((tabs.tabText(i), tabs.tabToolTip(i)))
    return out


@pytest.mark.parametrize("widget_class", list(WIDGETS), ids=lambda c: c.__name__)
def test_every_term_shown_has_its_definition_as_tooltip(make_napari_viewer, widget_class):
    widget = widget_class(make_napari_viewer())
    seen = set()
    for text, tooltip in shown_texts(widget):
        for term in terms_in(text):
            seen.add(term)
            assert f"{term}: {define(term)}" in tooltip, (text, tooltip)
    assert WIDGETS[widget_class] <= seen


def test_a_result_line_explains_terms_that_appear_after_a_run(make_napari_viewer):
    """A result label's text changes after a run; its tooltip follows when it shows."""
    widget = SimulateWidget(make_napari_viewer())
    label = widget.summary.native
    label.setText("k_eff along x = 3.1 (P2, Doerfler marking)")
    QApplication.sendEvent(label, QHelpEvent(QEvent.ToolTip, label.rect().center(),
                                             label.mapToGlobal(label.rect().center())))
    for term in ("k_eff", "P2", "Doerfler"):
        assert define(term) in label.toolTip()
