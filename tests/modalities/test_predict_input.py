"""`dsfec predict --input PATH...`: a user's own files for every modality (modalities/files.py and
modalities/<name>/files.py). The paths (files, folders, globs; sorted, de-duplicated, bounded), one
end-to-end run per modality with the shipped weights on inputs of the shapes the shipped-detections
test already compiles (a 256 x 64 RD map, a 256 x 416 street image, a sparse radar scan), and the
hostile files: each is refused naming the file, before anything is written."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from conftest import shared_data_dir
from PIL import Image

from dsfec_jax import api, cli, zoo
from dsfec_jax.core.columns import VOD_FEATURES
from dsfec_jax.data.points.nuscenes import write_radar_pcd
from dsfec_jax.modalities import files
from dsfec_jax.modalities.image.files import READER as IMAGES
from dsfec_jax.modalities.points.files import READER as POINTS
from dsfec_jax.modalities.rd.files import READER as RD, RD_MAP_SHAPE

TI_CAPTURE = shared_data_dir() / "openradar_ti_adc" / "assets" / "simple_frame_1.npy"


def touch(folder, *names):
    folder.mkdir(parents=True, exist_ok=True)
    for name in names:
        (folder / name).write_bytes(b"x")
    return folder


# ----------------------------------------------------------------------------- PATH arguments


def test_files_folders_and_globs_expand_sorted_and_once(tmp_path):
    touch(tmp_path / "a", "2.jpg", "1.PNG", "notes.txt")
    touch(tmp_path / "b", "3.jpeg", "4.jpg")
    found = files.expand([str(tmp_path / "b" / "*.jp*g"), str(tmp_path / "a"), str(tmp_path / "a" / "2.jpg"),
                          str(tmp_path / "b" / "4.jpg")], IMAGES.suffixes)
    assert [p.relative_to(tmp_path).as_posix() for p in found] == ["a/1.PNG", "a/2.jpg", "b/3.jpeg", "b/4.jpg"]


@pytest.mark.parametrize("given,message", [
    ("a/notes.txt", r"notes.txt: extension '.txt'; expected .jpg / .jpeg / .png"),
    ("missing.jpg", r"missing.jpg: no such file or folder"),
    ("a/*.bmp", r"glob '.*a/\*.bmp': no .jpg / .jpeg / .png file"),
    ("empty", r"folder .*empty: no .jpg"),
])
def test_a_path_that_gives_no_image_is_named(tmp_path, given, message):
    touch(tmp_path / "a", "1.jpg", "notes.txt")
    (tmp_path / "empty").mkdir()
    with pytest.raises(files.InputFileError, match=message):
        files.expand([str(tmp_path / given)], IMAGES.suffixes)


def test_more_files_than_the_bound_are_refused_before_any_is_read(tmp_path):
    touch(tmp_path / "many", *(f"{i}.png" for i in range(5)))  # not images: the bound comes first
    with pytest.raises(files.InputFileError, match="more than 4 files"):
        files.expand([str(tmp_path / "many")], IMAGES.suffixes, limit=4)
    assert len(files.expand([str(tmp_path / "many")], IMAGES.suffixes, limit=5)) == 5


# ----------------------------------------------------------------------------- hostile files


def vod_bin(path, rows: int = 6, seed: int = 0) -> np.ndarray:
    """A VoD-layout scan: points ahead of the sensor, radial speeds, RCS, time 0."""
    rng = np.random.default_rng(seed)
    points = np.column_stack([rng.uniform(5, 40, rows), rng.uniform(-10, 10, rows), rng.uniform(-1, 1, rows),
                              rng.uniform(-10, 10, rows), rng.uniform(-5, 5, rows), rng.uniform(-5, 5, rows),
                              np.zeros(rows)]).astype("<f4")
    path.write_bytes(points.tobytes())
    return points


def test_point_files_are_read_in_the_models_columns(tmp_path):
    points = vod_bin(tmp_path / "scan.bin")
    frame = POINTS.read(tmp_path / "scan.bin", zoo.config("dsfec_s"), "vod")
    assert frame.frame_id == str(tmp_path / "scan.bin") and frame.point_features == zoo.config("dsfec_s").point_features
    np.testing.assert_allclose(frame.points[:, :3], points[:, :3])
    assert frame.points[:, 3].tolist() == pytest.approx(points[:, 3].tolist())  # RCS -> rcs
    named = POINTS.read(tmp_path / "scan.bin", zoo.config("dsfec_s"), ",".join(VOD_FEATURES))
    np.testing.assert_array_equal(named.points, frame.points)
    native = POINTS.read(tmp_path / "scan.bin", zoo.config("radarnext_fpn"), None)  # RadarNeXt: its own columns
    assert native.point_features == VOD_FEATURES
    np.testing.assert_array_equal(native.points, points)


def test_hostile_point_files_are_named(tmp_path):
    cfg = zoo.config("dsfec_s")
    (tmp_path / "short.bin").write_bytes(np.zeros(7 * 3 + 2, "<f4").tobytes())
    with pytest.raises(files.InputFileError, match=r"short.bin: size 92 B is not a multiple of 28 B \(7 float32"):
        POINTS.read(tmp_path / "short.bin", cfg, "vod")
    points = vod_bin(tmp_path / "nan.bin")
    points[2, 4] = np.nan
    (tmp_path / "nan.bin").write_bytes(points.tobytes())
    with pytest.raises(files.InputFileError, match=r"nan.bin: 1 of 6 points hold NaN or infinity \(first: row 2\)"):
        POINTS.read(tmp_path / "nan.bin", cfg, "vod")
    vod_bin(tmp_path / "plain.bin")
    with pytest.raises(files.InputFileError, match=r"plain.bin: a .bin does not say its columns; pass --columns"):
        POINTS.read(tmp_path / "plain.bin", cfg, None)
    with pytest.raises(files.InputFileError, match=r"--columns 'y,x,z': expected"):
        POINTS.read(tmp_path / "plain.bin", cfg, "y,x,z")
    with pytest.raises(files.InputFileError, match=r"plain.bin: its columns \('x', 'y', 'z', 'a', 'b', 'c', 'd'\) "
                                                   r"do not give dsfec_s's"):
        POINTS.read(tmp_path / "plain.bin", cfg, "x,y,z,a,b,c,d")
    write_radar_pcd(tmp_path / "sweep.pcd", np.ones((4, 18)))
    (tmp_path / "cut.pcd").write_bytes((tmp_path / "sweep.pcd").read_bytes()[:-10])
    with pytest.raises(files.InputFileError, match=r"cut.pcd: PCD body has .* \(truncated\)"):
        POINTS.read(tmp_path / "cut.pcd", cfg, None)


def test_hostile_rd_files_are_named(tmp_path):
    np.save(tmp_path / "small.npy", np.zeros((128, 64), np.float32))
    with pytest.raises(files.InputFileError, match=r"small.npy: shape \(128, 64\); expected a range-Doppler map"):
        RD.read(tmp_path / "small.npy")
    bad = np.zeros(RD_MAP_SHAPE, np.float32)
    bad[3, 4] = np.inf
    np.save(tmp_path / "inf.npy", bad)
    with pytest.raises(files.InputFileError, match=r"inf.npy: 1 map cells hold NaN or infinity"):
        RD.read(tmp_path / "inf.npy")
    np.save(tmp_path / "ints.npy", np.zeros(RD_MAP_SHAPE, np.int32))
    with pytest.raises(files.InputFileError, match=r"ints.npy: dtype int32; expected"):
        RD.read(tmp_path / "ints.npy")
    np.save(tmp_path / "adc.npy", np.zeros((64, 64), np.complex64))
    with pytest.raises(files.InputFileError, match=r"adc.npy: complex array of shape \(64, 64\): a raw TI ADC"):
        RD.read(tmp_path / "adc.npy")
    np.save(tmp_path / "map.npy", np.zeros(RD_MAP_SHAPE, np.float32))
    (tmp_path / "cut.npy").write_bytes((tmp_path / "map.npy").read_bytes()[:500])
    with pytest.raises(files.InputFileError, match=r"cut.npy: truncated"):
        RD.read(tmp_path / "cut.npy")


def test_hostile_images_are_named(tmp_path):
    Image.fromarray(np.full((40, 60, 3), 90, np.uint8)).save(tmp_path / "ok.jpg", quality=95)
    assert IMAGES.read(tmp_path / "ok.jpg").hw == (40, 60)
    (tmp_path / "cut.jpg").write_bytes((tmp_path / "ok.jpg").read_bytes()[:300])
    with pytest.raises(files.InputFileError, match=r"cut.jpg: not a readable image"):
        IMAGES.read(tmp_path / "cut.jpg")
    (tmp_path / "text.png").write_text("not a picture")
    with pytest.raises(files.InputFileError, match=r"text.png: not a readable image"):
        IMAGES.read(tmp_path / "text.png")


def test_a_bad_file_stops_predict_before_anything_is_written(tmp_path, monkeypatch):
    folder = tmp_path / "in"
    folder.mkdir()
    Image.fromarray(np.zeros((40, 60, 3), np.uint8)).save(folder / "a.png")
    (folder / "b.jpg").write_bytes(b"\xff\xd8\xff\xe0 truncated")
    out, png = tmp_path / "out.json", tmp_path / "png"
    with pytest.raises(SystemExit, match=r"dsfec predict: .*b.jpg: not a readable image"):
        cli.main(["predict", "--model", "shuffle_yolov3", "--input", str(folder), "--out", str(out),
                  "--png-dir", str(png)])
    assert not out.exists() and not png.exists()
    monkeypatch.setattr(files, "MAX_INPUT_FILES", 1)
    with pytest.raises(SystemExit, match=r"more than 1 files"):
        cli.main(["predict", "--model", "shuffle_yolov3", "--input", str(folder / "a.png"), str(folder),
                  "--out", str(out)])
    with pytest.raises(SystemExit, match=r"--data, --gt-out read a data source"):
        cli.main(["predict", "--model", "yolov8n", "--input", str(folder), "--data", "synthetic", "--gt-out", "g",
                  "--out", str(out)])
    with pytest.raises(SystemExit, match=r"--out .* is a folder; give the JSON file to write"):
        cli.main(["predict", "--model", "yolov8n", "--input", str(folder), "--out", str(tmp_path)])
    with pytest.raises(SystemExit, match=r"--columns says the layout of --input .bin files; give --input"):
        cli.main(["predict", "--model", "dsfec_s", "--columns", "vod", "--out", str(out)])
    assert not out.exists()


# ----------------------------------------------------------------------------- end to end, shipped weights


def predict_json(argv, capsys) -> tuple[dict, dict]:
    assert cli.main(["predict", *argv, "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    return printed, json.loads(open(printed["out"]).read())


def test_points_input_end_to_end(tmp_path, capsys):
    """Two VoD-layout .bin scans through a quoted glob, and a nuScenes .pcd from the shared data."""
    scans = tmp_path / "scans"
    scans.mkdir()
    vod_bin(scans / "b.bin", 40, seed=1)
    vod_bin(scans / "a.bin", 40, seed=2)
    pcd = next((shared_data_dir() / "nuscenes_radar").glob("*.pcd"))
    printed, document = predict_json(["--model", "dsfec_s", "--input", str(scans / "*.bin"), str(pcd),
                                      "--columns", "vod", "--out", str(tmp_path / "dets.json"),
                                      "--png-dir", str(tmp_path / "png")], capsys)
    entries = document["inputs"]
    assert document["model"] == "dsfec_s" and printed["inputs"] == 3
    # Files are reported resolved and sorted, so where the shared .pcd falls depends on where the data lives.
    given = [p.resolve() for p in (scans / "a.bin", scans / "b.bin", pcd)]
    assert [e["file"] for e in entries] == [str(p) for p in sorted(given)]
    first_scan = next(e for e in entries if e["file"] == str(given[0]))
    assert first_scan["points"] == 40 and sum(len(e["detections"]) for e in entries) == printed["detections"]
    frame = POINTS.read(scans / "a.bin", zoo.config("dsfec_s"), "vod")
    found = api.load("dsfec_s", predictor_options={"score_threshold": 0.05})(frame)  # what --input ran
    assert [d["score"] for d in first_scan["detections"]] == pytest.approx(found.scores.tolist(), abs=1e-5)
    assert sorted(p.name for p in (tmp_path / "png").iterdir()) == sorted(
        ["a.bin.png", "b.bin.png", f"{pcd.name}.png"])


def test_rd_input_end_to_end(tmp_path, capsys):
    """A synthetic 256 x 64 map saved as .npy, and the TI tutorial's raw ADC capture."""
    from dsfec_jax.data.rd.sources import load_rd_samples

    sample = load_rd_samples("synthetic", "test", 2)[1]
    np.save(tmp_path / "map.npy", sample.power)
    shutil.copy(TI_CAPTURE, tmp_path / "capture.npy")  # a user's copy: known by its shape, not its name
    printed, document = predict_json(["--model", "yolov8n", "--input", str(tmp_path / "map.npy"),
                                      str(tmp_path / "capture.npy"), "--out", str(tmp_path / "dets.json"),
                                      "--png-dir", str(tmp_path / "png")], capsys)
    adc, rd_map = document["inputs"]
    assert adc["map_shape"] == [128, 128] and rd_map["map_shape"] == list(RD_MAP_SHAPE)
    expected = api.load("yolov8n")(sample)  # the map read back from the file detects as the sample does
    assert [d["score"] for d in rd_map["detections"]] == pytest.approx(expected.scores.tolist(), abs=1e-5)
    first = rd_map["detections"][0]
    assert first["range_m"][0] < first["range_m"][1] and first["velocity_mps"][0] < first["velocity_mps"][1]
    assert len(list((tmp_path / "png").glob("*.png"))) == 2


def test_camera_input_end_to_end(tmp_path, capsys):
    """A street frame saved as PNG (the benchmark's 256 x 416 shape) detects as the frame does."""
    from dsfec_jax.data.camera.sources import load_camera_images

    item = load_camera_images("street", "test", 1)[0]
    Image.fromarray(item.image).save(tmp_path / "frame.png")
    printed, document = predict_json(["--model", "shuffle_yolov3", "--input", str(tmp_path),
                                      "--out", str(tmp_path / "out" / "dets.json"),
                                      "--png-dir", str(tmp_path / "out")], capsys)
    (entry,) = document["inputs"]
    expected = api.load("shuffle_yolov3").predict_samples([item])[item.image_id]
    assert entry["image_hw"] == list(item.hw) and len(entry["detections"]) == len(expected)
    assert [d["class"] for d in entry["detections"]] == expected.names.tolist()  # the model's own class names
    np.testing.assert_allclose([d["xyxy_px"] for d in entry["detections"]], expected.xyxy, atol=0.06)
    assert (tmp_path / "out" / "frame.png.png").is_file()
