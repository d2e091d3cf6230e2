"""The predict pictures: which detections they draw (modalities/pictures.py) and that the figures
(data/*/figure.py, matplotlib) draw axes in the modality's units, a legend and the detections."""

from __future__ import annotations

from argparse import Namespace

import numpy as np
import pytest
from PIL import Image

from dsfec_jax.boxes.boxes2d import Boxes2D
from dsfec_jax.data.camera.images import CameraImage
from dsfec_jax.modalities.image import cli as cli_image
from dsfec_jax.modalities.pictures import drawn, picture_names


def test_the_default_draws_the_best_when_none_reaches_it():
    """The shipped Shuffle-YOLOv3 scores at most 0.22 on the VOC photos: at the old default (>= 0.25
    and nothing else) their pictures showed ground truth only."""
    low = np.array([0.05, 0.22, 0.2, 0.01, 0.21], np.float32)
    keep, note = drawn(low, None)
    assert np.flatnonzero(keep).tolist() == [1, 2, 4] and note == "none >= 0.25: the 3 best shown"
    keep, note = drawn(np.array([0.3, 0.1], np.float32), None)
    assert keep.tolist() == [True, False] and note == "1 detection >= 0.25"
    keep, note = drawn(low, 0.25)  # an explicit --png-min-score is kept to the letter
    assert not keep.any() and note == "0 detections >= 0.25"
    assert drawn(np.zeros(0, np.float32), None)[0].shape == (0,)


def test_camera_pictures_show_the_detections_by_default(tmp_path, monkeypatch):
    from dsfec_jax.data.camera import figure

    item = CameraImage("photos/a.jpg", np.full((60, 80, 3), 128, np.uint8),
                       Boxes2D(np.array([[10, 10, 40, 50]], np.float32), np.array(["person"])))
    found = Boxes2D(np.array([[12, 8, 42, 52], [50, 5, 70, 30]], np.float32), np.array(["person", "car"]),
                    np.array([0.2, 0.1], np.float32))
    calls = []
    monkeypatch.setattr(figure, "save_camera_figure", lambda item, path, predicted, classes, title:
                        calls.append((path.name, predicted, title)))
    predictor = Namespace(classes=("person", "car"))
    cli_image.write_pngs(Namespace(png_dir=str(tmp_path), png_min_score=None, model="m"), [item],
                         {item.image_id: found}, predictor)
    (name, predicted, title), = calls
    assert name == "a.jpg.png" and predicted.scores.tolist() == pytest.approx([0.2, 0.1])
    assert title == "photos/a.jpg: m, none >= 0.25: the 2 best shown"


def test_figures_draw_detections_over_the_input(tmp_path):
    """Each figure differs where a detection is drawn, and is a plotted PNG (axes, legend, colorbar:
    looked at by eye, docs/points-train-evaluate-predict.md)."""
    from dsfec_jax.data.camera.figure import render_camera_figure

    item = CameraImage("a", np.full((60, 80, 3), 128, np.uint8), Boxes2D.empty())
    found = Boxes2D(np.array([[10, 10, 40, 50]], np.float32), np.array(["car"]), np.array([0.9], np.float32))
    (tmp_path / "none.png").write_bytes(render_camera_figure(item, None, ("car",)))
    (tmp_path / "one.png").write_bytes(render_camera_figure(item, found, ("car",)))
    none, one = (np.asarray(Image.open(tmp_path / f"{n}.png").convert("RGB")) for n in ("none", "one"))
    assert none.shape == one.shape == (int(60 * 7.5 + 90), 700, 3)
    changed = np.argwhere((none != one).any(-1))
    assert len(changed) > 100  # the dashed box, its label and the legend


def test_picture_names_keep_the_file_name_and_tell_clashes_apart():
    assert picture_names(["/x/a.bin", "/y/a.bin", "/y/b.bin", "token"]) == {
        "/x/a.bin": "x_a.bin.png", "/y/a.bin": "y_a.bin.png", "/y/b.bin": "b.bin.png", "token": "token.png"}
