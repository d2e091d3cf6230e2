"""The edge pipeline: frame sources, depth sources, per-frame placement, the resumable loop, the CLI."""

import csv
import json
import re

import numpy as np
import pytest
from edge_fakes import FakeMap
from PIL import Image

from dsfec_jax.boxes.boxes2d import Boxes2D
from dsfec_jax.cli_edge import TOKEN_ENV
from dsfec_jax.data.camera.street import StreetConfig, generate_drive
from dsfec_jax.edge import depth_sources as ds
from dsfec_jax.edge.frames import EdgeFrame, drive_frames, folder_frames
from dsfec_jax.edge.pipeline import EdgePipeline
from dsfec_jax.edge.run import BATCHES, done_batches, run_edge
from dsfec_jax.edge.uplink import Uplink
from dsfec_jax.geo.gps import EgoTrack, GpsFixes, clean_fixes, write_gps_csv
from dsfec_jax.geo.geodesy import geodetic_to_enu

CFG = StreetConfig(width=160)  # small frames: the geometry is the same at any width


@pytest.fixture(scope="module")
def drive():
    return generate_drive(CFG, "test", 0, seed=0, num_frames=4)


@pytest.fixture(scope="module")
def frames(drive):
    return list(drive_frames(drive))


def truth_detector(frames):
    """The ground-truth boxes as detections (score 1): isolates placement from detection."""
    by_image = {id(f.image): f.truth.boxes for f in frames}

    def detect(image):
        b = by_image[id(image)]
        return Boxes2D(b.xyxy, b.names, np.ones(len(b), np.float32))
    return detect


def pipeline_for(drive, frames, depth=None, fixes=None):
    fixes = fixes or clean_fixes(GpsFixes.from_track(drive.gps))[0]
    return EdgePipeline(truth_detector(frames), depth or ds.TruthDepth(), CFG.camera_model(),
                        EgoTrack(fixes, origin=CFG.origin), "dev-1")


def test_exact_depth_places_objects_near_their_true_centres(drive, frames):
    pipe = pipeline_for(drive, frames)
    errors = []
    for f in frames:
        result = pipe(f)
        assert result.batch["batch_id"] == f"dev-1:{f.frame_id}" and result.placed.all()
        placed = geodetic_to_enu([o["lat"] for o in result.batch["objects"]], [o["lon"] for o in result.batch["objects"]],
                                 [o["alt"] for o in result.batch["objects"]], CFG.origin)
        truth = f.truth.objects.center_enu
        rel = np.hypot(*(placed[:, :2] - truth[:, :2]).T) / np.maximum(f.truth.objects.center_cam[:, 2], 1)
        errors += list(rel[~f.truth.difficult])  # an occluded box's centre may see what occludes it
        assert set(result.seconds) == {"detect", "depth", "place"}
    # the centre of a box sees the near surface (half an object's length in front of its centre)
    # and the 1 Hz fixes are interpolated: within 35 % of the range, and mostly far better
    assert len(errors) > 5 and np.max(errors) < 0.35 and np.median(errors) < 0.12


def test_frames_outside_the_gps_track_are_skipped_and_counted(drive, frames):
    fixes = clean_fixes(GpsFixes.from_track(drive.gps))[0]
    late = GpsFixes(fixes.time_s + 0.25, fixes.lat, fixes.lon, fixes.alt)  # the first frames precede the first fix
    pipe = pipeline_for(drive, frames, fixes=late)
    results = [pipe(f) for f in frames]
    assert [r.batch is None for r in results] == [True, True, True, False] and pipe.skipped == 3


def test_a_killed_run_resumes_without_recomputing_or_reposting(drive, frames, tmp_path):
    def source(limit):
        return lambda skip: (f for f in frames[:limit] if f.frame_id not in skip)

    with FakeMap() as server:
        run_edge(source(2), pipeline_for(drive, frames), tmp_path, Uplink(server.url, tmp_path / "queue"))
        first = list(server.stored)
        with open(tmp_path / BATCHES, "a") as f:
            f.write('{"batch_id": "torn')                            # a kill in the middle of a line
        summary = run_edge(source(4), pipeline_for(drive, frames), tmp_path, Uplink(server.url, tmp_path / "queue"))
    run_id = summary["run_id"]
    assert first == [f"dev-1:{run_id}:00000{i}" for i in range(2)] and server.answers == [201] * 4
    assert [b["frame"] for b in done_batches(tmp_path)] == ["000000", "000001", "000002", "000003"]
    assert summary["frames_resumed"] == 2 and summary["frames_placed"] == 4 and summary["uplink"]["delivered_all"]
    geo = json.loads((tmp_path / "edge.geojson").read_text())
    assert sum(f["geometry"]["type"] == "Point" for f in geo["features"]) == summary["objects"] > 0
    assert (tmp_path / "edge.png").stat().st_size > 1000 and (tmp_path / "edge.csv").exists()


def write_folder(tmp_path, frames, times=True):
    d = tmp_path / "frames"
    d.mkdir()
    for f in frames:
        Image.fromarray(f.image).save(d / f"{f.frame_id}.png")
    cam = CFG.camera_model()
    (d / "camera.json").write_text(json.dumps({"fx": cam.fx, "cx": cam.cx, "width": cam.width, "height": cam.height,
                                               "baseline_m": 0.54}))
    if times:
        with open(d / "times.csv", "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["frame", "time_s"])
            w.writerows([[f"{f.frame_id}.png", f.time_s] for f in frames])
    return d


def test_folder_frames_and_their_clear_errors(frames, tmp_path):
    d = write_folder(tmp_path, frames)
    folder = folder_frames(d)
    got = list(folder.frames(skip={"000001"}))
    assert [f.frame_id for f in got] == ["000000", "000002", "000003"] and np.array_equal(got[0].image, frames[0].image)
    (d / "times.csv").write_text("frame,time_s\n000000.png,0\n000001.png,x\n")
    with pytest.raises(ValueError, match=r"times.csv row 3: time_s='x'"):
        folder_frames(d)
    (d / "times.csv").unlink()
    with pytest.raises(ValueError, match="--fps"):
        folder_frames(d)
    assert folder_frames(d, fps=10.0).times[:2] == (0.0, 0.1)
    (d / "camera.json").write_text('{"fx": 1}')
    with pytest.raises(ValueError, match="camera.json.*fx, cx, width, height"):
        folder_frames(d, fps=10.0)


def test_user_depth_and_disparity_files(frames, tmp_path):
    f = frames[0]
    cam = CFG.camera_model()
    disp = f.truth.disparity()
    (tmp_path / "disp").mkdir()
    Image.fromarray(np.round(np.nan_to_num(disp, posinf=0) * 256).astype(np.uint16)).save(tmp_path / "disp" / "000000.png")
    (tmp_path / "depth").mkdir()
    np.save(tmp_path / "depth" / "000000.npy", f.truth.depth)
    from_disp = ds.StereoDisparityFiles(tmp_path / "disp", 0.54)(f, cam)
    from_depth = ds.DepthFiles(tmp_path / "depth")(f, cam)
    near = np.isfinite(f.truth.depth) & (f.truth.depth < 30)
    assert np.allclose(from_depth[near], f.truth.depth[near])
    assert np.nanmax(np.abs(from_disp[near] - f.truth.depth[near]) / f.truth.depth[near]) < 0.05  # 1/256 px steps
    with pytest.raises(FileNotFoundError, match="000001.npy or 000001.png"):
        ds.DepthFiles(tmp_path / "depth")(frames[1], cam)
    np.save(tmp_path / "depth" / "000001.npy", np.zeros((3, 3)))
    with pytest.raises(ValueError, match=r"depth map \(3, 3\)"):
        ds.DepthFiles(tmp_path / "depth")(frames[1], cam)
    with pytest.raises(ValueError, match="synthetic drive"):
        ds.TruthDepth()(EdgeFrame("x", 0.0, f.image), cam)


def test_network_depth_reads_a_fraction_of_the_width_as_pixels():
    cam = CFG.camera_model()
    source = ds.NetworkDepth(lambda image: np.full(image.shape[:2], 0.05), baseline_m=0.54)
    depth = source(EdgeFrame("x", 0.0, np.zeros((cam.height, cam.width, 3), np.uint8)), cam)
    assert np.allclose(depth, 0.54 * cam.fx / (cam.width * 0.05))
    calibrated = ds.NetworkDepth(lambda image: np.full(image.shape[:2], 0.05), baseline_m=0.54, a=2 * cam.width)
    assert np.allclose(calibrated(EdgeFrame("x", 0.0, np.zeros((cam.height, cam.width, 3), np.uint8)), cam), depth / 2)


def test_cli_edge_over_a_folder_with_user_depth(drive, frames, tmp_path, monkeypatch, capsys):
    from dsfec_jax.cli import main

    d = write_folder(tmp_path, frames)
    (tmp_path / "depth").mkdir()
    for f in frames:
        np.save(tmp_path / "depth" / f"{f.frame_id}.npy", f.truth.depth)
    write_gps_csv(tmp_path / "gps.csv", GpsFixes.from_track(drive.gps))
    out = tmp_path / "out"
    command = ["edge", "--frames", str(d), "--gps", str(tmp_path / "gps.csv"), "--depth", f"depth:{tmp_path / 'depth'}",
               "--out", str(out), "--device", "cam-7"]
    monkeypatch.delenv(TOKEN_ENV, raising=False)
    with FakeMap(token="tok-7") as server:
        with pytest.raises(SystemExit, match="not everything was delivered:\n  the server at .* answered HTTP 401"):
            main(command + ["--server", server.url])                    # no token: it stops, keeps its batches
        stopped = json.loads((out / "edge.json").read_text())
        assert stopped["uplink"]["queued"] == stopped["frames_placed"] >= 1 and server.stored == {}
        monkeypatch.setenv(TOKEN_ENV, "tok-7")
        capsys.readouterr()
        assert main(command + ["--server", server.url]) == 0
    assert re.search(r"edge frames placed: \d+frame", capsys.readouterr().err)  # a bar on stderr (issue 51)
    summary = json.loads((out / "edge.json").read_text())
    assert summary["frames_placed"] == 4 and summary["timing_this_run"]["frames_per_s"] > 0
    assert summary["uplink"]["delivered_all"] and sorted(server.stored) == [b["batch_id"] for b in done_batches(out)]
    assert all(b["device"] == "cam-7" for b in done_batches(out)) and server.auth[-1] == "Bearer tok-7"
    with pytest.raises(SystemExit, match="--gps"):
        main(["edge", "--frames", str(d), "--out", str(out)])


# The shipped depth weights' disparity on a fixed image (np.random.default_rng(0), 234 x 416), computed
# with the depth network's own loader (modalities/image/depth.py at 3487237) before it joined the zoo,
# under the tests' XLA flags (conftest: backend optimisation level 0; a plain process gives other last
# bits, sha256 f923ab85...); the zoo's loader must give the same bits
SHIPPED_DISPARITY_SHA256 = "da68d3fcd53e66745070615684f2b1844c27c5a8d879cf0357f37a1097a01d9e"
SHIPPED_DISPARITY_AT = {(0, 0): 0.12154500931501389, (117, 208): 0.006413883995264769, (233, 415): 0.12793684005737305}


def test_the_shipped_depth_weights_follow_the_zoo_rules_and_give_the_same_disparity():
    import hashlib

    from dsfec_jax import zoo
    from dsfec_jax.cli_edge import DEPTH_MODEL
    from dsfec_jax.core import checkpoint
    from dsfec_jax.modalities.image.depth import load_depth_predictor

    path = zoo.shipped_weights(DEPTH_MODEL)
    manifest = checkpoint.read_manifest(path)
    assert manifest["model"] == DEPTH_MODEL and manifest["training"]["command"].startswith("dsfec depth train")
    assert manifest["training"]["seed"] == 0 and manifest["versions"]["jax"] and checkpoint.problem(path) is None
    assert manifest["training"]["init_chain"][0]["command"].startswith("dsfec depth train")
    test = manifest["measured"]["test"]  # docs/edge-and-map-service.md quotes them
    assert (round(test["abs_rel"], 3), round(test["rmse"], 2), round(test["a1"], 3), test["frames"]) == (0.378, 5.01, 0.73, 50)
    predictor = load_depth_predictor(path)
    assert predictor.config == zoo.config(DEPTH_MODEL)
    disparity = predictor(np.random.default_rng(0).integers(0, 256, (234, 416, 3), dtype=np.uint8))
    assert {at: float(disparity[at]) for at in SHIPPED_DISPARITY_AT} == SHIPPED_DISPARITY_AT
    assert hashlib.sha256(disparity.tobytes()).hexdigest() == SHIPPED_DISPARITY_SHA256
