#!/usr/bin/env bash
# Regenerates the single-channel reader fixtures in calibration/fixtures/interop/: what
# OpenImageIO (ST-map EXR), OpenCV (2d PFM) and ffmpeg's `remap` filter (xmap/ymap PGM) show when
# they read the centre channel's exports of the fixture rig, which tests/core/interop.rs compares
# today's exports against. Everything comes from the registries: ffmpeg from Debian, OpenCV,
# OpenImageIO, numpy and Pillow from PyPI.
#
# Usage: calibration/interop/make_channel_fixtures.sh
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
cd "$here/../.."
out=calibration/fixtures/interop
command -v ffmpeg >/dev/null || { apt-get update -qq && apt-get install -y -qq ffmpeg; }
python3 -m pip install -q opencv-python-headless OpenImageIO numpy Pillow
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cargo build --release --quiet
ow=target/release/omniwarp
rig="$out/rig.json"
canvas=(--projection equirect --hfov 360 --vfov 180 --content-size 1024x512)

"$ow" pattern --pattern smooth --size 1024x512 --out "$work/content.png"
"$ow" export --rig "$rig" --channel centre --format stmap "${canvas[@]}" --out "$work/stmap.exr"
"$ow" export --rig "$rig" --channel centre --format pfm2d "${canvas[@]}" --out "$work/pfm2d.pfm"
"$ow" export --rig "$rig" --channel centre --format remap "${canvas[@]}" \
  --out "$work/xmap.pgm" --ymap "$work/ymap.pgm"
python3 "$here/channel_readers.py" "$work/content.png" "$work/stmap.exr" "$work/pfm2d.pfm" \
  "$work/"
cp "$work/oiio-stmap.png" "$out/oiio-stmap-centre.png"
cp "$work/opencv-pfm2d.png" "$out/opencv-pfm2d-centre.png"
ffmpeg -nostdin -loglevel error -y -i "$work/content.png" -i "$work/xmap.pgm" -i "$work/ymap.pgm" \
  -lavfi "[0:v]format=rgb24[c];[c][1:v][2:v]remap=fill=black" -frames:v 1 \
  "$out/ffmpeg-remap-centre.png"

# The references: the channel's warp rendered without its blend, bilinear and nearest.
"$ow" warp --rig "$rig" --channel centre --out "$work/warp.exr" >/dev/null
for filter in bilinear nearest; do
  "$ow" render --normal-map "$work/warp.exr" --content "$work/content.png" \
    --content-format equirect --filter "$filter" --out "$work/ref-$filter.png"
done
log="$out/CHANNEL-COMMANDS.txt"
{
  echo "# Made by calibration/interop/make_channel_fixtures.sh on $(date -u +%Y-%m-%d)"
  echo "# omniwarp $(git rev-parse --short HEAD); $(ffmpeg -version | head -1 | cut -d' ' -f1-3);" \
    "$(python3 -c 'import cv2, OpenImageIO as o; print("OpenCV", cv2.__version__, "OpenImageIO", o.__version__)')"
  echo "oiio-stmap centre vs omniwarp render: $(python3 "$here/psnr.py" "$work/ref-bilinear.png" "$out/oiio-stmap-centre.png")"
  echo "opencv-pfm2d centre vs omniwarp render: $(python3 "$here/psnr.py" "$work/ref-bilinear.png" "$out/opencv-pfm2d-centre.png")"
  echo "ffmpeg-remap centre vs omniwarp render --filter nearest: $(python3 "$here/psnr.py" "$work/ref-nearest.png" "$out/ffmpeg-remap-centre.png")"
} >"$log"
cat "$log"
