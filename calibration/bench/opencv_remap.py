"""Times OpenCV's cv2.remap with float maps on the bench's input, for calibration/bench/bench-peers.

The maps send each pixel of a cylindrical view (270°×90° unless told) to the cube map in ffmpeg's c6x1
layout (docs/conventions.md's directions and face table; ffmpeg's slots mirror our faces, see
omniwarp::cubemap::Layout). OpenCV filters one image, so lookups across face edges clamp
instead of reading the neighbour face; that costs it a little PSNR, not time.

usage: opencv_remap.py CUBE_C6X1.png WIDTH HEIGHT FRAMES THREADS OUT.png [nearest|bilinear|bicubic [HFOV VFOV]]
(HFOV and VFOV in degrees, default 270 and 90: the cylindrical view's field.)
"""
import sys
import time

import cv2
import numpy as np


def maps(n, w, h, hfov=270.0, vfov=90.0):
    s = (2.0 * (np.arange(w) + 0.5) / w - 1.0)[None, :]
    t = (1.0 - 2.0 * (np.arange(h) + 0.5) / h)[:, None]
    lon = s * np.radians(hfov / 2.0)
    x = np.broadcast_to(np.sin(lon), (h, w))
    y = np.broadcast_to(t * np.tan(np.radians(vfov / 2.0)), (h, w))
    z = np.broadcast_to(-np.cos(lon), (h, w))
    ax, ay, az = np.abs(x), np.abs(y), np.abs(z)
    # Face table of docs/conventions.md: (slot in ffmpeg's r l u d f b, sc, tc, ma, mirror left-right).
    is_x = (ax >= ay) & (ax >= az)
    is_y = ~is_x & (ay >= az)
    is_z = ~is_x & ~is_y
    slot = np.zeros((h, w))
    sc = np.zeros((h, w))
    tc = np.zeros((h, w))
    ma = np.ones((h, w))
    for cond, sl, scv, tcv, mav in [
        (is_x & (x >= 0), 0, -z, -y, ax),
        (is_x & (x < 0), 1, z, -y, ax),
        (is_y & (y >= 0), 2, x, z, ay),
        (is_y & (y < 0), 3, x, -z, ay),
        (is_z & (z < 0), 4, -x, -y, az),
        (is_z & (z >= 0), 5, x, -y, az),
    ]:
        slot[cond], sc[cond], tc[cond], ma[cond] = sl, scv[cond], tcv[cond], mav[cond]
    fs = 0.5 * (sc / ma + 1.0)
    ft = 0.5 * (tc / ma + 1.0)
    sides = slot != 2
    sides &= slot != 3
    u = np.where(sides, 1.0 - fs, fs)
    v = np.where(sides, ft, 1.0 - ft)
    map_x = (slot * n + u * n - 0.5).astype(np.float32)
    map_y = (v * n - 0.5).astype(np.float32)
    return map_x, map_y


def main():
    src_path, w, h, frames, threads, out = sys.argv[1:7]
    filter_name = sys.argv[7] if len(sys.argv) > 7 else "bilinear"
    hfov = float(sys.argv[8]) if len(sys.argv) > 8 else 270.0
    vfov = float(sys.argv[9]) if len(sys.argv) > 9 else 90.0
    interp = {
        "nearest": cv2.INTER_NEAREST,
        "bilinear": cv2.INTER_LINEAR,
        "bicubic": cv2.INTER_CUBIC,
    }[filter_name]
    w, h, frames, threads = int(w), int(h), int(frames), int(threads)
    cv2.setNumThreads(threads)
    src = cv2.imread(src_path, cv2.IMREAD_UNCHANGED)
    n = src.shape[0]
    mx, my = maps(n, w, h, hfov, vfov)
    dst = None
    for _ in range(2):
        dst = cv2.remap(src, mx, my, interp, borderMode=cv2.BORDER_REPLICATE)
    times = []
    for _ in range(frames):
        t0 = time.perf_counter()
        cv2.remap(src, mx, my, interp, dst=dst, borderMode=cv2.BORDER_REPLICATE)
        times.append(time.perf_counter() - t0)
    times.sort()
    med = times[len(times) // 2]
    print(f"opencv remap ({filter_name}, float maps, {src.shape[2]} channels, {threads} threads): "
          f"{med * 1e3:.2f} ms/frame, {w * h / med / 1e6:.0f} Mpixel/s (cv2 {cv2.__version__})")
    cv2.imwrite(out, dst)


if __name__ == "__main__":
    main()
