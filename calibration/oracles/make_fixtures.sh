#!/usr/bin/env bash
# Regenerates calibration/fixtures/lens/ with the real libraries in a private venv.
# OpenCV 4.x from PyPI (opencv-python-headless); mrcal 2.5 from PyPI, which needs Python ≥ 3.12
# (the machine's pyenv has one) and is installed without its GUI dependencies (pyfltk does not
# build), plus the libraries it imports.
set -euo pipefail
cd "$(dirname "$0")/../.."
venv=target/oracle-venv
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install -q "opencv-python-headless>=4.10,<5" "numpy<3"
fi
"$venv/bin/python" calibration/oracles/opencv_lens.py calibration/fixtures/lens
mkdir -p calibration/fixtures/calibration
"$venv/bin/python" calibration/oracles/opencv_calibration.py calibration/fixtures/calibration

py312=$(command -v python3.12 || ls /root/.pyenv/versions/3.1[2-9]*/bin/python 2>/dev/null | head -1 || true)
if [ -z "$py312" ]; then
  echo "no Python >= 3.12: mrcal fixtures left as they are" >&2
  exit 0
fi
mvenv=target/mrcal-venv
if [ ! -x "$mvenv/bin/python" ]; then
  "$py312" -m venv "$mvenv"
  "$mvenv/bin/pip" install -q --no-deps "mrcal>=2.5,<2.6"
  "$mvenv/bin/pip" install -q numpy numpysane gnuplotlib scipy
fi
"$mvenv/bin/python" calibration/oracles/mrcal_lens.py calibration/fixtures/lens
