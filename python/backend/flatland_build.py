"""The PEP 517 build backend of the Python package flatland (pyproject.toml, docs/PYTHON.md).

``pip install .`` calls it. It builds the native module with the project's own CMake build, the
same one ``scripts/setup.sh`` makes, and packs what that build put into ``<build>/python/flatland``
(the package, its native module and its stubs) with the bundled data (assets/, as
``flatland/data``) into a wheel. Only the module's target and the libraries it links are built;
an existing build directory is reused as it is, so that a clone that ``scripts/setup.sh`` has
built installs in seconds (CI), and a clean clone configures one without tests or benchmarks.

The build directory: the config setting ``build-dir`` (``pip install --config-settings
build-dir=DIR .``; pip 23.0 has no ``-C``), else the environment variable ``FLATLAND_BUILD_DIR``,
else ``build/`` in the source tree; a relative path is taken from the source tree. ``jobs``: the
build's parallel jobs (default: every core). The module is built for the interpreter that runs
pip (its base interpreter in a virtual environment): Debian's pybind11 and numpy belong to
``/usr/bin/python3``.

Nothing here needs anything beyond the standard library, CMake and Ninja: no setuptools, and no
download in an isolated build either.
"""

from __future__ import annotations

import base64
import hashlib
import io
import os
import re
import shutil
import subprocess
import sys
import sysconfig
import tarfile
import zipfile
from pathlib import Path
from typing import Dict, List, Optional, Tuple

SOURCE = Path(__file__).resolve().parents[2]
NAME = "flatland"
SUMMARY = ("The FLATLAND butterfly: rolling dynamics, headless camera rendering, tracking, "
           "calibration and the vision-feedback closed loop")
# The module's target and the copy of its Python files (python/CMakeLists.txt).
TARGETS = ("flatland_python", "flatland_python_files")


class BuildError(RuntimeError):
    """A build that cannot go on; its message is one line saying why and what to do."""


def _version() -> str:
    text = (SOURCE / "CMakeLists.txt").read_text()
    m = re.search(r"project\(\s*flatland\s+VERSION\s+([0-9][0-9.]*)", text)
    if not m:
        raise BuildError("CMakeLists.txt: no `project(flatland VERSION x.y.z)` line")
    return m.group(1)


def _python_tag() -> str:
    if sys.implementation.name != "cpython":
        raise BuildError(f"the native module is built for CPython, not {sys.implementation.name}")
    return f"cp{sys.version_info.major}{sys.version_info.minor}"


def _wheel_tag() -> str:
    platform = sysconfig.get_platform().replace("-", "_").replace(".", "_")
    return f"{_python_tag()}-{_python_tag()}-{platform}"


def _base_interpreter() -> str:
    """The interpreter itself, not a virtual environment's link to it: CMake's cache keeps it."""
    return os.path.realpath(getattr(sys, "_base_executable", None) or sys.executable)


SETTINGS = ("build-dir", "jobs")


def _check_settings(config_settings: Optional[Dict[str, str]]) -> None:
    for key, value in (config_settings or {}).items():
        if key not in SETTINGS:
            raise BuildError(f"config setting {key}: unknown ({', '.join(SETTINGS)})")
        if key == "jobs" and not (isinstance(value, str) and value.isdigit() and int(value) > 0):
            raise BuildError(f"config setting jobs: a positive integer, got {value!r}")
        if key == "build-dir" and not (isinstance(value, str) and value):
            raise BuildError(f"config setting build-dir: a directory, got {value!r}")


def _build_dir(config_settings: Optional[Dict[str, str]]) -> Path:
    chosen = (config_settings or {}).get("build-dir") or os.environ.get("FLATLAND_BUILD_DIR")
    path = Path(chosen) if chosen else Path("build")
    return path if path.is_absolute() else SOURCE / path


def _cache(build: Path) -> Dict[str, str]:
    values = {}
    for line in (build / "CMakeCache.txt").read_text(errors="replace").splitlines():
        m = re.match(r"([A-Za-z0-9_.+-]+):[A-Z]+=(.*)$", line)
        if m:
            values[m.group(1)] = m.group(2)
    return values


def _run(command: List[str]) -> None:
    # CMake's Python must see the base interpreter's packages (Debian's numpy): an isolated build's
    # PYTHONPATH and PYTHONNOUSERSITE would hide them from it.
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONNOUSERSITE",
                                                              "PYTHONHOME")}
    print("flatland_build:", " ".join(command), file=sys.stderr, flush=True)
    if subprocess.run(command, env=env, stdout=sys.stderr).returncode != 0:
        raise BuildError(f"`{' '.join(command)}` failed (its output is above)")


def _check_cache(build: Path) -> None:
    """An existing build directory must be this source tree's, with the module, built for this
    Python, without sanitizers (an instrumented module cannot load into a plain interpreter)."""
    cache = _cache(build)
    home = cache.get("CMAKE_HOME_DIRECTORY", "")
    if home and Path(home).resolve() != SOURCE:
        raise BuildError(f"build-dir {build}: configured for the sources in {home}, not {SOURCE}; "
                         "give another build-dir (pip install --config-settings build-dir=DIR .)")
    if cache.get("FLATLAND_BUILD_PYTHON", "ON").upper() in ("OFF", "0", "FALSE", "NO"):
        raise BuildError(f"build-dir {build}: configured with FLATLAND_BUILD_PYTHON=OFF; "
                         "reconfigure it with -DFLATLAND_BUILD_PYTHON=ON or give another build-dir")
    if cache.get("FLATLAND_SANITIZE") or cache.get("FLATLAND_FUZZ", "OFF").upper() == "ON":
        raise BuildError(f"build-dir {build}: a sanitizer or fuzzing build, whose module cannot be "
                         "imported by a plain interpreter; give another build-dir")
    configured = cache.get("Python3_EXECUTABLE", "")
    if configured and os.path.realpath(configured) != _base_interpreter():
        # The same interpreter under another name (python3 -> python3.11) is fine; another
        # version is not, which the module's file name (its EXT_SUFFIX) tells after the build.
        probe = subprocess.run([configured, "-c", "import sysconfig; "
                                "print(sysconfig.get_config_var('EXT_SUFFIX'))"],
                               capture_output=True, text=True)
        if probe.stdout.strip() != sysconfig.get_config_var("EXT_SUFFIX"):
            raise BuildError(f"build-dir {build}: builds the module for {configured}, but pip runs "
                             f"{_base_interpreter()} (Python {sys.version.split()[0]}); run pip "
                             "with that interpreter or give another build-dir")


def _build_module(config_settings: Optional[Dict[str, str]]) -> Path:
    """Configure (if needed) and build the module; the directory holding the package."""
    _check_settings(config_settings)
    if shutil.which("cmake") is None:
        raise BuildError("cmake is not on PATH (Debian: apt-get install cmake ninja-build; "
                         "scripts/setup.sh installs every package the build needs)")
    build = _build_dir(config_settings)
    if (build / "CMakeCache.txt").is_file():
        _check_cache(build)
    else:
        generator = ["-G", "Ninja"] if shutil.which("ninja") else []
        _run(["cmake", "-S", str(SOURCE), "-B", str(build), *generator,
              "-DCMAKE_BUILD_TYPE=Release", "-DFLATLAND_BUILD_TESTS=OFF",
              "-DFLATLAND_BUILD_BENCHMARKS=OFF", "-DFLATLAND_BUILD_PYTHON=ON",
              f"-DPython3_EXECUTABLE={_base_interpreter()}"])
    jobs = (config_settings or {}).get("jobs") or str(os.cpu_count() or 1)
    _run(["cmake", "--build", str(build), "-j", jobs, "--target", *TARGETS])
    package = build / "python" / NAME
    native = package / f"_flatland{sysconfig.get_config_var('EXT_SUFFIX')}"
    if not native.is_file():
        raise BuildError(f"build-dir {build}: no {native.name} after the build (a module for "
                         "another Python?); give another build-dir")
    return package


def _metadata() -> str:
    return (f"Metadata-Version: 2.1\nName: {NAME}\nVersion: {_version()}\nSummary: {SUMMARY}\n"
            "Requires-Python: >=3.9\nRequires-Dist: numpy\nLicense: see the repository\n")


def _wheel_file() -> str:
    return (f"Wheel-Version: 1.0\nGenerator: flatland_build\nRoot-Is-Purelib: false\n"
            f"Tag: {_wheel_tag()}\n")


def _dist_info() -> str:
    return f"{NAME}-{_version()}.dist-info"


def _package_files(package: Path) -> List[Tuple[str, Path]]:
    """(path in the wheel, file): the build's package (no bytecode) and assets/ as flatland/data."""
    files = [(f"{NAME}/{p.relative_to(package).as_posix()}", p)
             for p in sorted(package.rglob("*"))
             if p.is_file() and "__pycache__" not in p.parts]
    assets = SOURCE / "assets"
    files += [(f"{NAME}/data/{p.relative_to(assets).as_posix()}", p)
              for p in sorted(assets.rglob("*")) if p.is_file()]
    return files


def _record_line(name: str, data: bytes) -> str:
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
    return f"{name},sha256={digest},{len(data)}"


# PEP 517 hooks.

def get_requires_for_build_wheel(config_settings=None):
    return []


def get_requires_for_build_sdist(config_settings=None):
    return []


def prepare_metadata_for_build_wheel(metadata_directory, config_settings=None):
    info = Path(metadata_directory) / _dist_info()
    info.mkdir(parents=True, exist_ok=True)
    (info / "METADATA").write_text(_metadata())
    (info / "WHEEL").write_text(_wheel_file())
    return info.name


def build_wheel(wheel_directory, config_settings=None, metadata_directory=None):
    try:
        package = _build_module(config_settings)
    except BuildError as e:
        # One line for the user: pip prints the backend's stderr and its own summary.
        print(f"flatland_build: error: {e}", file=sys.stderr, flush=True)
        raise SystemExit(1) from None
    name = f"{NAME}-{_version()}-{_wheel_tag()}.whl"
    target = Path(wheel_directory) / name
    info = _dist_info()
    record = []
    with zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as wheel:
        entries = [(arc, path.read_bytes()) for arc, path in _package_files(package)]
        entries += [(f"{info}/METADATA", _metadata().encode()),
                    (f"{info}/WHEEL", _wheel_file().encode()),
                    (f"{info}/top_level.txt", f"{NAME}\n".encode())]
        for arc, data in entries:
            info_entry = zipfile.ZipInfo(arc, date_time=(1980, 1, 1, 0, 0, 0))
            # Keep the executable bit of the native module (unzip and pip honour it).
            info_entry.external_attr = (0o755 if arc.endswith(".so") else 0o644) << 16
            info_entry.compress_type = zipfile.ZIP_DEFLATED
            wheel.writestr(info_entry, data)
            record.append(_record_line(arc, data))
        record.append(f"{info}/RECORD,,")
        wheel.writestr(zipfile.ZipInfo(f"{info}/RECORD", date_time=(1980, 1, 1, 0, 0, 0)),
                       "\n".join(record) + "\n")
    return name


def build_editable(wheel_directory, config_settings=None, metadata_directory=None):
    """`pip install -e .` is refused in one line: the native module lives in the CMake build tree,
    which an editable install cannot point at; PYTHONPATH=build/python is the editable form."""
    print("flatland_build: error: editable installs (pip install -e) are not supported: put "
          "build/python on PYTHONPATH instead (docs/PYTHON.md)", file=sys.stderr, flush=True)
    raise SystemExit(1)


def build_sdist(sdist_directory, config_settings=None):
    """The files git tracks (an sdist of a clean checkout), with PKG-INFO."""
    listing = subprocess.run(["git", "-C", str(SOURCE), "ls-files", "-z"], capture_output=True)
    if listing.returncode != 0:
        print("flatland_build: error: an sdist is made from a git checkout (git ls-files failed)",
              file=sys.stderr)
        raise SystemExit(1)
    base = f"{NAME}-{_version()}"
    name = f"{base}.tar.gz"
    with tarfile.open(Path(sdist_directory) / name, "w:gz", format=tarfile.PAX_FORMAT) as tar:
        for rel in sorted(p for p in listing.stdout.decode().split("\0") if p):
            path = SOURCE / rel
            if path.is_file() or path.is_symlink():
                tar.add(path, arcname=f"{base}/{rel}", recursive=False)
        pkg_info = _metadata().encode()
        entry = tarfile.TarInfo(f"{base}/PKG-INFO")
        entry.size = len(pkg_info)
        tar.addfile(entry, io.BytesIO(pkg_info))
    return name
