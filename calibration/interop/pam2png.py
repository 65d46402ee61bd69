"""Converts the P7 (PAM) RGBA image vesa_render writes into a PNG."""
import sys, numpy as np
from PIL import Image
data = open(sys.argv[1], "rb").read()
end = data.index(b"ENDHDR\n") + 7
hdr = dict(l.split(" ", 1) for l in data[:end].decode().splitlines()[1:-1])
w, h = int(hdr["WIDTH"]), int(hdr["HEIGHT"])
Image.fromarray(np.frombuffer(data[end:], np.uint8).reshape(h, w, 4), "RGBA").save(sys.argv[2])
