#!/usr/bin/env bash
# Create .venv and install manifoldgen with its test extras. torch==2.13.0 goes first, with exactly
# that spec: any other spec pulls the CUDA build (gigabytes); once it is there, the package's
# own `torch>=2.1` requirement is already satisfied.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=$(command -v python3.11 || command -v python3)
[ -x .venv/bin/python ] || "$PY" -m venv .venv
.venv/bin/python -m pip install --quiet --disable-pip-version-check torch==2.13.0
.venv/bin/python -m pip install --quiet --disable-pip-version-check -e ".[test]"
