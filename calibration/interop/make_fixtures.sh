#!/usr/bin/env bash
# Regenerates calibration/fixtures/interop/: what two real MPCDI readers show when they read the
# packages omniwarp exports for them, which tests/core/interop.rs compares today's exports against.
#
#   PyMPCDI (github.com/drwrose/PyMPCDI, Python 2.7 + PyOpenGL), run unchanged under Xvfb and
#     Mesa by pympcdi_run.py; it renders one region of a 2d package and saves the frame.
#   The VESA/Scalable reference library (github.com/scaredyfish/MPCDI), which parses packages
#     but draws nothing: vesa_render.cpp reads the package through it and draws the region as
#     the MPCDI text says, so the library's parsing (region, PFM rows, 8-bit alpha) is what is
#     tested.
#
# Neither reader is fetched or built here: bring a checkout of PyMPCDI and a built VESA library
# (its own CMake build) and name them (checkouts without .git: also PYMPCDI_REV and VESA_REV):
#
#   PYMPCDI=/path/to/PyMPCDI VESA_SRC=/path/to/MPCDI VESA_LIB=/path/to/MPCDI-build/lib \
#     calibration/interop/make_fixtures.sh
#
# Also needs: python2.7 (pyenv's 2.7.18 here) with pip, python3 with numpy and Pillow, xvfb,
# g++; PyMPCDI's Python packages are installed from PyPI into a scratch directory.
set -euo pipefail
: "${PYMPCDI:?the PyMPCDI checkout}" "${VESA_SRC:?the VESA library source}" "${VESA_LIB:?its built lib directory}"
here=$(cd "$(dirname "$0")" && pwd)
cd "$here/../.."
out=calibration/fixtures/interop
python2=${PYTHON2:-$(pyenv prefix 2.7.18 2>/dev/null || echo /usr)/bin/python2.7}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cargo build --release --quiet
ow=target/release/omniwarp

"$python2" -m pip install -q --target "$work/site" Pillow==6.2.2 PyOpenGL==3.1.0 numpy==1.16.6
inc=()
for d in "$VESA_SRC"/src "$VESA_SRC"/src/*/ "$VESA_LIB"/../src; do inc+=("-I$d"); done
g++ -O2 -std=c++17 "$here/vesa_render.cpp" "${inc[@]}" -L"$VESA_LIB" -lmpcdi \
  -Wl,-rpath,"$VESA_LIB" -o "$work/vesa_render"

# The content: the chiral smooth pattern (a mirror or a swapped axis shows at once), on a
# 1024×512 equirect canvas; the rig: cylinder-270-3proj at a quarter of its resolution.
"$ow" pattern --pattern smooth --size 1024x512 --out "$work/content.png"
python3 -c "from PIL import Image; import sys; Image.open(sys.argv[1]).convert('RGB').save(sys.argv[2])" \
  "$work/content.png" "$work/content.ppm"
canvas=(--projection equirect --hfov 360 --vfov 180 --content-size 1024x512)

log="$out/COMMANDS.txt"
{
  echo "# Made by calibration/interop/make_fixtures.sh on $(date -u +%Y-%m-%d)"
  echo "# omniwarp $(git rev-parse --short HEAD); PyMPCDI ${PYMPCDI_REV:-$(git -C "$PYMPCDI" rev-parse --short HEAD)};" \
    "VESA library ${VESA_REV:-$(git -C "$VESA_SRC" rev-parse --short HEAD)}"
  echo "# $("$python2" --version 2>&1), PyOpenGL 3.1.0, Pillow 6.2.2, numpy 1.16.6; $(g++ --version | head -1)"
  echo "# content: omniwarp pattern --pattern smooth --size 1024x512 (sha256 $(sha256sum "$work/content.png" | cut -c1-64))"
  echo
} >"$log"
for reader in vesa pympcdi; do
  "$ow" export --rig "$out/rig.json" --format mpcdi "${canvas[@]}" --reader "$reader" \
    --out "$work/$reader.mpcdi" 2>>"$log"
done
for ch in left centre right; do
  "$ow" render --rig "$out/rig.json" --channel "$ch" --content "$work/content.png" \
    --content-format equirect --out "$work/ref-$ch.png"
  (cd "$PYMPCDI" && PYTHONPATH="$work/site" xvfb-run -a -s "-screen 0 1024x768x24" \
    "$python2" "$here/pympcdi_run.py" -m "$work/pympcdi.mpcdi" -r "$ch" \
    -i "$work/content.png" -o "$here/../../$out/pympcdi-$ch.png" >/dev/null)
  "$work/vesa_render" "$work/vesa.mpcdi" "$ch" "$work/content.ppm" "$work/vesa.pam" 2>>"$log"
  python3 "$here/pam2png.py" "$work/vesa.pam" "$out/vesa-$ch.png"
  for reader in pympcdi vesa; do
    echo "$reader $ch vs omniwarp render: $(python3 "$here/psnr.py" "$work/ref-$ch.png" "$out/$reader-$ch.png")" >>"$log"
  done
done
cat "$log"
