"""PSNR of an image against a reference, over the pixels the reference shows (alpha > 0)."""
import sys

import numpy as np
from PIL import Image

ref = np.asarray(Image.open(sys.argv[1]).convert("RGBA")).astype(float)
got = np.asarray(Image.open(sys.argv[2]).convert("RGBA")).astype(float)
shown = ref[..., 3] > 0
mse = ((ref[..., :3] - got[..., :3])[shown] ** 2).mean()
print("%.2f dB over %d pixels" % (10 * np.log10(255**2 / mse), shown.sum()))
