#!/usr/bin/env bash
# The tests, after scripts/setup.sh has built build/:
#   1. the GoogleTest suite on the Release build (build/);
#   2. the Python suite (pytest, python/tests) against build/python, and the examples (examples/);
#      then `pip install .` (pyproject.toml, reusing build/) into a virtual environment, imported
#      from another folder;
#   3. the install: build/ installed into a temporary prefix, a downstream project built against it
#      with find_package(flatland), and it and the installed CLI run (tests/downstream/check.sh);
#   3b. the sweeps on Open MPI (tests/mpi): mpirun -np 2 and 3 of montecarlo, study closed-loop,
#      surface and locus write what one process writes, a killed rank and bad launches give one
#      line, and mpi4py.futures spreads flatland.experiment calls;
#   4. the same suite built with AddressSanitizer + UndefinedBehaviorSanitizer (build-asan/,
#      -O1, no benchmarks; built beside stages 2-3b): any memory error, leak or undefined behaviour
#      fails the test;
# The libFuzzer targets (fuzz/) run over their seeds and kept reproducers inside the suite
# (FuzzTargets.*, built with GCC, sanitized in stage 4); fuzzing itself is by hand (docs/DEVELOPING.md).
# docs/DEVELOPING.md explains each stage and how to run it alone.
#
# Usage: scripts/test.sh [--no-sanitizers]
set -euo pipefail

usage() { echo "usage: scripts/test.sh [--no-sanitizers]" >&2; }
sanitizers=1
for arg in "$@"; do
  case "$arg" in
    --no-sanitizers) sanitizers=0 ;;
    -h|--help) usage; exit 0 ;;
    *) echo "test: unknown argument: $arg" >&2; usage; exit 2 ;;
  esac
done

log() { echo "test: $*" >&2; }
cd "$(dirname "${BASH_SOURCE[0]}")/.."
root=$(pwd)
jobs=$(nproc)

log "stage 1: ctest --test-dir build"
# Every test has its own temporary directory and no test measures time, so they run in parallel.
ctest --test-dir build --output-on-failure -j"$jobs"

# The sanitizer stage's options: for its build too, whose test discovery runs the sanitized test
# programs.
sanitizer_options() {
  # Leaks are checked; the suppressions name third-party libraries only (see the file).
  # intercept_tls_get_addr=0: GCC 12's ASan records each dynamic-TLS block that __tls_get_addr hands
  # out (e.g. libLLVM's, loaded with OSMesa) and, for a block whose address is 16 mod 4096, trusts a guessed
  # glibc header in front of it; LeakSanitizer's exit-time check then scans a garbage range and its
  # tracer crashes after the test has passed ("Tracer caught signal 11 ... LeakSanitizer has encountered
  # a fatal error"), at random (the heap addresses vary). Without the interception the blocks are
  # still found: they are heap blocks reachable from each thread's DTV.
  # detect_stack_use_after_return=0: its fake stack frames cost the sanitizer stage's tests about a
  # quarter of their time, and call-heavy numerical code more (2026-11-29, GCC 12: a spatial test
  # 29.2 s with them against 20.4 s without, the closed-loop estimator test 56 s against 41 s, a
  # rendered calibration 31.0 s either way). Use after scope is still detected, and -Wall's
  # -Wreturn-local-addr and -Wdangling-pointer catch a returned local's address at compile time.
  # quarantine_size_mb=64 (a quarter of the default): a freed block stays poisoned until 64 MB more
  # have been freed after it, some 70 camera frames. With 256 MB every allocation touched fresh pages
  # for longer: a closed-loop Monte Carlo 5.4 s against 4.9-5.1 s with 64 MB (2026-11-29, 119 000
  # against 85 000 page faults); the other tests measured as before.
  export ASAN_OPTIONS="detect_leaks=1:detect_stack_use_after_return=0:intercept_tls_get_addr=0:quarantine_size_mb=64"
  export LSAN_OPTIONS="suppressions=$root/tests/sanitizers/lsan.supp:print_suppressions=0"
  export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
}

# The sanitizer stage's build (build-asan/).
build_sanitized() {
  # -g1: line tables are all the sanitizers' stack traces need, and full debug information would
  # make this build (the longest step of CI) markedly slower.
  # UBSan's alignment and null checks are left out everywhere: they double the compile time of
  # Eigen-heavy code (test_calibration_chain.cpp: 24 s, 13 s without them and vptr, 12 s with ASan
  # alone; sim/src/spatial_run.cpp: 161 s, 89 s without them, 89 s with ASan alone). A null access
  # still faults under ASan, and x86 reads misaligned data correctly. The test programs and the
  # CLI's programs also skip vptr, which checks a polymorphic object's dynamic type: the libraries'
  # own code is still checked for it.
  cmake -S . -B build-asan -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1" -DFLATLAND_SANITIZE=address,undefined \
    -DFLATLAND_NO_SANITIZE=alignment,null -DFLATLAND_TESTS_AND_APPS_CXX_FLAGS="-fno-sanitize=vptr" \
    -DFLATLAND_BUILD_BENCHMARKS=OFF -DFLATLAND_BUILD_PYTHON=OFF -DFLATLAND_MPI=OFF || return
  cmake --build build-asan -j"$jobs"
}

# The stages below leave a core idle much of the time (one pytest process, pip, a small project's
# build, MPI jobs that wait for their ranks), so the sanitizer build runs beside them, its output
# kept until stage 4. It has a process group of its own, so that an early exit stops all of it.
venv_dir=$(mktemp -d)
asan_log=$(mktemp)
asan_pid=
cleanup() {
  if [ -n "$asan_pid" ]; then kill -- -"$asan_pid" 2>/dev/null || true; fi
  rm -rf "$venv_dir" "$asan_log"
}
trap cleanup EXIT
if [ "$sanitizers" -eq 1 ]; then
  log "stage 4's build: AddressSanitizer + UndefinedBehaviorSanitizer in build-asan/, beside stages 2-3b"
  set -m
  (sanitizer_options; build_sanitized) > "$asan_log" 2>&1 &
  asan_pid=$!
  set +m
fi

log "stage 2: the Python module's suite (pytest) and examples, with Debian's python3"
# Debian's numpy and pybind11 are /usr/bin/python3's (python/CMakeLists.txt); a pyenv or venv
# python3 earlier on PATH would not find them.
python=$(sed -n 's/^Python3_EXECUTABLE:FILEPATH=//p' build/CMakeCache.txt)
PYTHONPATH="$root/build/python" MPLBACKEND=Agg "${python:-/usr/bin/python3}" -m pytest -q -rs \
  -p no:cacheprovider python/tests

log "stage 2: pip install . into a virtual environment, and import flatland from elsewhere"
# As a Python user installs it (README, docs/PYTHON.md): a venv that sees Debian's numpy, and pip
# without build isolation. The backend (pyproject.toml) reuses build/: nothing is compiled again.
/usr/bin/python3 -m venv --system-site-packages "$venv_dir/v"
"$venv_dir/v/bin/pip" install -q --no-build-isolation . >&2
(cd "$venv_dir" && env -u PYTHONPATH -u FLATLAND_DATA_DIR v/bin/python -c \
  "import flatland; flatland.solve(period=1.181); print('test: installed', flatland.__file__)" >&2)

log "stage 3: install into a temporary prefix, and a find_package(flatland) project against it"
bash tests/downstream/check.sh build

log "stage 3b: the sweeps on Open MPI (pytest tests/mpi)"
FLATLAND_BUILD_DIR="$root/build" /usr/bin/python3 -m pytest -q -rs -p no:cacheprovider tests/mpi

[ "$sanitizers" -eq 1 ] || { log "--no-sanitizers: done"; exit 0; }

log "stage 4: the AddressSanitizer + UndefinedBehaviorSanitizer build (started before stage 2)"
status=0
wait "$asan_pid" || status=$?
asan_pid=
cat "$asan_log" >&2
[ "$status" -eq 0 ] || { log "stage 4: the sanitizer build failed (exit $status)"; exit 1; }
sanitizer_options
# Sanitized code is several times slower; the tests are independent (each has its own temporary
# directory), so they run in parallel. The longest tests run the same code paths for less long
# here (tests/test_scale.hpp: FLATLAND_TEST_SHORT): the hour-long hold for 6 minutes, the Monte
# Carlo acceptance (400 whole experiments in stage 1) on 4 perturbed worlds, the thread-count
# test on 2, the closed-loop estimator's consistency on 3 worlds instead of 15, identify's fits
# one iteration each and its statistics of many fits not at all (docs/DEVELOPING.md lists which
# and what covers their code paths). The full lengths ran in stage 1.
export FLATLAND_TEST_SHORT=1 FLATLAND_MC_RUNS=4
# llvmpipe renders on the calling thread: each of its worker threads takes dynamic-TLS blocks,
# and before intercept_tls_get_addr=0 (above) that made the tracer crash reproducibly in one
# rendering test. flatland's code paths are the same either way.
export LP_NUM_THREADS=0
ctest --test-dir build-asan --output-on-failure -j"$jobs"

log "done"
