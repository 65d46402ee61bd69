"""One still through py360convert, timed as a whole process is: read the equirectangular PNG,
project it to a perspective view, write the PNG. For calibration/bench/bench-peers.

usage: py360_still.py IN.png WIDTH HEIGHT HFOV VFOV OUT.png
"""
import sys

import numpy as np
import py360convert
from PIL import Image

src, w, h, hfov, vfov, out = sys.argv[1:7]
e = np.asarray(Image.open(src).convert("RGB"))
view = py360convert.e2p(e, fov_deg=(float(hfov), float(vfov)), u_deg=0, v_deg=0,
                        out_hw=(int(h), int(w)), mode="bilinear")
Image.fromarray(view.astype(np.uint8)).save(out)
