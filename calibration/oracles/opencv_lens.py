"""Reference data for omniwarp's OpenCV lens models, made by OpenCV itself.

For LENSMODEL_OPENCV4/5/8/12/14 (cv2.projectPoints / cv2.undistortPointsIter) and
LENSMODEL_OPENCV_FISHEYE (cv2.fisheye.projectPoints / cv2.fisheye.undistortPoints), three
realistic projector parameter sets each, a few hundred camera-frame points spread over the
image and out to the edge of the model's valid region: the pixels, OpenCV's Jacobian with
respect to the intrinsics, and OpenCV's accurate inverse. Points where OpenCV's own inverse is
known to be wrong (docs/lens-models.md ("OpenCV fisheye"): fisheye radii beyond π/2, which 4.x clamps) are listed,
not used as truth. Deterministic (fixed seed); run by calibration/oracles/make_fixtures.sh.

usage: opencv_lens.py OUT_DIR
"""
import json
import sys

import cv2
import numpy as np

W, H = 1920, 1080
RNG = np.random.default_rng(20261122)


def radial_fold(d):
    k = list(d) + [0.0] * (14 - len(d))
    r = np.linspace(0, 20, 200001)[1:]
    r2 = r * r
    g = (1 + k[0] * r2 + k[1] * r2**2 + k[4] * r2**3) / (1 + k[5] * r2 + k[6] * r2**2 + k[7] * r2**3)
    f = r * g
    bad = np.nonzero((np.diff(f) <= 0) | ~np.isfinite(f[1:]))[0]
    return float(r[bad[0]]) if len(bad) else float("inf")


def pinhole_sets(n):
    sets = []
    for i in range(3):
        fx = RNG.uniform(1300, 2300)
        core = [fx, fx * RNG.uniform(0.98, 1.02), W / 2 - 0.5 + RNG.uniform(-40, 40), H / 2 - 0.5 + RNG.uniform(-60, 60)]
        k1 = [-0.25, 0.12, -0.05][i]
        d = [k1, RNG.uniform(-0.05, 0.08), RNG.uniform(-2e-3, 2e-3), RNG.uniform(-2e-3, 2e-3),
             RNG.uniform(-0.02, 0.02), RNG.uniform(-0.05, 0.05), RNG.uniform(-0.02, 0.02), RNG.uniform(-0.01, 0.01),
             RNG.uniform(-2e-3, 2e-3), RNG.uniform(-5e-4, 5e-4), RNG.uniform(-2e-3, 2e-3), RNG.uniform(-5e-4, 5e-4),
             RNG.uniform(-0.02, 0.02), RNG.uniform(-0.02, 0.02)][:n]
        sets.append((core, d))
    return sets


def pinhole_case(n, core, d):
    K = np.array([[core[0], 0, core[2]], [0, core[1], core[3]], [0, 0, 1.0]])
    D = np.array(d, dtype=np.float64)
    fold = radial_fold(d)
    # Pixels over the image and a margin around it, undistorted by OpenCV's accurate inverse.
    px = np.column_stack([RNG.uniform(-0.05 * W, 1.05 * W, 300), RNG.uniform(-0.05 * H, 1.05 * H, 300)])
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 1000, 1e-12)
    und = cv2.undistortPointsIter(px.reshape(-1, 1, 2), K, D, np.eye(3), np.eye(3), crit).reshape(-1, 2)
    rays = np.column_stack([und, np.ones(len(und))])
    # Keep pixels whose inverse converged inside the valid (non-folded) region.
    keep = np.hypot(und[:, 0], und[:, 1]) < 0.95 * fold
    back, _ = cv2.projectPoints(rays[keep].reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, D)
    err = np.hypot(*(back.reshape(-1, 2) - px[keep]).T)
    good = np.nonzero(keep)[0][err < 1e-9]
    pts = rays[good] * RNG.uniform(0.5, 20.0, (len(good), 1))
    q, jac = cv2.projectPoints(pts.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, D)
    q = q.reshape(-1, 2)
    # Columns: rvec(3), tvec(3), fx, fy, cx, cy, distortion…
    jac = jac.reshape(len(pts), 2, -1)[:, :, 6:]
    name = f"LENSMODEL_OPENCV{n}"
    # OpenCV's default inverse (5 plain fixed-point iterations), recorded to show where it is off.
    default = cv2.undistortPoints(px[good].reshape(-1, 1, 2), K, D).reshape(-1, 2)
    default_rays = np.column_stack([default, np.ones(len(default))])
    return {
        "undistortPoints_default_rays": (default_rays / np.linalg.norm(default_rays, axis=1, keepdims=True)).tolist(),
        "model": name,
        "intrinsics": list(core) + list(d),
        "fold_radius": fold if np.isfinite(fold) else None,
        "points": pts.tolist(),
        "pixels": q.tolist(),
        "dq_dintrinsics": jac.tolist(),
        "unproject_pixels": px[good].tolist(),
        "unproject_rays": (rays[good] / np.linalg.norm(rays[good], axis=1, keepdims=True)).tolist(),
    }


def fisheye_case(core, k):
    K = np.array([[core[0], 0, core[2]], [0, core[1], core[3]], [0, 0, 1.0]])
    D = np.array(k, dtype=np.float64)
    # Directions up to 89° from the axis, all azimuths.
    th = np.arccos(RNG.uniform(np.cos(np.radians(89)), 1.0, 300))
    az = RNG.uniform(-np.pi, np.pi, 300)
    dirs = np.column_stack([np.sin(th) * np.cos(az), np.sin(th) * np.sin(az), np.cos(th)])
    pts = dirs * RNG.uniform(0.5, 20.0, (300, 1))
    q, jac = cv2.fisheye.projectPoints(pts.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, D)
    q = q.reshape(-1, 2)
    # Columns: fx, fy, cx, cy, k1..k4, rvec(3), tvec(3), alpha.
    jac = jac.reshape(len(pts), 2, -1)[:, :, :8]
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14)
    und = cv2.fisheye.undistortPoints(q.reshape(-1, 1, 2), K, D, criteria=crit).reshape(-1, 2)
    rays = np.column_stack([und, np.ones(len(und))])
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    pw = np.column_stack([(q[:, 0] - core[2]) / core[0], (q[:, 1] - core[3]) / core[1]])
    clamped = np.nonzero(np.hypot(pw[:, 0], pw[:, 1]) > np.pi / 2)[0]
    return {
        "model": "LENSMODEL_OPENCV_FISHEYE",
        "intrinsics": list(core) + list(k),
        "points": pts.tolist(),
        "pixels": q.tolist(),
        "dq_dintrinsics": jac.tolist(),
        "unproject_pixels": q.tolist(),
        "unproject_rays": rays.tolist(),
        "opencv_theta_d_clamped_point_indices": clamped.tolist(),
    }


def main():
    out = sys.argv[1]
    cases = []
    for n in (4, 5, 8, 12, 14):
        for core, d in pinhole_sets(n):
            cases.append(pinhole_case(n, core, d))
    for k in ([0.02, -0.01, 0.002, -0.0005], [-0.03, 0.004, -0.001, 0.0002], [0.08, -0.02, 0.005, -0.001]):
        f = RNG.uniform(560, 640)
        cases.append(fisheye_case([f, f * RNG.uniform(0.99, 1.01), 959.5, 959.5], k))
    # One lens written by OpenCV's own FileStorage, in both of its text formats.
    first8 = next(c for c in cases if c["model"] == "LENSMODEL_OPENCV8")
    i = first8["intrinsics"]
    K = np.array([[i[0], 0, i[2]], [0, i[1], i[3]], [0, 0, 1.0]])
    for ext in ("yml", "json"):
        fs = cv2.FileStorage(f"{out}/opencv8_camera.{ext}", cv2.FILE_STORAGE_WRITE)
        fs.write("cameraMatrix", K)
        fs.write("distCoeffs", np.array(i[4:]).reshape(1, -1))
        fs.release()
    with open(f"{out}/opencv.json", "w") as fh:
        json.dump({"opencv": cv2.__version__, "numpy": np.__version__, "cases": cases}, fh)
    print(f"wrote {len(cases)} cases with OpenCV {cv2.__version__}")


if __name__ == "__main__":
    main()
