#!/usr/bin/env bash
# Regenerates calibration/fixtures/lens/ with the real libraries in a private venv.
# OpenCV 4.x from PyPI (opencv-python-headless). mrcal 2.5 needs Python ≥ 3.12, which this
# machine's registries do not offer; its fixtures wait for a machine that has it.
set -euo pipefail
cd "$(dirname "$0")/../.."
venv=target/oracle-venv
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install -q "opencv-python-headless>=4.10,<5" "numpy<3"
fi
"$venv/bin/python" calibration/oracles/opencv_lens.py calibration/fixtures/lens
