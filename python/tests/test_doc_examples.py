"""The documentation's examples run as written: every fenced block of README.md's Python section,
docs/PYTHON.md and docs/CLI.md. Python blocks run under the build's module; shell blocks run with
bash (-e: every command must succeed) with the build's bin/ first on PATH. Both run in a temporary
folder that looks like the repository's root to them (assets/, examples/ and build/ linked
there), so that what they write stays there. A block that cannot run here says so in its info
string, ```sh not-run: WHY; those are listed (pytest -rs shows them)."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import BUILD, ROOT

RUNNERS = {"python": [sys.executable, "-"], "sh": ["bash", "-e", "-o", "pipefail", "-s"]}


def section(text: str, heading: str) -> str:
    """The part of a Markdown text under `heading` (a '## ' line), to the next '## '."""
    start = text.index(heading + "\n")
    end = text.find("\n## ", start + len(heading))
    return text[start:end if end >= 0 else len(text)]


def blocks(path: Path, text: str):
    """(id, info string, code) of each fenced block."""
    found = []
    for m in re.finditer(r"^```([^\n]*)\n(.*?)^```", text, flags=re.S | re.M):
        line = text[:m.start()].count("\n") + 1
        found.append((f"{path.relative_to(ROOT)}:{line}", m.group(1).strip(), m.group(2)))
    return found


def doc_blocks():
    readme = (ROOT / "README.md").read_text()
    found = blocks(ROOT / "README.md", section(readme, "## Python"))
    # Line numbers of the README's section are counted from the section's start: shift them.
    offset = readme[:readme.index("## Python\n")].count("\n")
    found = [(f"README.md:{int(i.split(':')[1]) + offset}", info, code)
             for i, info, code in found]
    for name in ("PYTHON.md", "CLI.md"):
        path = ROOT / "docs" / name
        found += blocks(path, path.read_text())
    return found


BLOCKS = doc_blocks()


def test_every_block_is_runnable_or_says_why_not():
    for block_id, info, _ in BLOCKS:
        language = info.split()[0] if info else ""
        if "not-run" in info:
            assert re.search(r"not-run: \S", info), f"{block_id}: not-run needs a reason"
        else:
            assert language in RUNNERS, f"{block_id}: ```{info} is neither run nor not-run"


@pytest.fixture
def root_like(tmp_path):
    """A folder that looks like the repository root: assets/, examples/ and build/ linked."""
    for name, target in (("assets", ROOT / "assets"), ("examples", ROOT / "examples"),
                         ("build", BUILD)):
        (tmp_path / name).symlink_to(target)
    return tmp_path


@pytest.mark.parametrize("block_id, info, code", BLOCKS, ids=[b[0] for b in BLOCKS])
def test_the_example_runs(block_id, info, code, root_like):
    if "not-run" in info:
        pytest.skip(f"{block_id}: {info[info.index('not-run'):]}")
    env = dict(os.environ, MPLBACKEND="Agg", PATH=f"{BUILD / 'bin'}:{os.environ['PATH']}",
               PYTHONPATH=str(BUILD / "python"))
    p = subprocess.run(RUNNERS[info.split()[0]], input=code, capture_output=True, text=True,
                       cwd=root_like, env=env, timeout=900)
    assert p.returncode == 0, f"{block_id} exited {p.returncode}:\n{code}\n{p.stderr[-3000:]}"
