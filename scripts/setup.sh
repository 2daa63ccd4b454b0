#!/usr/bin/env bash
# Create .venv and install manifoldgen with every extra and the test tools. torch==2.13.0 goes first, with
# exactly that spec: any other spec pulls the CUDA build (gigabytes); once it is there, the package's own
# `torch>=2.1` requirement is already satisfied. The package install compiles the planning core (native/,
# the module manifoldgen_core) against the pin version the package requires (see pyproject.toml).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=$(command -v python3.11 || command -v python3)
[ -x .venv/bin/python ] || "$PY" -m venv .venv
.venv/bin/python -m pip install --quiet --disable-pip-version-check torch==2.13.0
# This environment is built on this machine for this machine: the decoder kernel uses its own instruction set
# (a wheel for other machines: `pip install .` alone, portable; MANIFOLDGEN_NATIVE_ARCH=OFF here does the same).
MANIFOLDGEN_NATIVE_ARCH="${MANIFOLDGEN_NATIVE_ARCH:-ON}" \
  .venv/bin/python -m pip install --quiet --disable-pip-version-check -e ".[all,test]"
# Debian's Chromium for the viewer's browser tests (they skip, saying why, where it cannot be installed)
if [ ! -x /usr/bin/chromium ] && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends chromium) \
    >/dev/null 2>&1 || echo "setup: chromium not installed; the browser tests will be skipped"
fi
# Optional benchmark extra: the C++ OMPL baseline (Debian's libompl-dev; `bench` methods ompl-native-*).
# Never fails the set-up: without it those methods say how to build it.
if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null && command -v cmake >/dev/null; then
  ( (dpkg -s libompl-dev >/dev/null 2>&1 || (apt-get update -qq && DEBIAN_FRONTEND=noninteractive \
      apt-get install -y -qq --no-install-recommends libompl-dev)) \
    && PYTHON=.venv/bin/python benchmarks/ompl_native/build.sh ) >/dev/null 2>&1 \
    || echo "setup: the C++ OMPL baseline was not built (optional; see benchmarks/ompl_native/README.md)"
fi
