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
