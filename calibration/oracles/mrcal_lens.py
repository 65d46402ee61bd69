"""Reference data for omniwarp's mrcal lens models, made by mrcal itself (2.5, Python ≥ 3.12).

For PINHOLE, STEREOGRAPHIC, LONLAT, LATLON, OPENCV4/5/8/12, CAHVOR and
SPLINED_STEREOGRAPHIC: two parameter sets each, a few hundred camera-frame points (behind the
camera too where the model allows), mrcal.project with its gradients, and mrcal.unproject
(normalised). Points where mrcal's own iterative inverse does not reproject to 1e-6 px are
listed, not used as truth. Deterministic (fixed seed); run by make_fixtures.sh.

usage: mrcal_lens.py OUT_DIR
"""
import json
import sys

import mrcal
import numpy as np

RNG = np.random.default_rng(2026_11_22)
W, H = 1920, 1080


def directions(n, max_deg, behind=False):
    top = 179.0 if behind else max_deg
    th = np.radians(RNG.uniform(0, top, n))
    az = RNG.uniform(-np.pi, np.pi, n)
    return np.column_stack([np.sin(th) * np.cos(az), np.sin(th) * np.sin(az), np.cos(th)])


def cases():
    core = lambda f: [f * RNG.uniform(0.98, 1.02), f * RNG.uniform(0.98, 1.02), W / 2 - 0.5 + RNG.uniform(-30, 30), H / 2 - 0.5 + RNG.uniform(-30, 30)]
    out = []
    for _ in range(2):
        out.append(("LENSMODEL_PINHOLE", core(1500), 30, False))
        out.append(("LENSMODEL_STEREOGRAPHIC", core(700), 100, True))
        out.append(("LENSMODEL_LONLAT", core(600), 80, True))
        out.append(("LENSMODEL_LATLON", core(600), 80, True))
        d = [RNG.uniform(-0.2, 0.1), RNG.uniform(-0.02, 0.05), RNG.uniform(-1e-3, 1e-3), RNG.uniform(-1e-3, 1e-3),
             RNG.uniform(-0.01, 0.01), RNG.uniform(-0.03, 0.03), RNG.uniform(-0.01, 0.01), RNG.uniform(-0.005, 0.005),
             RNG.uniform(-1e-3, 1e-3), RNG.uniform(-2e-4, 2e-4), RNG.uniform(-1e-3, 1e-3), RNG.uniform(-2e-4, 2e-4)]
        for n in (4, 5, 8, 12):
            out.append((f"LENSMODEL_OPENCV{n}", core(1500) + d[:n], 30, False))
        out.append(("LENSMODEL_CAHVOR", core(1400) + [RNG.uniform(-0.02, 0.02), RNG.uniform(-0.02, 0.02),
                                                     RNG.uniform(-0.05, 0.05), RNG.uniform(-0.02, 0.02), RNG.uniform(-0.005, 0.005)], 30, False))
        name = "LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_Nx=16_Ny=12_fov_x_deg=120"
        out.append((name, core(900) + list(RNG.uniform(-0.01, 0.01, 2 * 16 * 12)), 55, False))
        name2 = "LENSMODEL_SPLINED_STEREOGRAPHIC_order=2_Nx=10_Ny=8_fov_x_deg=100"
        out.append((name2, core(800) + list(RNG.uniform(-0.005, 0.005, 2 * 10 * 8)), 45, False))
    return out


def main():
    out_dir = sys.argv[1]
    result = []
    for name, intrinsics, max_deg, behind in cases():
        intr = np.array(intrinsics, dtype=np.float64)
        # The splined models' dense gradients (388 columns) would make the file huge: fewer points.
        n = 60 if "SPLINED" in name else 300
        pts = directions(n, max_deg, behind) * RNG.uniform(0.5, 20.0, (n, 1))
        q, dq_dv, dq_di = mrcal.project(pts, name, intr, get_gradients=True)
        v = mrcal.unproject(q, name, intr, normalize=True)
        back = mrcal.project(v, name, intr)
        err = np.hypot(*(back - q).T)
        unreliable = np.nonzero(~np.isfinite(err) | (err > 1e-6) | (np.linalg.norm(v, axis=1) < 0.5))[0]
        result.append({
            "model": name,
            "intrinsics": intr.tolist(),
            "points": pts.tolist(),
            "pixels": q.tolist(),
            "dq_dp": dq_dv.tolist(),
            "dq_dintrinsics": dq_di.tolist(),
            "unproject_rays": np.nan_to_num(v).tolist(),
            "unreliable_inverse_point_indices": unreliable.tolist(),
        })
    with open(f"{out_dir}/mrcal.json", "w") as fh:
        json.dump({"mrcal": "2.5", "numpy": np.__version__, "cases": result}, fh)
    print(f"wrote {len(result)} cases with mrcal")


if __name__ == "__main__":
    main()
