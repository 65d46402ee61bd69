// Renders one region of an MPCDI 2d package as the MPCDI text describes it, with every value
// taken from the VESA/Scalable reference library's reader: the region's x, y, xsize, ysize; the
// warp's nodes as the library's PFM reader lays them out (node (0, 0) the top-left); the alpha
// map as the library's PNG reader decodes it. Only the drawing is ours: per output pixel the
// warp is interpolated bilinearly with nodes edge to edge (i / (n - 1)), the media is sampled
// bilinearly at (x + u * xsize, y + v * ysize) from the top-left, and the colour is multiplied
// by the stored alpha (gamma embedded, so in signal space, as PyMPCDI's shader ends up doing).
//
// usage: vesa_render package.mpcdi region media.ppm out.pam
#include "mpcdiReader.h"
#include "mpcdiProfile.h"
#include "mpcdiDisplay.h"
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

struct Image { int w = 0, h = 0; std::vector<unsigned char> rgb; };

static bool read_ppm(const char *path, Image &img) {
  std::ifstream f(path, std::ios::binary);
  std::string magic; int maxval;
  f >> magic >> img.w >> img.h >> maxval;
  f.get();
  if (magic != "P6" || maxval != 255) return false;
  img.rgb.resize(size_t(img.w) * img.h * 3);
  f.read(reinterpret_cast<char *>(img.rgb.data()), img.rgb.size());
  return bool(f);
}

// Bilinear at pixel-centre coordinates, clamped to the edge.
static void sample(const Image &m, double px, double py, double out[3]) {
  px = std::fmin(std::fmax(px, 0.0), m.w - 1.0);
  py = std::fmin(std::fmax(py, 0.0), m.h - 1.0);
  int x0 = int(px), y0 = int(py);
  int x1 = std::min(x0 + 1, m.w - 1), y1 = std::min(y0 + 1, m.h - 1);
  double fx = px - x0, fy = py - y0;
  for (int c = 0; c < 3; c++) {
    auto at = [&](int x, int y) { return double(m.rgb[(size_t(y) * m.w + x) * 3 + c]); };
    out[c] = (1 - fy) * ((1 - fx) * at(x0, y0) + fx * at(x1, y0)) +
             fy * ((1 - fx) * at(x0, y1) + fx * at(x1, y1));
  }
}

int main(int argc, char **argv) {
  if (argc != 5) {
    std::cerr << "usage: vesa_render package.mpcdi region media.ppm out.pam\n";
    return 2;
  }
  mpcdi::Profile *profile = new mpcdi::Profile();
  mpcdi::Reader *reader = mpcdi::Reader::CreateReader();
  // The library's version check knows 1.0 only; 2.0 packages are read the same way.
  reader->SetCheckVersionSupported(false);
  if (MPCDI_FAILED(reader->Read(argv[1], profile))) {
    std::cerr << "read failed: " << mpcdi::ErrorHelper::GetLastError() << "\n";
    return 1;
  }
  mpcdi::Region *region = nullptr;
  for (auto b = profile->GetDisplay()->GetBufferBegin(); b != profile->GetDisplay()->GetBufferEnd(); ++b)
    if (auto r = b->second->GetRegion(argv[2])) region = r;
  if (!region) { std::cerr << "no region " << argv[2] << "\n"; return 1; }
  Image media;
  if (!read_ppm(argv[3], media)) { std::cerr << "bad media\n"; return 1; }
  mpcdi::GeometryWarpFile *warp = region->GetFileSet()->GetGeometryWarpFile();
  mpcdi::AlphaMap *alpha = region->GetFileSet()->GetAlphaMap();
  const int W = region->GetXresolution(), H = region->GetYresolution();
  const int nx = warp->GetSizeX(), ny = warp->GetSizeY();
  std::cerr << argv[2] << ": region " << region->GetX() << " " << region->GetY() << " "
            << region->GetXsize() << " " << region->GetYsize() << ", warp " << nx << "x" << ny
            << ", alpha " << alpha->GetSizeX() << "x" << alpha->GetSizeY() << " bit depth "
            << int(alpha->GetBitDepth()) << "\n";
  std::FILE *out = std::fopen(argv[4], "wb");
  std::fprintf(out, "P7\nWIDTH %d\nHEIGHT %d\nDEPTH 4\nMAXVAL 255\nTUPLTYPE RGB_ALPHA\nENDHDR\n", W, H);
  std::vector<unsigned char> row(size_t(W) * 4);
  for (int j = 0; j < H; j++) {
    for (int i = 0; i < W; i++) {
      double gx = (i + 0.5) / W * (nx - 1), gy = (j + 0.5) / H * (ny - 1);
      int x0 = std::min(int(gx), nx - 2), y0 = std::min(int(gy), ny - 2);
      double fx = gx - x0, fy = gy - y0, uv[2] = {0, 0};
      bool known = true;
      for (int k = 0; k < 4; k++) {
        int x = x0 + (k & 1), y = y0 + (k >> 1);
        double wt = (k & 1 ? fx : 1 - fx) * (k >> 1 ? fy : 1 - fy);
        if (wt == 0) continue;
        mpcdi::NODE &n = (*warp)(x, y);
        if (std::isnan(n.r) || std::isnan(n.g)) known = false;
        uv[0] += wt * n.r;
        uv[1] += wt * n.g;
      }
      unsigned char *p = &row[size_t(i) * 4];
      double a = (*alpha)(i, j, 0) / 255.0;
      if (!known || a == 0) { p[0] = p[1] = p[2] = p[3] = 0; continue; }
      double mx = (region->GetX() + uv[0] * region->GetXsize()) * media.w - 0.5;
      double my = (region->GetY() + uv[1] * region->GetYsize()) * media.h - 0.5;
      double c[3];
      sample(media, mx, my, c);
      for (int k = 0; k < 3; k++) p[k] = (unsigned char)std::lround(std::fmin(c[k] * a, 255.0));
      p[3] = 255;
    }
    std::fwrite(row.data(), 1, row.size(), out);
  }
  std::fclose(out);
  delete reader;
  delete profile;
  return 0;
}
