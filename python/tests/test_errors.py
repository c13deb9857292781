"""Bad input raises ValueError with the CLI's one-line message (the option named as the keyword);
runtime failures raise RuntimeError."""

import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

import flatland
from conftest import ROOT, SCENES, cli_error


def test_a_bad_period_names_the_keyword_with_the_clis_reason(cli):
    with pytest.raises(ValueError) as e:
        flatland.solve(period=-1)
    assert str(e.value) == cli_error("solve", "--period", "-1").replace("--period", "period")


def test_a_bad_scene_file_has_the_clis_message(cli, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("motion:\n  type: butterfly\n  period: -3\n")
    with pytest.raises(ValueError) as e:
        flatland.load(bad)
    assert str(e.value) == cli_error("solve", "--scene", bad)
    with pytest.raises(ValueError):
        flatland.solve(scene=str(bad))


def test_a_missing_scene_file(cli, tmp_path):
    with pytest.raises(ValueError) as e:
        flatland.load(tmp_path / "none.yaml")
    assert str(e.value) == cli_error("solve", "--scene", tmp_path / "none.yaml")


@pytest.mark.parametrize("call, message", [
    (lambda: flatland.simulate(method="euler"), "method: must be one of dopri5, dop853, rk4"),
    (lambda: flatland.simulate(mu=-1), "mu: must be a finite number >= 0"),
    (lambda: flatland.simulate(sample_dt=0), "sample_dt: must be positive"),
    (lambda: flatland.simulate(sample_dt=1e-12), "sample_dt: 1e-12 s over 1.181 s is"),
    (lambda: flatland.simulate(rtol=1e-300), "rtol: must be in [1e-14, 0.1]"),
    (lambda: flatland.simulate(atol=1e-302), "atol: must be in [1e-18, 1]"),
    (lambda: flatland.solve(energy_tolerance=2), "energy_tolerance: must be in [1e-12, 1]"),
    (lambda: flatland.simulate(method="rk4", step=1e-12), "integrator.step: 1e-12 s over"),
    (lambda: flatland.simulate(duration=1e9), "duration: 1e+09 s would take about"),
    (lambda: flatland.simulate(model="hybrid", stop_on_contact_loss=False),
     "stop_on_contact_loss=False: only for the rolling model"),
    (lambda: flatland.time_optimal(from_=2, to=1), "to: must be larger than from_"),
    (lambda: flatland.locus(n=0), "n: must be in [1, 10000]"),
    (lambda: flatland.surface(nk=1), "nk: must be in [2, 10000]"),
    (lambda: flatland.solve(solve_for="x"), "solve_for: must be one of k, d"),
    (lambda: flatland.calibrate("chessboard:2x6:0.02", corners=[]), "board:"),
    (lambda: flatland.Renderer(SCENES / "butterfly-camera.yaml", duration=-1),
     "duration: must be positive"),
    (lambda: flatland.Renderer(SCENES / "butterfly-camera.yaml").render(t=99),
     "t: outside the scene's run"),
    (lambda: flatland.Renderer(SCENES / "butterfly-camera.yaml").render(),
     "render: give exactly one of t and state"),
    (lambda: flatland.Renderer(SCENES / "butterfly-camera.yaml", backend="vulkan"), "vulkan"),
    (lambda: flatland.calibrate("chessboard:9x6:0.02"), "images/corners: give exactly one"),
    (lambda: flatland.Tracker().track(np.zeros((4, 4, 2), np.uint8)), "frame: an image of shape"),
    (lambda: flatland.Tracker().track(np.zeros((4, 4), np.int32)), "frame: uint8 or float32"),
    (lambda: flatland.Tracker(method="magic"), "magic"),
    (lambda: flatland.experiment(controller="psychic"), "controller: unknown 'psychic' (a mode: feedback, open-loop"),
    (lambda: flatland.montecarlo(perturbations={"gravity": 1}), "perturbations.gravity: unknown"),
    (lambda: flatland.montecarlo(perturbations={"drop": 2}), "perturbations.drop"),
    (lambda: flatland.montecarlo(perturbations={"drop": "often"}),
     "perturbations.drop: a number, got a str"),
    (lambda: flatland.calibrate("chessboard:9x6:0.02", corners=[5], image_size=(640, 480)),
     "corners[0]: a pair (image_points (N, 2), object_points (N, 3)), got a int"),
    (lambda: flatland.calibrate("chessboard:9x6:0.02", corners=[(np.zeros((4, 3)), np.zeros((4, 3)))],
                                image_size=(640, 480)), "corners[0][0]: an array of shape (N, 2)"),
    (lambda: flatland.calibrate("chessboard:9x6:0.02", [np.zeros((8, 8), np.float64)]),
     "images[0]: uint8 or float32 pixels"),
    (lambda: flatland.calibrate("chessboard:9x6:0.02", corners=[]), "image_size:"),
    (lambda: flatland.Renderer(flatland.default_scene_path()), "camera"),
    (lambda: flatland.load(123), "path: a Model, a path or None"),
])
def test_bad_input_raises_value_error(call, message):
    with pytest.raises(ValueError) as e:
        call()
    assert message in str(e.value)
    assert "\n" not in str(e.value)


def test_a_failed_search_raises_runtime_error():
    # No butterfly brings the disk over the tip in 0.2 s: the search finds no bracket (the
    # CLI's exit 1).
    with pytest.raises(RuntimeError):
        flatland.solve(period=0.2)


def test_ctrl_c_interrupts_a_long_call():
    # A surface of a million simulations takes minutes; SIGINT must end it within seconds with
    # KeyboardInterrupt, and the interpreter must be usable afterwards.
    script = textwrap.dedent("""
        import sys, time, flatland
        print("ready", flush=True)
        t = time.monotonic()
        try:
            flatland.surface(nk=1000, np=1000)
        except KeyboardInterrupt:
            print("interrupted after", time.monotonic() - t, flush=True)
            print(flatland.solve(period=1.181)["k"], flush=True)
            sys.exit(0)
        sys.exit(3)
    """)
    env = dict(os.environ)
    p = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True,
                         env=env)
    assert p.stdout.readline().strip() == "ready"
    time.sleep(1.0)
    p.send_signal(signal.SIGINT)
    try:
        out, _ = p.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        p.kill()
        pytest.fail("SIGINT did not stop flatland.surface within 30 s")
    assert p.returncode == 0, out
    assert "interrupted after" in out
    assert abs(float(out.strip().splitlines()[-1]) + 1.1393) < 5e-4


def test_an_unknown_study():
    with pytest.raises(ValueError, match="name: unknown study 'fast'"):
        flatland.study("fast")
