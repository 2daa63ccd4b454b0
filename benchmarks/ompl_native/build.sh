#!/usr/bin/env bash
# Build the C++ OMPL baseline into benchmarks/ompl_native/build/ompl_native, and OMPL's sphere demo
# program into build/sphere_demo (optional extras:
# manifoldgen runs without them). Needs Debian's libompl-dev (OMPL 1.5, with Eigen 3.4 and Boost 1.74),
# cmake, g++ and the `pin` wheel in the Python environment given as $PYTHON (default .venv/bin/python).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
python="${PYTHON:-$here/../../.venv/bin/python}"
prefix="$("$python" -c 'import sysconfig, pathlib; print(pathlib.Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix")')"
[ -d "$prefix" ] || { echo "build.sh: no cmeel.prefix at $prefix; pip install pin into $python's environment" >&2; exit 1; }
generator=(); command -v ninja >/dev/null && generator=(-G Ninja)
cmake -S "$here" -B "$here/build" "${generator[@]}" -DCMEEL_PREFIX="$prefix" -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$here/build"
