"""Each example in examples/ runs to completion (no window) and writes its figures."""

import os
import subprocess
import sys

import pytest

from conftest import ROOT

EXAMPLES = {
    "fig6_fig7.py": (["--quick"], ["fig6.png", "fig7.png"]),
    "closed_loop_fig10.py": ([], ["fig10.png"]),
    "render_and_track.py": ([], ["tracking.png"]),
    "python_controller.py": ([], ["python_controller.png"]),
    "env_agent.py": ([], ["env_agent.png"]),
}


def test_every_example_is_run_here():
    assert sorted(p.name for p in (ROOT / "examples").glob("*.py")) == sorted(EXAMPLES)


@pytest.mark.parametrize("name", sorted(EXAMPLES))
def test_example_runs(name, tmp_path):
    args, figures = EXAMPLES[name]
    env = dict(os.environ, MPLBACKEND="Agg")
    p = subprocess.run([sys.executable, str(ROOT / "examples" / name), "--out", str(tmp_path),
                        *args], capture_output=True, text=True, timeout=600, env=env)
    assert p.returncode == 0, p.stderr
    for figure in figures:
        assert (tmp_path / figure).stat().st_size > 10_000, figure
