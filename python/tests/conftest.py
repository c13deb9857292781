"""Fixtures of the Python suite: the CLI built beside the module (build/bin/flatland), whose
results the module's must equal, and the repository's paths."""

import json
import os
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BUILD = Path(os.environ.get("FLATLAND_BUILD_DIR", ROOT / "build"))
CLI = BUILD / "bin" / "flatland"
SCENES = ROOT / "assets" / "scenes"


def run_cli(*args, check=True):
    """The CLI's result: (exit code, stdout, stderr)."""
    p = subprocess.run([str(CLI), *map(str, args)], capture_output=True, text=True, timeout=600)
    if check and p.returncode != 0:
        raise AssertionError(f"flatland {' '.join(map(str, args))} exited {p.returncode}: "
                             f"{p.stderr}")
    return p.returncode, p.stdout, p.stderr


def cli_json(*args):
    return json.loads(run_cli(*args, "--json")[1])


@pytest.fixture(scope="session")
def cli():
    if not CLI.is_file():
        pytest.fail(f"{CLI} is missing: build the project first (scripts/setup.sh)")
    return CLI


def cli_error(*args):
    """The one-line error the CLI prints for bad input (exit 2), without its prefix."""
    code, _, err = run_cli(*args, check=False)
    assert code == 2, f"flatland {' '.join(map(str, args))} exited {code}, not 2: {err}"
    lines = [l for l in err.splitlines() if l.startswith("flatland: error: ")]
    assert len(lines) == 1, err
    return lines[0][len("flatland: error: "):]
