"""Spatial scenes (space: 3d) from Python: flatland.simulate's report and trajectory equal
`flatland simulate --json --out`'s, a Renderer's frames and truth equal `flatland render`'s, and
what only planar scenes have is refused with the CLI's message."""

import csv
import json

import numpy as np
import pytest
from PIL import Image

import flatland
from conftest import SCENES, cli_error, run_cli

BOWL = SCENES / "ball-in-bowl.yaml"          # a ball rolling in a fixed bowl
TURNTABLE = SCENES / "ball-on-turntable.yaml"  # a ball on a spinning plane


def read_csv(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], rows[1:]


@pytest.mark.parametrize("scene, args, kwargs", [
    (BOWL, ["--duration", "0.5"], {"duration": 0.5}),
    (TURNTABLE, ["--duration", "0.4", "--sample-dt", "0.01", "--rtol", "1e-9"],
     {"duration": 0.4, "sample_dt": 0.01, "rtol": 1e-9}),
])
def test_simulate_equals_the_cli(cli, tmp_path, scene, args, kwargs):
    out = tmp_path / "run.csv"
    code, stdout, err = run_cli("simulate", "--scene", scene, *args, "--out", out, "--no-plot",
                                "--json")
    expected = json.loads(stdout)
    del expected["csv"], expected["png"]
    run = flatland.simulate(scene, **kwargs)
    assert run.report == expected
    header, rows = read_csv(out)
    assert list(run.trajectory) == header
    for c, name in enumerate(header):
        np.testing.assert_array_equal(run.trajectory[name], [float(r[c]) for r in rows])
    # An invariant the CLI does not print: a ball stays on its bowl's surface (the contact point
    # is a ball radius from the centre, to the run's constraint tolerance).
    if scene == BOWL:
        t = run.trajectory
        gap = np.hypot(np.hypot(t["x"] - t["contact_x"], t["y"] - t["contact_y"]),
                       t["z"] - t["contact_z"])
        assert np.ptp(gap) < 1e-8


def test_frames_and_truth_equal_the_clis(cli, tmp_path):
    out = tmp_path / "frames"
    run_cli("render", "--scene", BOWL, "--duration", "0.2", "--out", out)
    header, rows = read_csv(out / "truth.csv")
    assert header == ["frame", "t", "x", "y", "z", "u", "v"]
    renderer = flatland.Renderer(BOWL, duration=0.2)
    fps = renderer.camera["fps"]
    assert len(rows) == 7  # 0.2 s at 30 frames/s: frames 0 to 6
    for row in rows:
        i = int(row[0])
        image, truth = renderer.render(t=i / fps)
        png = np.asarray(Image.open(out / f"frame_{i:06d}.png").convert("RGB"))
        np.testing.assert_array_equal(image[:, :, ::-1], png)
        assert truth["t"] == float(row[1])
        assert truth["disk_center_table"] == tuple(float(v) for v in row[2:5])
        assert truth["disk_center_px"] == (float(row[5]), float(row[6]))
    # The camera the CLI wrote beside the frames is the renderer's.
    written = flatland.read_camera_file(out / "camera.yaml")["camera"]
    np.testing.assert_array_equal(written["K"], renderer.camera["K"])
    assert renderer.t_end == pytest.approx(0.2, abs=1e-12)


@pytest.mark.parametrize("call, cli_args, message", [
    (lambda: flatland.simulate(BOWL, model="hybrid"), ["simulate", "--model", "hybrid"],
     "model: a spatial scene has the rolling model only"),
    (lambda: flatland.simulate(BOWL, period=1.0), ["simulate", "--period", "1"],
     "period: only for a scene whose motion is the butterfly"),
    (lambda: flatland.simulate(BOWL, duration=-1), ["simulate", "--duration", "-1"],
     "duration: must be positive"),
    (lambda: flatland.simulate(BOWL, mu=-0.5), ["simulate", "--mu", "-0.5"], "mu:"),
    (lambda: flatland.simulate(BOWL, formulation="reduced"),
     ["simulate", "--formulation", "reduced"], "formulation"),
    (lambda: flatland.simulate(BOWL, sample_dt=1e-12), ["simulate", "--sample-dt", "1e-12"],
     "sample_dt:"),
])
def test_bad_overrides_have_the_clis_messages(cli, call, cli_args, message):
    with pytest.raises(ValueError) as e:
        call()
    assert message in str(e.value) and "\n" not in str(e.value)
    expected = cli_error(*cli_args, "--scene", BOWL)
    for option in ("model", "period", "duration", "mu", "formulation", "sample_dt"):
        expected = expected.replace("--" + option.replace("_", "-"), option)
    assert str(e.value) == expected


@pytest.mark.parametrize("call, message", [
    (lambda: flatland.load(BOWL), "path: " + str(BOWL) + " is a spatial scene (space: 3d)"),
    (lambda: flatland.solve(scene=BOWL), "scene: " + str(BOWL) + " is a spatial scene"),
    (lambda: flatland.Tracker(BOWL), "model: " + str(BOWL) + " is a spatial scene"),
    (lambda: flatland.experiment(BOWL), "model: " + str(BOWL) + " is a spatial scene"),
    (lambda: flatland.Renderer(BOWL).render(t=0.51), "t: a spatial scene is drawn at its camera's"),
    (lambda: flatland.Renderer(BOWL, duration=0.1).render(t=1.0), "t: outside the scene's run"),
    (lambda: flatland.Renderer(BOWL).render(state={"hand_angle": 0.1}), "state: a planar scene's"),
    (lambda: flatland.Renderer(SCENES / "butterfly.yaml"), "camera"),
])
def test_what_a_spatial_scene_does_not_have_is_refused(call, message):
    with pytest.raises(ValueError) as e:
        call()
    assert message in str(e.value) and "\n" not in str(e.value)
