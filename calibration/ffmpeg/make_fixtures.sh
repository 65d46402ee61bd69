#!/usr/bin/env bash
# Regenerates calibration/fixtures/ffmpeg/: reference renders made by ffmpeg's v360 filter (the
# Debian package), which tests/core/peer_ffmpeg.rs compares omniwarp's renders against. The input is
# omniwarp's smooth procedural pattern: band-limited, so that two correct bilinear resamplers
# agree to well above 40 dB, and chiral, so that a mirrored face or axis shows.
#
# Usage: calibration/ffmpeg/make_fixtures.sh   (installs ffmpeg with apt-get if it is missing)
set -euo pipefail
cd "$(dirname "$0")/../.."
out=calibration/fixtures/ffmpeg
mkdir -p "$out"
command -v ffmpeg >/dev/null || { apt-get update -qq && apt-get install -y -qq ffmpeg; }
cargo build --release --quiet
ow=target/release/omniwarp

# The same pattern twice, each in its reader's convention: ffmpeg 5.1's v360 maps an equirect
# input's ±180° and ±90° to the centres of its edge pixels (its `scale()`: (x/2 + 1/2)·(W − 1)),
# where DESIGN.md maps them to the image's outer edges. Cube inputs agree (both half-pixel).
"$ow" pattern --pattern smooth --size 512x256 --supersample 4 --out "$out/input_equirect.png"
"$ow" pattern --pattern smooth --size 512x256 --supersample 4 --ffmpeg-equirect \
  --out "$out/input_equirect_ffmpeg.png"

log="$out/COMMANDS.txt"
{
  echo "# Made by calibration/ffmpeg/make_fixtures.sh on $(date -u +%Y-%m-%d)"
  ffmpeg -version | head -1
  echo
} >"$log"

v360() { # v360 INPUT OUTPUT FILTER-OPTIONS
  local cmd=(ffmpeg -nostdin -loglevel error -y -i "$out/$1"
    -vf "format=gbrp,v360=$3:interp=linear,format=rgb24" -frames:v 1 "$out/$2")
  echo "${cmd[*]}" >>"$log"
  "${cmd[@]}"
}

v360 input_equirect_ffmpeg.png equirect_to_cylindrical_270x90.png "input=e:output=cylindrical:h_fov=270:v_fov=90:w=384:h=192"
v360 input_equirect_ffmpeg.png equirect_to_fisheye_180.png "input=e:output=fisheye:h_fov=180:v_fov=180:w=256:h=256"
v360 input_equirect_ffmpeg.png equirect_to_flat_90.png "input=e:output=flat:h_fov=90:v_fov=73.7397952917:w=256:h=192"
v360 input_equirect_ffmpeg.png equirect_to_c3x2.png "input=e:output=c3x2:w=384:h=256"
v360 input_equirect_ffmpeg.png equirect_to_c6x1.png "input=e:output=c6x1:w=768:h=128"
v360 equirect_to_c3x2.png c3x2_to_equirect.png "input=c3x2:output=e:w=512:h=256"
v360 equirect_to_c6x1.png c6x1_to_equirect.png "input=c6x1:output=e:w=512:h=256"
# ffmpeg's own fisheye back to equirect: its fisheye input, like its equirect input, puts the
# circle's rim on the centres of the edge pixels (radius 127.5 pixels about (128, 128) here).
v360 equirect_to_fisheye_180.png fisheye_to_equirect.png "input=fisheye:ih_fov=180:iv_fov=180:output=e:w=512:h=256"
echo "wrote $out"
