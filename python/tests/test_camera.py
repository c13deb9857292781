"""Frames, tracking and calibration from Python: frames identical to `flatland render`'s, and
the tracker and calibration right against the renderer's exact truth."""

import csv
import math

import numpy as np
import pytest
from PIL import Image

import flatland
from conftest import SCENES, run_cli

FEEDBACK = SCENES / "airtable-feedback.yaml"  # noise, blur and jitter: the RNG's order matters
CAMERA = SCENES / "butterfly-camera.yaml"


def test_frames_equal_the_clis(cli, tmp_path):
    out = tmp_path / "frames"
    run_cli("render", "--scene", FEEDBACK, "--duration", "0.2", "--out", out)
    with open(out / "truth.csv", newline="") as f:
        truth = list(csv.DictReader(f))
    renderer = flatland.Renderer(flatland.load(FEEDBACK), duration=0.2)
    fps = renderer.camera["fps"]
    assert len(truth) == math.floor(0.2 * fps + 1e-9) + 1
    for i, row in enumerate(truth):
        image, t = renderer.render(t=min(i / fps, renderer.t_end))
        assert t["t"] == float(row["t"])
        if row["frame"] == "-1":
            assert image is None
            continue
        png = np.asarray(Image.open(out / f"frame_{int(row['frame']):06d}.png").convert("RGB"))
        assert image.shape == (480, 640, 3) and image.dtype == np.uint8
        np.testing.assert_array_equal(image[:, :, ::-1], png)  # BGR vs the PNG's RGB
        assert (t["disk_center_px"][0], t["disk_center_px"][1]) == (float(row["disk_u"]),
                                                                    float(row["disk_v"]))


def test_a_state_renders_where_its_truth_projects():
    renderer = flatland.Renderer(flatland.load(CAMERA))
    image, truth = renderer.render(state={"hand_angle": 0.3, "disk_center": (0.05, 0.16)})
    assert image.shape == (480, 640, 3)
    # The overhead camera looks straight down from 1.2 m with f = 900 px: a table point (x, y)
    # on the disk's top face (z) projects to (319.5 + 900 x / (1.2 - z), 239.5 - 900 y / (1.2 - z)).
    x, y, z = truth["disk_center_table"]
    assert (x, y) == (0.05, 0.16)
    u, v = truth["disk_center_px"]
    assert abs(u - (319.5 + 900 * x / (1.2 - z))) < 1e-9
    assert abs(v - (239.5 - 900 * y / (1.2 - z))) < 1e-9
    # The disk's face is bright there.
    assert image[int(round(v)), int(round(u))].mean() > 128


def test_the_mask_holds_the_disk_where_its_truth_projects():
    # The disk's id fills the disk's projected circle (the overhead camera: radius
    # r_px = 900 r / (1.2 - z) about the projected centre) to its rim's pixel: every pixel more
    # than 1.5 px inside is the disk unless the hand (its top face 6 mm above the disk's) covers
    # it, and none more than 1.5 px outside is.
    renderer = flatland.Renderer(flatland.load(CAMERA))
    for truth in (renderer.render(state={"hand_angle": 0.3, "disk_center": (0.05, 0.16)},
                                  mask=True)[1],
                  renderer.render(t=0.5, mask=True)[1]):
        mask = truth["mask"]
        assert mask.shape == (480, 640) and mask.dtype == np.uint8
        assert set(np.unique(mask)) <= {0, 1, 2, 3}
        assert {1, 2, 3} <= set(np.unique(mask))  # table, hand and disk all in view
        u, v = truth["disk_center_px"]
        r_px = 900 * 0.051 / (1.2 - truth["disk_center_table"][2])  # the scene's disk.radius
        vs, us = np.mgrid[0:480, 0:640]
        d = np.hypot(us - u, vs - v)
        inside = mask[d < r_px - 1.5]
        assert np.all((inside == 3) | (inside == 2))
        assert np.count_nonzero(inside == 3) > 0.8 * inside.size
        assert not np.any(mask[d > r_px + 1.5] == 3)
        assert truth["t_state"] == truth["t"]  # a global shutter
    _, plain = renderer.render(t=0.5)
    assert "mask" not in plain


def test_the_tracker_finds_the_disk_and_its_contact():
    model = flatland.load(CAMERA)
    renderer = flatland.Renderer(model)
    tracker = flatland.Tracker(model)
    errors, s_errors = [], []
    for i in range(0, 30, 3):
        image, truth = renderer.render(t=i / 30)
        r = tracker.track(image, theta=truth["theta"])
        assert r["state"] in ("found", "tracking")
        errors.append(math.dist(r["center"], truth["disk_center_px"]))
        s_errors.append(abs(r["s_h"] - truth["s_h"]))
    # docs/VISION.md: the edge tracker's error on clean frames is a few hundredths of a pixel.
    assert max(errors) < 0.1
    assert max(s_errors) < 2e-3


def test_a_blank_frame_is_lost():
    r = flatland.Tracker().track(np.zeros((120, 160), np.uint8))
    assert r["state"] == "lost" and r["center"] is None


def test_calibration_recovers_the_rendered_camera():
    session = flatland.render_calibration(flatland.load(CAMERA), intrinsics_views=8,
                                          table_views=1, joint_views=3, seed=3)
    images = [session["images"][p] for p in session["intrinsics_images"]]
    r = flatland.calibrate(session["board"], images)
    K, K_true = r["camera"]["K"], session["camera"]["K"]
    assert r["views_used"] >= 6 and r["rms_px"] < 0.5
    assert abs(K[0, 0] - K_true[0, 0]) / K_true[0, 0] < 0.01
    assert abs(K[0, 2] - K_true[0, 2]) < 3 and abs(K[1, 2] - K_true[1, 2]) < 3


def test_calibration_from_corners_matches_an_exact_projection():
    # Corners projected by hand through a known pinhole camera (no distortion) from 6 tilted
    # poses: the calibration must give back f and the principal point.
    f, cx, cy = 800.0, 320.0, 240.0
    cols, rows, square = 9, 6, 0.03
    obj = np.array([[(i % cols + 1) * square, (i // cols + 1) * square, 0.0]
                    for i in range(cols * rows)])
    views = []
    for a, b in [(0.3, 0.1), (-0.3, 0.2), (0.2, -0.3), (-0.2, -0.25), (0.35, 0.3), (-0.1, 0.4)]:
        ca, sa, cb, sb = math.cos(a), math.sin(a), math.cos(b), math.sin(b)
        R = np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]]) @ \
            np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
        p = obj @ R.T + np.array([-0.15, -0.1, 0.6])
        views.append((np.c_[f * p[:, 0] / p[:, 2] + cx, f * p[:, 1] / p[:, 2] + cy], obj))
    r = flatland.calibrate("chessboard:9x6:0.03", corners=views, image_size=(640, 480),
                           fix="k3")
    K = r["camera"]["K"]
    assert abs(K[0, 0] - f) < 0.05 and abs(K[1, 1] - f) < 0.05
    assert abs(K[0, 2] - cx) < 0.05 and abs(K[1, 2] - cy) < 0.05


def test_camera_files_equal_the_clis(cli, tmp_path):
    """`flatland render` writes the scene's camera file and the truth: read from Python, the file
    is the renderer's camera, written back from Python it is the same file byte for byte, and
    projecting the truth's table points gives the truth's pixels."""
    out = tmp_path / "frames"
    run_cli("render", "--scene", CAMERA, "--duration", "0.2", "--out", out)
    f = flatland.read_camera_file(out / "camera.yaml")
    assert f["camera_name"] == "butterfly-camera" and f["table_pose"] and not f["rational_model"]
    expected = flatland.Renderer(flatland.load(CAMERA)).camera
    for key in ("width", "height", "fps", "exposure"):
        assert f["camera"][key] == expected[key], key
    for key in ("K", "dist", "t"):
        np.testing.assert_array_equal(f["camera"][key], expected[key])
    # The file keeps the rotation as a Rodrigues vector: R comes back to rounding.
    np.testing.assert_allclose(f["camera"]["R"], expected["R"], rtol=0, atol=1e-15)
    written = tmp_path / "python.yaml"
    flatland.write_camera_file(written, f["camera"], camera_name=f["camera_name"],
                               table_pose=True, joint=f["joint"])
    assert written.read_bytes() == (out / "camera.yaml").read_bytes()
    with open(out / "truth.csv", newline="") as fh:
        truth = list(csv.DictReader(fh))
    table = np.array([[float(r[c]) for c in ("disk_x", "disk_y", "disk_z")] for r in truth])
    pixels = np.array([[float(r["disk_u"]), float(r["disk_v"])] for r in truth])
    np.testing.assert_allclose(flatland.project(f["camera"], table), pixels, rtol=0, atol=1e-9)


def test_projection_is_the_pinhole_and_the_lens():
    # An independent projection: x_cam = R x + t, then OpenCV's plumb_bob distortion by hand.
    K = np.array([[800.0, 0, 320], [0, 810.0, 240], [0, 0, 1]])
    dist = np.array([-0.2, 0.05, 0.001, -0.002, 0.01])
    a = 0.3
    R = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    t = np.array([0.05, -0.02, 1.0])
    points = np.array([[0.1, 0.05, 0.0], [-0.12, 0.2, 0.03], [0.0, 0.0, 0.0]])
    got = flatland.project({"width": 640, "height": 480, "K": K, "dist": dist, "R": R, "t": t},
                           points)
    k1, k2, p1, p2, k3 = dist
    for p, (u, v) in zip(points, got):
        x, y, z = R @ p + t
        x, y = x / z, y / z
        r2 = x * x + y * y
        radial = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        assert abs(u - (K[0, 0] * xd + K[0, 2])) < 1e-9 and abs(v - (K[1, 1] * yd + K[1, 2])) < 1e-9


def test_bad_camera_files_and_cameras_write_nothing(tmp_path):
    camera = {"width": 640, "height": 480, "K": np.diag([900.0, 900.0, 1.0]), "dist": [0] * 5,
              "R": np.eye(3), "t": [0, 0, 1]}
    target = tmp_path / "camera.yaml"
    bad_cameras = [
        ({**camera, "K": np.diag([-900.0, 900.0, 1.0])}, "camera.K: fx and fy must be positive"),
        ({**camera, "dist": [0] * 4}, "camera.dist: 5 (plumb_bob) or 8"),
        ({**camera, "width": 0}, "camera.width: must be in [1, 16384]"),
        ({**camera, "R": 2 * np.eye(3)}, "camera.R: must be a rotation"),
        ({**camera, "t": [0, 0, float("nan")]}, "camera.t: every value must be finite"),
        ({k: v for k, v in camera.items() if k != "K"}, "camera.K: missing"),
    ]
    for bad, message in bad_cameras:
        with pytest.raises(ValueError, match="^" + message.replace("[", r"\[").replace("(", r"\(")
                           .replace(")", r"\)")):
            flatland.write_camera_file(target, bad, table_pose=True)
        assert not list(tmp_path.iterdir())
    with pytest.raises(ValueError, match="^path: no folder "):
        flatland.write_camera_file(tmp_path / "none" / "camera.yaml", camera)
    flatland.write_camera_file(target, camera)
    before = target.read_bytes()
    with pytest.raises(ValueError, match=r"^path: .* exists \(force=True overwrites it\)"):
        flatland.write_camera_file(target, {**camera, "width": 320})
    assert target.read_bytes() == before
    flatland.write_camera_file(target, {**camera, "width": 320}, force=True)
    assert flatland.read_camera_file(target)["camera"]["width"] == 320
    assert not flatland.read_camera_file(target)["table_pose"]
    with pytest.raises(ValueError, match=r"none\.yaml: \(file\): cannot read camera file"):
        flatland.read_camera_file(tmp_path / "none.yaml")
    (tmp_path / "bad.yaml").write_text("image_width: 640\n")
    with pytest.raises(ValueError, match="bad.yaml: image_height"):
        flatland.read_camera_file(tmp_path / "bad.yaml")
    with pytest.raises(ValueError, match=r"^points: an array of shape \(N, 3\)"):
        flatland.project(camera, np.zeros((2, 2)))


def test_a_camera_file_says_which_sections_its_data_could_not_support(cli, tmp_path):
    """`calibrate --force` marks a section its data could not support (flatland.unsupported, as
    the camera file's reader in C++ reads it): read_camera_file lists the marks, and a file
    without any has an empty list."""
    out = tmp_path / "frames"
    run_cli("render", "--scene", CAMERA, "--duration", "0.1", "--out", out)
    assert flatland.read_camera_file(out / "camera.yaml")["unsupported"] == []
    text = (out / "camera.yaml").read_text()
    marked = text.replace("flatland:\n", "flatland:\n   unsupported: [ \"joint: only 2 images\" ]\n", 1)
    assert marked != text
    (tmp_path / "marked.yaml").write_text(marked)
    assert flatland.read_camera_file(tmp_path / "marked.yaml")["unsupported"] == [
        "joint: only 2 images"]


def test_transposed_arrays_are_read_by_value_not_by_memory_order(cli, tmp_path):
    """numpy hands over a transposed matrix in Fortran order: K and R given so must project and
    be written exactly as their C-ordered copies (before, they were read transposed)."""
    out = tmp_path / "frames"
    run_cli("render", "--scene", CAMERA, "--duration", "0.1", "--out", out)
    cam = flatland.read_camera_file(out / "camera.yaml")["camera"]
    fortran = dict(cam, K=np.asfortranarray(cam["K"]), R=np.asfortranarray(cam["R"]))
    assert not fortran["R"].flags.c_contiguous
    points = np.array([[0.0, 0.1, 0.0], [0.05, -0.02, 0.006]])
    np.testing.assert_array_equal(flatland.project(fortran, points), flatland.project(cam, points))
    flatland.write_camera_file(tmp_path / "c.yaml", cam, table_pose=True)
    flatland.write_camera_file(tmp_path / "f.yaml", fortran, table_pose=True)
    assert (tmp_path / "c.yaml").read_text() == (tmp_path / "f.yaml").read_text()


def test_marks_survive_a_read_and_write_back(cli, tmp_path):
    out = tmp_path / "frames"
    run_cli("render", "--scene", CAMERA, "--duration", "0.1", "--out", out)
    f = flatland.read_camera_file(out / "camera.yaml")
    flatland.write_camera_file(tmp_path / "m.yaml", f["camera"], table_pose=True,
                               unsupported=["joint: only 2 images"])
    assert flatland.read_camera_file(tmp_path / "m.yaml")["unsupported"] == ["joint: only 2 images"]
