"""The Zarr reader: stores open lazily as Dask layers, OME-Zarr levels as multiscale."""

from __future__ import annotations

from pathlib import Path

import dask.array as da
import numpy as np
import zarr

from napari_swa_imesh._napari._zarr_reader import LAZY_KEY, get_zarr_reader

ROOT = Path(__file__).resolve().parents[2]


def _ome(path: Path, data: np.ndarray) -> None:
    root = zarr.open_group(str(path), mode="w", zarr_format=2)
    root.create_array("0", data=data, chunks=(8, 16, 16))
    root.create_array("1", data=data[::2, ::2, ::2].copy(), chunks=(8, 16, 16))
    root.attrs["multiscales"] = [{"version": "0.4", "axes": [
        {"name": a, "type": "space"} for a in "zyx"], "datasets": [
        {"path": "0", "coordinateTransformations": [{"type": "scale",
                                                     "scale": [2.0, 0.5, 0.5]}]},
        {"path": "1", "coordinateTransformations": [{"type": "scale",
                                                     "scale": [4.0, 1.0, 1.0]}]}]}]


def test_ome_zarr_opens_as_a_lazy_multiscale_image(make_napari_viewer, tmp_path):
    data = np.random.default_rng(0).random((16, 32, 48)).astype(np.float32)
    _ome(tmp_path / "scan.ome.zarr", data)
    reader = get_zarr_reader(str(tmp_path / "scan.ome.zarr") + "/")
    ((layer_data, kwargs, kind),) = reader(tmp_path / "scan.ome.zarr")
    assert kind == "image" and kwargs["multiscale"] and kwargs["name"] == "scan"
    assert all(isinstance(level, da.Array) for level in layer_data)
    viewer = make_napari_viewer()
    layer = viewer.add_image(layer_data, **kwargs)
    assert layer.multiscale and tuple(layer.scale) == (2.0, 0.5, 0.5)
    assert isinstance(layer.data[0], da.Array)
    np.testing.assert_array_equal(np.asarray(layer.data[1]), data[::2, ::2, ::2])
    assert layer.metadata[LAZY_KEY] == str(tmp_path / "scan.ome.zarr")


def test_a_volume_larger_than_memory_opens_without_loading(make_napari_viewer, tmp_path):
    # 2048 x 4096 x 4096 float32 is 137 GB; no chunk is written, and napari reads only the
    # chunks of the planes it draws or samples
    z = zarr.create_array(str(tmp_path / "huge.zarr"), shape=(2048, 4096, 4096),
                          chunks=(1, 1024, 1024), dtype="f4", fill_value=0.0)
    z[1024, :64, :64] = 1.0
    ((layer_data, kwargs, kind),) = get_zarr_reader(tmp_path / "huge.zarr")(
        tmp_path / "huge.zarr")
    assert isinstance(layer_data, da.Array) and layer_data.nbytes > 1.3e11
    viewer = make_napari_viewer()
    layer = viewer.add_image(layer_data, **kwargs)
    viewer.dims.set_point(0, 1024)
    assert np.asarray(layer._slice.image.view).max() == 1.0


def test_integer_store_named_as_labels_opens_as_labels(tmp_path):
    z = zarr.create_array(str(tmp_path / "scan_labels.zarr"), shape=(8, 16, 16),
                          chunks=(4, 8, 8), dtype="u1", attributes={"spacing": [2, 1, 1]})
    z[:] = np.random.default_rng(1).integers(1, 4, (8, 16, 16))
    ((layer_data, kwargs, kind),) = get_zarr_reader(tmp_path / "scan_labels.zarr")(
        tmp_path / "scan_labels.zarr")
    assert kind == "labels" and kwargs["scale"] == (2.0, 1.0, 1.0)
    assert not kwargs["multiscale"] and isinstance(layer_data, da.Array)
    assert get_zarr_reader(tmp_path / "x.tif") is None


def test_manifest_names_the_zarr_reader_for_folders():
    from npe2 import PluginManifest

    manifest = PluginManifest.from_file(ROOT / "src/napari_swa_imesh/napari.yaml")
    manifest.validate_imports()
    (reader,) = [r for r in manifest.contributions.readers
                 if r.command.endswith("get_zarr_reader")]
    assert reader.accepts_directories and reader.filename_patterns == ["*.zarr"]


def _model_and_image(tmp_path):
    from napari_swa_imesh.segmentation import RecommendedModel, Samples

    rng = np.random.default_rng(3)
    train = np.concatenate([rng.normal(0, 1, (48, 48)), rng.normal(4, 1, (48, 48))], 1)
    model = RecommendedModel(max_scale=1, bias_correction=False).fit(train, Samples.from_dict(
        {"boxes": [{"label": 1, "start": [0, 0], "stop": [48, 48]},
                   {"label": 2, "start": [0, 48], "stop": [48, 96]}]}))
    model.save(tmp_path / "m.npz")
    image = np.where(np.add.outer(np.arange(120), np.arange(100)) % 50 < 25,
                     rng.normal(0, 1, (120, 100)), rng.normal(4, 1, (120, 100)))
    z = zarr.create_array(str(tmp_path / "img.zarr"), shape=image.shape, chunks=(32, 32),
                          dtype="f4")
    z[:] = image
    return model, np.asarray(z[:])


def test_chunked_steps_report_every_chunk(tmp_path):
    from napari_swa_imesh._napari._chunked_classify import chunked_steps

    model, image = _model_and_image(tmp_path)
    gen = chunked_steps(da.from_zarr(str(tmp_path / "img.zarr")), model, chunks=(40, 50))
    reports = []
    while True:
        try:
            reports.append(next(gen))
        except StopIteration as stop:
            labels, plan = stop.value
            break
    assert reports[0][:2] == (0, 6) and reports[-1][:2] == (6, 6)
    assert isinstance(labels, da.Array) and plan["chunks"] == (40, 50)
    np.testing.assert_array_equal(labels.compute(), model.predict(image))


def test_classify_widget_applies_a_model_to_a_lazy_layer(make_napari_viewer, qtbot,
                                                         tmp_path):
    from swa_napari_helpers import wait_idle

    from napari_swa_imesh._napari._chunked_classify import CHUNKED_KEY
    from napari_swa_imesh._napari._classify_widget import ClassifyWidget

    model, image = _model_and_image(tmp_path)
    viewer = make_napari_viewer()
    ((data, kwargs, _),) = get_zarr_reader(tmp_path / "img.zarr")(tmp_path / "img.zarr")
    layer = viewer.add_image(data, **kwargs)
    widget = ClassifyWidget(viewer)
    widget.load_model(tmp_path / "m.npz")
    widget.image_combo.value = layer
    widget.apply_model()
    wait_idle(qtbot, widget)
    labels = viewer.layers["img SWA labels"]
    assert isinstance(labels.data, da.Array) and CHUNKED_KEY in labels.metadata
    np.testing.assert_array_equal(np.asarray(labels.data), model.predict(image))
