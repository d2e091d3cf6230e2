"""The PASCAL VOC reader (data/camera/voc.py): the 100 real VOC2012 annotations and images of
rafaelpadilla/review_object_detection_metrics (read by path, never copied), the inclusive -> edge
conversion into Boxes2D (with its new `difficult` field), and the error messages on bad files."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import shared_data_dir

from dsfec_jax.boxes.boxes2d import Boxes2D
from dsfec_jax.data.camera import voc

XML = """<annotation><folder>VOC2012</folder><filename>a.jpg</filename>
<size><width>40</width><height>30</height><depth>3</depth></size>
<object><name>dog</name><truncated>1</truncated><difficult>1</difficult>
<bndbox><xmin>1</xmin><ymin>2</ymin><xmax>10</xmax><ymax>20</ymax></bndbox></object>
<object><name>cat</name>{extra}<bndbox><xmin>5</xmin><ymin>5</ymin><xmax>5</xmax><ymax>9</ymax></bndbox></object>
</annotation>"""


@pytest.fixture(scope="module")
def database():
    path = shared_data_dir() / "voc_review_od_metrics" / "data" / "database"
    if not (path / "voc.names").is_file():
        pytest.fail(f"VOC sample data not found under {path}; set DSFEC_DATA")
    return path


@pytest.fixture(scope="module")
def annotations(database):
    return voc.read_annotation_dir(database / "gts" / "pascalvoc_format")


def write(tmp_path, name: str, text: str):
    path = tmp_path / name
    path.write_text(text)
    return path


# --------------------------------------------------------------------------- the real files


def test_the_100_real_annotations(annotations, database):
    objects = [o for a in annotations.values() for o in a.objects]
    names = voc.read_names(database / "voc.names")
    assert len(annotations) == 100 and len(objects) == 273
    assert len(names) == 20 and {o.name for o in objects} == set(names)
    assert sum(o.difficult for o in objects) == 38
    first = annotations["2007_000027"]
    assert (first.filename, first.width, first.height, first.depth) == ("2007_000027.jpg", 486, 500, 3)
    assert first.objects == (voc.VocObject("person", (174.0, 101.0, 349.0, 351.0), False, False),)
    for a in annotations.values():
        for o in a.objects:
            assert 0 <= o.bbox[0] < o.bbox[2] <= a.width and 0 <= o.bbox[1] < o.bbox[3] <= a.height


def test_every_referenced_image_exists_and_has_its_size(annotations, database):
    for a in annotations.values():
        image = voc.load_image(voc.image_path(a, database / "images"))
        assert image.shape == (a.height, a.width, 3) and image.dtype == np.uint8, a.image_id


def test_the_real_detection_files(database):
    names = voc.read_names(database / "voc.names")
    dets = voc.read_detection_dir(database / "dets" / "abs_xyx2y2", names)
    assert len(dets) == 98 and sum(map(len, dets.values())) == 452
    assert dets["2007_000027"] == (voc.VocDetection("person", 0.431418, (162.0, 96.0, 351.0, 341.0)),)


# --------------------------------------------------------------------------- conversion to Boxes2D


def test_voc_boxes_become_pixel_edges_with_difficult_flags(tmp_path):
    a = voc.read_annotation(write(tmp_path, "x.xml", XML.format(extra="")))
    assert a.image_id == "x" and a.objects[0] == voc.VocObject("dog", (1.0, 2.0, 10.0, 20.0), True, True)
    assert a.objects[1].difficult is False and a.objects[1].truncated is False  # missing flags are 0
    boxes = a.boxes()
    np.testing.assert_array_equal(boxes.xyxy, [[0, 1, 10, 20], [4, 4, 5, 9]])  # xmin - 1, ymin - 1, xmax, ymax
    np.testing.assert_array_equal(boxes.wh, [[10, 19], [1, 5]])                # = xmax - xmin + 1 pixels
    assert boxes.difficult.tolist() == [True, False] and boxes.scores is None
    np.testing.assert_array_equal(voc.edges_to_inclusive(boxes.xyxy), [o.bbox for o in a.objects])


def test_an_annotation_without_objects_is_empty_ground_truth(tmp_path):
    text = "<annotation><filename>b.png</filename><size><width>4</width><height>3</height></size></annotation>"
    a = voc.read_annotation(write(tmp_path, "b.xml", text))
    assert a.depth is None and len(a.boxes()) == 0 and a.boxes().difficult.shape == (0,)


def test_boxes2d_difficult_is_checked_and_selected():
    b = Boxes2D(np.zeros((3, 4), np.float32), np.array(["a", "b", "c"]), difficult=np.array([True, False, True]))
    assert b.select(np.array([2, 1])).difficult.tolist() == [True, False]
    assert Boxes2D(b.xyxy, b.names).select([0]).difficult is None
    with pytest.raises(ValueError, match="difficult"):
        Boxes2D(b.xyxy, b.names, difficult=np.array([1, 0, 1]))        # ints, not bools
    with pytest.raises(ValueError, match="difficult"):
        Boxes2D(b.xyxy, b.names, difficult=np.array([True, False]))


def test_images_load_as_rgb(tmp_path):
    from PIL import Image

    Image.fromarray(np.full((3, 5), 7, np.uint8)).save(tmp_path / "g.png")  # greyscale PNG
    assert voc.load_image(tmp_path / "g.png").shape == (3, 5, 3)
    write(tmp_path, "bad.jpg", "not a jpeg")
    with pytest.raises(ValueError, match="bad.jpg"):
        voc.load_image(tmp_path / "bad.jpg")


def test_a_box_a_pixel_or_two_outside_its_image_is_kept_as_written(tmp_path):
    # VOC has off-by-one boxes (xmin 0, xmax width + 1); voc_eval scores them as written
    text = XML.format(extra="").replace("<xmin>1<", "<xmin>0<").replace("<xmax>10<", "<xmax>42<")
    a = voc.read_annotation(write(tmp_path, "x.xml", text))
    assert a.objects[0].bbox == (0.0, 2.0, 42.0, 20.0) and np.isfinite(a.boxes().xyxy).all()


def test_a_truncated_jpeg_is_an_unreadable_image_naming_the_file(tmp_path, database):
    whole = (database / "images" / "2007_000027.jpg").read_bytes()
    (tmp_path / "cut.jpg").write_bytes(whole[: len(whole) // 2])
    with pytest.raises(voc.UnreadableImage, match="cut.jpg: not a readable image .*truncated"):
        voc.load_image(tmp_path / "cut.jpg")


# --------------------------------------------------------------------------- errors name the file and field


@pytest.mark.parametrize("text, match", [
    ("<annotation><size>", "malformed XML"),
    (XML.format(extra="").replace("<bndbox><xmin>1", "<box><xmin>1").replace("</ymax></bndbox></object>\n<obj",
                                                                          "</ymax></box></object>\n<obj"),
     r"object\[0\]\.bndbox: missing"),
    (XML.format(extra="").replace("<xmax>10<", "<xmax>0<"), r"object\[0\]\.bndbox: expected xmin <= xmax"),
    (XML.format(extra="").replace("<ymin>2<", "<ymin>two<"), r"object\[0\]\.bndbox\.ymin: expected a finite"),
    (XML.format(extra="<difficult>2</difficult>"), r"object\[1\]\.difficult: expected 0 or 1"),
    (XML.format(extra="").replace("<width>40<", "<width>-40<"), r"size\.width: expected an integer"),
    (XML.format(extra="").replace("<name>dog</name>", ""), r"object\[0\]\.name: missing"),
    ("<root/>", "expected <annotation>"),
    (XML.format(extra="").replace("<xmax>10<", "<xmax>5000<"),
     r"object\[0\]\.bndbox\.xmax: 5000 lies outside the 40 x 30 image \(expected 1\.\.40, give or take 2 px\)"),
    (XML.format(extra="").replace("<ymin>5<", "<ymin>-7<"), r"object\[1\]\.bndbox\.ymin: -7 lies outside"),
    (XML.format(extra="").replace("<xmax>10<", "<xmax>1e308<"), r"object\[0\]\.bndbox\.xmax: '1e308' does not fit float32"),
    (XML.format(extra="").replace("<width>40<", "<width>70000<"), r"size\.width: expected an integer in 1\.\.65535"),
])
def test_bad_xml_is_a_value_error_naming_file_and_field(tmp_path, text, match):
    path = write(tmp_path, "bad_file.xml", text)
    with pytest.raises(ValueError, match=match) as e:
        voc.read_annotation(path)
    assert str(path) in str(e.value)


@pytest.mark.parametrize("line, match", [
    ("0 0.5 1 2 3", "bad.txt:2: expected 6 columns 'class_id score x1 y1 x2 y2'; got 5"),
    ("2 0.5 1 2 3 4", r"bad.txt:2: class_id: expected an integer in 0..1 .*got '2'"),
    ("-1 0.5 1 2 3 4", "bad.txt:2: class_id"),
    ("1.0 0.5 1 2 3 4", "bad.txt:2: class_id"),
    ("0 high 1 2 3 4", "bad.txt:2: score: expected a finite number; got 'high'"),
    ("0 nan 1 2 3 4", "bad.txt:2: score"),
    ("0 0.5 1 2 x 4", "bad.txt:2: x2: expected a finite number"),
    ("0 0.5 5 2 3 4", r"bad.txt:2: expected x1 <= x2"),
    ("0 1e308 1 2 3 4", "bad.txt:2: score: '1e308' does not fit float32"),
    ("0 0.5 1 2 5e6 4", "bad.txt:2: x2: 5e[+]06 is no pixel coordinate"),
])
def test_bad_detection_lines_are_value_errors_naming_file_and_line(tmp_path, line, match):
    path = write(tmp_path, "bad.txt", f"1 0.9 1 1 5 5\n{line}\n")
    with pytest.raises(ValueError, match=match):
        voc.read_detections(path, ("cat", "dog"))


def test_detections_become_edges_with_scores(tmp_path):
    path = write(tmp_path, "d.txt", "1 0.9 1 1 5 5\n\n0 0.25 2.5 3 4 6\n")
    dets = voc.read_detections(path, ("cat", "dog"))
    assert [d.name for d in dets] == ["dog", "cat"]
    boxes = voc.detection_boxes(dets)
    np.testing.assert_array_equal(boxes.xyxy, [[0, 0, 5, 5], [1.5, 2, 4, 6]])
    np.testing.assert_allclose(boxes.scores, [0.9, 0.25])
    assert len(voc.detection_boxes(voc.read_detections(write(tmp_path, "e.txt", ""), ("cat",)))) == 0


@pytest.mark.parametrize("text, match", [("cat\n\ndog\n", "names:2: empty class name"),
                                         ("cat\ndog\ncat\n", "names:3: class 'cat' is listed twice"),
                                         ("\n\n", "no class names")])
def test_bad_names_files(tmp_path, text, match):
    with pytest.raises(ValueError, match=match):
        voc.read_names(write(tmp_path, "names", text))
    assert voc.read_names(write(tmp_path, "ok.names", " cat \ndog\n\n")) == ("cat", "dog")


def test_folders_must_exist_and_hold_files(tmp_path):
    with pytest.raises(FileNotFoundError, match="no such folder"):
        voc.read_annotation_dir(tmp_path / "missing")
    with pytest.raises(ValueError, match=r"no \*.xml files"):
        voc.read_annotation_dir(tmp_path)
