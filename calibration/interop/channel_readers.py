"""Reads one channel's exports with third-party readers and writes what each shows.

  stmap.exr   OpenImageIO decodes it; the content is sampled where it points, as Nuke's and
              TouchDesigner's ST-map nodes do (u across, v up from the bottom, bilinear).
  pfm2d.pfm   OpenCV decodes the PFM (rows come back top first, channels as B, G, R); the grid
              is spread over the projector edge to edge (node i at i/(n - 1)) and cv2.remap
              samples the content.

(opencv-python 5.0's wheels read no EXR: cv2.haveImageReader says so, hence OpenImageIO.)

usage: channel_readers.py CONTENT.png STMAP.exr PFM2D.pfm OUT_PREFIX
"""
import sys

import cv2
import numpy as np
import OpenImageIO as oiio

content_path, stmap_path, pfm_path, prefix = sys.argv[1:5]
content = cv2.imread(content_path, cv2.IMREAD_COLOR)  # B, G, R
ch, cw = content.shape[:2]


def save(name, bgr, shown):
    rgba = np.dstack([bgr[..., ::-1], np.where(shown, 255, 0).astype(np.uint8)])
    cv2.imwrite(prefix + name + ".png", cv2.cvtColor(rgba, cv2.COLOR_RGBA2BGRA))


# OpenImageIO: the ST-map's R, G, A by name.
buf = oiio.ImageBuf(stmap_path)
spec = buf.spec()
px = buf.get_pixels(oiio.FLOAT).reshape(spec.height, spec.width, spec.nchannels)
names = list(spec.channelnames)
u, v, a = (px[..., names.index(c)] for c in ("R", "G", "A"))
map_x = (u * cw - 0.5).astype(np.float32)
map_y = ((1.0 - v) * ch - 0.5).astype(np.float32)
img = cv2.remap(content, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
save("oiio-stmap", np.where(a[..., None] > 0, img, 0), a > 0)

# OpenCV's PFM decoder: the 2d grid (R = x, G = y of the content, top-left origin).
pfm = cv2.imread(pfm_path, cv2.IMREAD_UNCHANGED)
gx, gy = pfm[..., 2], pfm[..., 1]
ny, nx = gx.shape
w, h = spec.width, spec.height
# Node i of n sits at i/(n - 1) across the image: pixel centre p at (p + 0.5)/w * (n - 1).
cols = ((np.arange(w) + 0.5) / w * (nx - 1)).astype(np.float32)
rows = ((np.arange(h) + 0.5) / h * (ny - 1)).astype(np.float32)
grid_x, grid_y = np.meshgrid(cols, rows)
x = cv2.remap(gx, grid_x, grid_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
y = cv2.remap(gy, grid_x, grid_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
known = np.isfinite(x) & np.isfinite(y) & (x >= 0) & (x <= 1) & (y >= 0) & (y <= 1)
map_x = np.where(known, x * cw - 0.5, -1).astype(np.float32)
map_y = np.where(known, y * ch - 0.5, -1).astype(np.float32)
img = cv2.remap(content, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
save("opencv-pfm2d", np.where(known[..., None], img, 0), known)
