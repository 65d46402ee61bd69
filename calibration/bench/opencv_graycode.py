#!/usr/bin/env python3
"""OpenCV's structured-light Gray code (opencv-contrib's GrayCodePattern) on omniwarp's virtual
bench, beside omniwarp's own sequence: the peer of `omniwarp bench camera`.

OpenCV's code numbers every projector column and row (1-pixel stripes at its finest bit, each
bit with its inverse, plus black and white for the shadow mask) and decodes to whole pixels; it
cannot read omniwarp's phase-shifted frames, so both codes are filmed through the same bench:
same rig, projector, camera, optics, sensor noise and seed (`omniwarp simulate --patterns`).
Each decoded projector pixel is compared with the bench's truth (truth.exr: the projector
coordinate the camera pixel's centre sees; pixel centres at whole numbers in both).

Usage: opencv_graycode.py OMNIWARP WORKDIR [bench options passed to omniwarp, e.g.
       --rig R --channel C --camera-size 1920x1080]
Needs numpy, OpenEXR and opencv-contrib-python-headless (calibration/bench/bench-camera-peer installs them).
"""
import json
import os
import subprocess
import sys
import time

import OpenEXR
import cv2
import numpy as np


def run(cmd):
    out = subprocess.run(cmd, check=True, capture_output=True, text=True)
    return out.stdout


def main():
    omniwarp, work, bench = sys.argv[1], sys.argv[2], sys.argv[3:]
    rig_path = next((bench[i + 1] for i, a in enumerate(bench) if a == "--rig"),
                    "calibration/rigs/dome-180-tilt15-5proj.json")
    channel = next((bench[i + 1] for i, a in enumerate(bench) if a == "--channel"), None)
    rig = json.load(open(rig_path))
    chan = next(c for c in rig["channels"] if channel is None or c["id"] == channel)
    pw, ph = chan["resolution"]

    pattern = cv2.structured_light.GrayCodePattern.create(pw, ph)
    ok, images = pattern.generate()
    assert ok
    black = np.zeros((ph, pw), np.uint8)
    white = np.full((ph, pw), 255, np.uint8)
    patterns = os.path.join(work, "patterns")
    os.makedirs(patterns, exist_ok=True)
    for n, image in enumerate(list(images) + [black, white]):
        cv2.imwrite(os.path.join(patterns, f"{n:03}.png"), image)

    captures = os.path.join(work, "opencv-captures")
    run([omniwarp, "simulate", *bench, "--patterns", patterns, "--out", captures])
    frames = [cv2.imread(os.path.join(captures, f"{n:03}.png"), cv2.IMREAD_GRAYSCALE)
              for n in range(len(images) + 2)]
    shots, cam_black, cam_white = frames[:-2], frames[-2], frames[-1]
    with OpenEXR.File(os.path.join(captures, "truth.exr")) as f:
        truth = f.channels()["RGBA"].pixels
    tx, ty, lit = truth[..., 0], truth[..., 1], truth[..., 3] > 0.5

    # OpenCV's own decoder, timed: its API decodes a stereo pair, so both views are this one.
    t = time.perf_counter()
    ok, _ = pattern.decode([shots, shots], blackImages=[cam_black, cam_black],
                           whiteImages=[cam_white, cam_white],
                           flags=cv2.structured_light.DECODE_3D_UNDERWORLD)
    t_decode = time.perf_counter() - t

    # Per pixel, as decode() does it: the shadow mask (white − black > blackThreshold, 40 by
    # default), then getProjPixel (each bit's pair must differ by whiteThreshold, 5).
    mask = (cam_white.astype(np.int16) - cam_black.astype(np.int16)) > 40
    ys, xs = np.nonzero(mask)
    errors, wrong = [], 0
    t = time.perf_counter()
    for x, y in zip(xs.tolist(), ys.tolist()):
        failed, q = pattern.getProjPixel(shots, x, y)
        if failed:
            continue
        if not lit[y, x]:
            wrong += 1
            continue
        errors.append(np.hypot(q[0] - tx[y, x], q[1] - ty[y, x]))
    t_pixels = time.perf_counter() - t
    errors = np.array(errors)

    ours = run([omniwarp, "bench", "camera", *bench])
    print(ours.rstrip())
    print(f"OpenCV {cv2.__version__} GrayCodePattern, {len(images)} patterns + black and white, "
          f"the same bench:")
    print(f"  lit camera pixels {int(lit.sum())}, in the shadow mask {len(xs)}, "
          f"decoded {len(errors) + wrong} ({100.0 * len(errors) / max(int(lit.sum()), 1):.1f} % "
          f"of lit on the lit wall), {wrong} decoded where the projector does not light")
    if len(errors):
        gross = int((errors > 1.0).sum())
        print(f"  decoded against truth: median {np.median(errors):.4f} px, "
              f"p99 {np.percentile(errors, 99):.4f} px, max {errors.max():.4f} px, "
              f"{gross} above 1 px ({100.0 * gross / len(errors):.3f} %)")
    print(f"  decode() of the two-view pair: {t_decode:.2f} s; getProjPixel over the mask from "
          f"Python: {t_pixels:.2f} s")


if __name__ == "__main__":
    main()
