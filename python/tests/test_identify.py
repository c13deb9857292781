"""flatland.identify and flatland.validate_world: recordings as numpy arrays in, values, sigmas and
the correlation as numpy arrays out; bad recordings are a ValueError naming the keyword."""

import numpy as np
import pytest

import flatland
from conftest import SCENES

AIRTABLE = SCENES / "airtable-5deg.yaml"


def recording(n=20, **changes):
    t = np.linspace(0.0, 1.9, n)
    rec = {"t": t, "theta": 0.1 * t, "s_h": -1 + 0.01 * t, "sigma": 1e-3}
    rec.update(changes)
    return rec


@pytest.mark.parametrize("changes, message", [
    ({"sigma": None}, "recordings[0].sigma: a number"),
    ({"t": np.zeros((4, 2))}, "recordings[0].t: a 1-D array, got shape (4, 2)"),
    ({"s_h": "abc"}, "recordings[0].s_h: an array of numbers"),
    ({"theta": np.zeros(3)}, "recordings[0].theta: 3 values for 20 times"),
    ({"joint_t": np.arange(5.0)}, "recordings[0]: theta or joint_t and joint_theta, not both"),
    ({"speed": 1}, "recordings[0]: unknown key 'speed'"),
])
def test_bad_recordings_name_the_keyword(changes, message):
    with pytest.raises(ValueError) as e:
        flatland.identify(AIRTABLE, recording(**changes), ["drag"])
    assert message in str(e.value)


def test_a_recording_without_sigma_is_refused():
    rec = recording()
    del rec["sigma"]
    with pytest.raises(ValueError, match=r"recordings\[0\]\.sigma: missing"):
        flatland.identify(AIRTABLE, rec, ["drag"])


def test_the_librarys_checks_name_the_recording():
    t = np.linspace(0.0, 1.9, 20)
    t[5] = t[4]
    with pytest.raises(ValueError, match=r"recordings\[0\]"):
        flatland.identify(AIRTABLE, recording(t=t), ["drag"])
    with pytest.raises(ValueError, match=r"recordings: a dict or a non-empty list"):
        flatland.identify(AIRTABLE, [], ["drag"])
    with pytest.raises(ValueError, match=r"unknowns: a list of str"):
        flatland.identify(AIRTABLE, recording(), "drag")
    with pytest.raises(ValueError, match=r"bounds.drag: a pair"):
        flatland.identify(AIRTABLE, recording(), ["drag"], bounds={"drag": 1.0})
    with pytest.raises(ValueError, match=r"validate.t: missing"):
        flatland.identify(AIRTABLE, recording(), ["drag"], validate={"s_h": [1.0]})


def synthetic_recording(scene, t_end, rate=30.0, sigma=2e-3, seed=1):
    """The scene's own world simulated and sampled at `rate` Hz, with Gaussian noise of `sigma`
    on s_h: a recording whose truth is the scene's parameters."""
    sim = flatland.simulate(scene, duration=t_end, sample_dt=1.0 / rate)
    tr = sim.trajectory
    rng = np.random.default_rng(seed)
    return {"t": tr["t"], "theta": tr["theta"],
            "s_h": tr["s_h"] + rng.normal(0.0, sigma, tr["t"].shape), "sigma": sigma}


def test_identify_recovers_the_worlds_drag_and_writes_its_scene(tmp_path):
    """The air-table world's drag (0.015 N s/m) from its own motion with noise, started at twice
    the truth: within 3 sigma, a finite sigma, and the fitted scene carries the value."""
    rec = synthetic_recording(AIRTABLE, 4.0)
    out = flatland.identify(AIRTABLE, rec, ["drag"], initial={"drag": 0.03})
    assert out["names"] == ["drag"]
    assert isinstance(out["values"], np.ndarray) and out["values"].shape == (1,)
    assert out["correlation"].shape == (1, 1)
    assert bool(out["determined"][0]), out["not_determined"]
    drag, sigma = out["values"][0], out["sigmas"][0]
    assert 0 < sigma < 0.015
    assert abs(drag - 0.015) < 3 * sigma, (drag, sigma)
    assert out["correlation"][0, 0] == pytest.approx(1.0)
    # chi^2 of noise of the stated sigma: about its degrees of freedom, below its 99 % quantile,
    # so sigma is not scaled; the fit converged and held nothing.
    assert out["degrees_of_freedom"] > 0
    assert out["chi2"] / out["degrees_of_freedom"] < 2.0
    assert out["chi2"] < out["chi2_limit"]
    assert out["sigma_scale"] == 1.0
    np.testing.assert_array_equal(out["sigmas_unscaled"], out["sigmas"])
    assert not out["held"].any()
    assert out["converged"] and out["termination_type"] == "CONVERGENCE"
    # Converged means at a minimum: the Gauss-Newton step there moves no value by 0.3 sigma.
    assert out["steps_to_minimum"].shape == out["values"].shape
    steps_in_sigma = np.abs(out["steps_to_minimum"]) / out["sigmas"]
    assert out["step_in_sigma"] == pytest.approx(np.max(steps_in_sigma))
    assert out["step_in_sigma"] <= 0.3 and out["chi2_decrease_expected"] >= 0
    assert isinstance(out["warnings"], list)
    assert out["validation"] is None
    fits = out["fits"][0]
    assert fits["t"].shape == fits["measured"].shape == fits["fitted"].shape
    # The fitted scene carries the value, to the last bit, and loads.
    scene = out["scene"]
    line = next(l for l in scene.splitlines() if l.strip().startswith("drag:"))
    assert float(line.split(":")[1].split("#")[0]) == drag
    assert "identified:" in line
    path = tmp_path / "fitted.yaml"
    path.write_text(scene)
    assert flatland.load(path).origin == str(path)


def test_validate_world_predicts_its_own_recording():
    """The world that made a recording predicts it to within its noise."""
    rec = synthetic_recording(AIRTABLE, 2.0, sigma=1e-3, seed=3)
    check = flatland.validate_world(AIRTABLE, rec)
    assert check["t"].shape == check["error"].shape
    np.testing.assert_allclose(check["error"], check["predicted"] - check["measured"])
    assert check["rms_error"] < 3e-3
    assert check["stopped"] is None
