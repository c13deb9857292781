"""`pip install .` (pyproject.toml and its backend, python/backend/flatland_build.py): the
wheel holds the build's package and the bundled data, byte for byte, with a RECORD pip can check;
the user-site install imports from any folder; a build directory the module cannot come from is
refused in one line. (scripts/test.sh installs into a virtual environment on every CI run.)"""

import base64
import hashlib
import importlib.util
import json
import os
import subprocess
import sys
import sysconfig
import zipfile

import pytest

from conftest import BUILD, ROOT

EXT_SUFFIX = sysconfig.get_config_var("EXT_SUFFIX")


def backend():
    spec = importlib.util.spec_from_file_location(
        "flatland_build", ROOT / "python" / "backend" / "flatland_build.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def clean_env(**extra):
    """The environment of a user's shell: no PYTHONPATH to the build tree, no data override."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "FLATLAND_DATA_DIR", "FLATLAND_BUILD_DIR")}
    env.update(extra)
    return env


def test_the_wheel_holds_the_built_package_and_the_data(tmp_path):
    name = backend().build_wheel(str(tmp_path), {"build-dir": str(BUILD)})
    assert name == f"flatland-{backend()._version()}-{backend()._wheel_tag()}.whl"
    with zipfile.ZipFile(tmp_path / name) as wheel:
        names = set(wheel.namelist())
        package = BUILD / "python" / "flatland"
        for f in ("__init__.py", "_flatland.pyi", "py.typed", f"_flatland{EXT_SUFFIX}"):
            assert wheel.read(f"flatland/{f}") == (package / f).read_bytes(), f
        assets = [p for p in (ROOT / "assets").rglob("*") if p.is_file()]
        assert assets
        for p in assets:
            arc = f"flatland/data/{p.relative_to(ROOT / 'assets').as_posix()}"
            assert wheel.read(arc) == p.read_bytes(), arc
        info = [n for n in names if n.endswith(".dist-info/RECORD")]
        assert len(info) == 1
        record = wheel.read(info[0]).decode().splitlines()
        listed = {line.split(",")[0] for line in record}
        assert listed == names  # every file, RECORD itself included
        for line in record:
            path, digest, size = line.split(",")
            if path == info[0]:
                continue
            data = wheel.read(path)
            expected = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=")
            assert digest == "sha256=" + expected.decode() and int(size) == len(data), path


def test_a_user_site_install_imports_from_anywhere(tmp_path):
    user = tmp_path / "user"
    p = subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--user",
                        "--break-system-packages", "--no-build-isolation", "--no-deps",
                        "--config-settings", f"build-dir={BUILD}", str(ROOT)],
                       capture_output=True, text=True, timeout=600,
                       env=clean_env(PYTHONUSERBASE=str(user)))
    assert p.returncode == 0, p.stderr
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    script = ("import flatland; print(flatland.__file__); print(flatland.default_scene_path()); "
              "print(repr(flatland.solve(period=1.181)['k']))")
    p = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                       cwd=elsewhere, timeout=600, env=clean_env(PYTHONUSERBASE=str(user)))
    assert p.returncode == 0, p.stderr
    module, scene, k = p.stdout.splitlines()
    assert module.startswith(str(user)) and scene.startswith(str(user))
    # The same native code as the build tree's module: the same k to the last bit.
    import flatland
    assert float(k) == flatland.solve(period=1.181)["k"]


@pytest.mark.parametrize("settings, message", [
    ({"build_dir": "b"}, "config setting build_dir: unknown (build-dir, jobs)"),
    ({"jobs": "two"}, "config setting jobs: a positive integer, got 'two'"),
    ({"jobs": "0"}, "config setting jobs: a positive integer, got '0'"),
    ({"build-dir": ""}, "config setting build-dir: a directory, got ''"),
])
def test_bad_config_settings_are_refused(tmp_path, settings, message):
    script = ("import sys, json; sys.path.insert(0, sys.argv[1]); import flatland_build; "
              "flatland_build.build_wheel(sys.argv[2], json.loads(sys.argv[3]))")
    p = subprocess.run([sys.executable, "-c", script, str(ROOT / "python" / "backend"),
                        str(tmp_path), json.dumps(settings)], capture_output=True, text=True,
                       timeout=60)
    assert p.returncode == 1
    assert p.stderr.splitlines() == [f"flatland_build: error: {message}"]
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("cache, message", [
    ("CMAKE_HOME_DIRECTORY:INTERNAL=/elsewhere\n", "configured for the sources in /elsewhere"),
    ("FLATLAND_BUILD_PYTHON:BOOL=OFF\n", "configured with FLATLAND_BUILD_PYTHON=OFF"),
    ("FLATLAND_SANITIZE:STRING=address,undefined\n", "a sanitizer or fuzzing build"),
])
def test_a_build_dir_the_module_cannot_come_from_is_refused(tmp_path, cache, message):
    build = tmp_path / "build"
    build.mkdir()
    (build / "CMakeCache.txt").write_text(f"CMAKE_HOME_DIRECTORY:INTERNAL={ROOT}\n" + cache)
    script = ("import sys; sys.path.insert(0, sys.argv[1]); import flatland_build; "
              "flatland_build.build_wheel(sys.argv[2], {'build-dir': sys.argv[3]})")
    p = subprocess.run([sys.executable, "-c", script, str(ROOT / "python" / "backend"),
                        str(tmp_path), str(build)], capture_output=True, text=True, timeout=60)
    assert p.returncode == 1
    lines = p.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("flatland_build: error: build-dir ")
    assert message in lines[0]
    assert not list(tmp_path.glob("*.whl"))


def test_an_editable_install_is_refused_in_one_line(tmp_path):
    script = ("import sys; sys.path.insert(0, sys.argv[1]); import flatland_build; "
              "flatland_build.build_editable(sys.argv[2])")
    p = subprocess.run([sys.executable, "-c", script, str(ROOT / "python" / "backend"),
                        str(tmp_path)], capture_output=True, text=True, timeout=60)
    assert p.returncode == 1
    lines = p.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("flatland_build: error: editable installs")
    assert "PYTHONPATH" in lines[0]
    assert not list(tmp_path.iterdir())
