"""The camera predictor (predict_camera.py): raw YOLOv3 outputs that encode a known box, fed through
the real decode, NMS and letterbox inverse, come back as that box in the original image's pixels,
for a 16:9 street frame (416 x 256 input) and a portrait VOC-sized image (320 x 416); the class map
renames and drops classes. The network is replaced by the synthetic outputs: nothing is compiled
but the decode."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest

from dsfec_jax import zoo
from dsfec_jax.boxes.boxes2d import Boxes2D
from dsfec_jax.data.camera.images import CameraImage
from dsfec_jax.models.camera.anchors import YOLOV3_ANCHORS
from dsfec_jax.models.camera.decode import decode
from dsfec_jax.modalities.image.predict import CameraPredictor

STREET = ("car", "truck", "bus", "pedestrian", "cyclist")


def logit(p: float) -> float:
    return math.log(p / (1 - p))


def encoded_outputs(box, input_hw, scale: int, anchor: int, label: int, classes: int):
    """Raw outputs (one image) where only `anchor` of output `scale` fires, encoding `box` (input
    pixels) and class `label`; every other candidate scores ~1e-9."""
    outs = []
    for s, stride in enumerate(YOLOV3_ANCHORS.strides):
        raw = np.full((1, input_hw[0] // stride, input_hw[1] // stride, 3, 5 + classes), -20.0, np.float32)
        if s == scale:
            cx, cy = (box[0] + box[2]) / 2 / stride, (box[1] + box[3]) / 2 / stride
            aw, ah = YOLOV3_ANCHORS.for_scale(s)[anchor]
            raw[0, int(cy), int(cx), anchor, :5] = [logit(cx % 1), logit(cy % 1), math.log((box[2] - box[0]) / aw),
                                                    math.log((box[3] - box[1]) / ah), 20.0]
            raw[0, int(cy), int(cx), anchor, 5 + label] = 20.0
        outs.append(jnp.asarray(raw))
    return tuple(outs)


def predictor_with_outputs(image_box, image_hw, input_hw, class_map=None):
    det = zoo.create("shuffle_yolov3", num_classes=5, class_names=STREET)
    predictor = CameraPredictor(det, variables=None, class_map=class_map)
    assert predictor.input_hw(image_hw) == input_hw
    scale = min(input_hw[1] / image_hw[1], input_hw[0] / image_hw[0])
    offset = ((input_hw[1] - image_hw[1] * scale) / 2, (input_hw[0] - image_hw[0] * scale) / 2)
    in_input = [image_box[0] * scale + offset[0], image_box[1] * scale + offset[1],
                image_box[2] * scale + offset[0], image_box[3] * scale + offset[1]]
    seen = []

    def network(variables, image):
        seen.append(image.shape)
        return decode(encoded_outputs(in_input, input_hw, scale=1, anchor=1, label=3, classes=5))

    predictor.network = network
    return predictor, seen


@pytest.mark.parametrize("image_hw,input_hw,box", [((234, 416), (256, 416), (100.0, 52.0, 180.0, 120.0)),
                                                   ((500, 375), (416, 320), (40.0, 300.5, 130.0, 410.0))])
def test_a_decoded_box_comes_back_in_image_pixels(image_hw, input_hw, box):
    predictor, seen = predictor_with_outputs(box, image_hw, input_hw)
    image = CameraImage("im", np.zeros((*image_hw, 3), np.uint8), Boxes2D.empty())
    found = predictor.predict_samples([image])["im"]
    assert seen == [(1, *input_hw, 3)]  # letterboxed into the rectangle, one batch
    assert len(found) == 1 and found.names[0] == "pedestrian" and found.scores[0] > 0.99
    np.testing.assert_allclose(found.xyxy[0], box, atol=1e-3)
    direct = predictor(np.zeros((*image_hw, 3), np.uint8))  # a bare array works too
    np.testing.assert_allclose(direct.xyxy, found.xyxy)


def test_the_class_map_renames_and_drops():
    box, hw = (100.0, 52.0, 180.0, 120.0), (234, 416)
    image = CameraImage("im", np.zeros((*hw, 3), np.uint8), Boxes2D.empty())
    to_voc = {"car": "car", "bus": "bus", "pedestrian": "person", "cyclist": "bicycle"}
    predictor, _ = predictor_with_outputs(box, hw, (256, 416), class_map=to_voc)
    assert predictor.classes == ("car", "bus", "person", "bicycle")
    found = predictor.predict_samples([image])["im"]
    assert list(found.names) == ["person"]
    predictor, _ = predictor_with_outputs(box, hw, (256, 416), class_map={"car": "car"})
    assert len(predictor.predict_samples([image])["im"]) == 0  # pedestrians are not reported
    with pytest.raises(ValueError, match="dog"):
        CameraPredictor(zoo.create("shuffle_yolov3", num_classes=5, class_names=STREET), None, class_map={"dog": "dog"})


def test_a_png_draws_boxes_flat_on_the_image_edge(tmp_path):
    """Predictions clipped to the image can be flat on its far edge (y1 = y2 = H): still drawn."""
    from PIL import Image

    from dsfec_jax.data.camera.preview import PREDICTION, save_camera_png

    item = CameraImage("im", np.zeros((30, 40, 3), np.uint8), Boxes2D.empty())
    flat = Boxes2D(np.array([[0.0, 30.0, 40.0, 30.0], [5.0, 5.0, 15.0, 10.0]], np.float32), np.array(["car", "car"]),
                   np.ones(2, np.float32))
    image = np.asarray(Image.open(save_camera_png(item, tmp_path / "im.png", flat)))
    assert (image[29] == PREDICTION).all() and (image[5, 5:15] == PREDICTION).all()


def test_each_new_input_shape_says_it_compiles(capsys):
    """Photos of other aspect ratios letterbox to other shapes and compile again (tens of seconds
    on a busy machine): with progress on, each new shape after the first gets its own line."""
    box, hw = (100.0, 52.0, 180.0, 120.0), (234, 416)
    predictor, seen = predictor_with_outputs(box, hw, (256, 416))
    street = [CameraImage(f"s{i}", np.zeros((*hw, 3), np.uint8), Boxes2D.empty()) for i in range(2)]
    portrait = CameraImage("p", np.zeros((500, 375, 3), np.uint8), Boxes2D.empty())
    predictor.predict_samples(street + [portrait] + street, batch_size=2, progress=True)
    said = capsys.readouterr().err
    assert len(set(seen)) == 3  # (2, 256, 416), (1, 416, 320), (1, 256, 416)
    assert said.count("(a JAX predictor compiles for it): done in") == 2, said
    assert "running a new input shape, 1 x 416 x 320" in said
    predictor.predict_samples(street, batch_size=2)
    assert "running a new input shape" not in capsys.readouterr().err  # quiet without progress
