"""A scene's closed-loop choices through Python: an unknown controller.type or estimator.type, a
controller key of the wrong kind, a bad estimator.ukf key raise ValueError with the CLI's one-line
message (the field named, the known types listed); the unscented filter runs."""

import pytest

import flatland
from conftest import SCENES, cli_error


def scene_with(tmp_path, name, line, replacement):
    """The bundled closed-loop scene with one line replaced, written to tmp_path / name."""
    text = (SCENES / "airtable-feedback.yaml").read_text()
    assert text.count(line) == 1, line
    path = tmp_path / name
    path.write_text(text.replace(line, replacement))
    return path


@pytest.mark.parametrize("name, line, replacement, expected", [
    ("controller.yaml", "  mode: feedback ", "  type: pid\n  mode: feedback ",
     "controller.type: unknown type 'pid' (known: paper"),
    ("estimator.yaml", "  model: rolling ", "  type: particle\n  model: rolling ",
     "estimator.type: unknown type 'particle' (known: ekf, ukf)"),
    ("kp.yaml", "  kp: 900 ", '  kp: "fast" ', "controller.kp: expected a number, got the string"),
    ("alpha.yaml", "  latency_compensation: true",
     "  latency_compensation: true\n  ukf:\n    alpha: 2",
     "estimator.ukf.alpha: must be in [1e-04, 1], got 2"),
])
def test_a_bad_loop_choice_is_the_clis_value_error(cli, tmp_path, name, line, replacement,
                                                   expected):
    scene = scene_with(tmp_path, name, line, replacement)
    with pytest.raises(ValueError) as e:
        flatland.experiment(scene)
    message = str(e.value)
    assert expected in message and "\n" not in message
    assert message == cli_error("experiment", "--scene", scene, "--out", tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_the_unscented_filter_runs_from_a_scene(tmp_path):
    scene = scene_with(tmp_path, "ukf.yaml", "  model: rolling ", "  type: ukf\n  model: rolling ")
    e = flatland.experiment(scene)
    assert e["success"], e["failure"]
    # A consistent filter's time-averaged NEES (2 degrees of freedom) is about 2.
    assert e["nees_mean"] < 6
