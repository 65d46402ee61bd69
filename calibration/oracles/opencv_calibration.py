"""The calibration oracle: docs/lens-models.md's oracle synthetic projector inside a cylinder, solved by
OpenCV (solvePnP with the true lens, calibrateCamera with an intrinsic guess), so that
omniwarp's solver can be compared with it on the same data. Deterministic (fixed seed).

Projector 1920×1080, OPENCV5 (fx 2150, fy 2146, cx 968.5, cy 1012, k −0.061 0.094 0.0006 −0.0004
−0.012), centre (0.12, −0.35, −0.60) inside a cylinder of radius 2 m about +y, world→camera
rvec (0.105, −0.052, 0.009); 170 grid pixels cast onto the wall; 0.3 px noise per coordinate.

usage: opencv_calibration.py OUT_DIR
"""
import json
import sys

import cv2
import numpy as np

rng = np.random.default_rng(7)
W, H = 1920, 1080
K = np.array([[2150.0, 0, 968.5], [0, 2146.0, 1012.0], [0, 0, 1]])
D = np.array([-0.061, 0.094, 0.0006, -0.0004, -0.012])
rvec = np.array([0.105, -0.052, 0.009])
R, _ = cv2.Rodrigues(rvec)
C = np.array([0.12, -0.35, -0.60])
t = -R @ C

px = np.array([[u, v] for v in np.linspace(30, H - 31, 10) for u in np.linspace(30, W - 31, 17)])
crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 1000, 1e-12)
und = cv2.undistortPointsIter(px.reshape(-1, 1, 2), K, D, np.eye(3), np.eye(3), crit).reshape(-1, 2)
world = []
for x, y in und:
    d = R.T @ np.array([x, y, 1.0])
    d /= np.linalg.norm(d)
    a = d[0] ** 2 + d[2] ** 2
    b = 2 * (C[0] * d[0] + C[2] * d[2])
    c = C[0] ** 2 + C[2] ** 2 - 4.0
    s = (-b + np.sqrt(b * b - 4 * a * c)) / (2 * a)
    world.append(C + s * d)
world = np.array(world)
truth_px, _ = cv2.projectPoints(world, rvec, t, K, D)
noisy = truth_px.reshape(-1, 2) + rng.normal(0, 0.3, (len(world), 2))

obj = world.astype(np.float64).reshape(-1, 1, 3)
img = noisy.astype(np.float64).reshape(-1, 1, 2)
ok, r_pnp, t_pnp = cv2.solvePnP(obj, img, K, D, flags=cv2.SOLVEPNP_ITERATIVE)
q_pnp, _ = cv2.projectPoints(obj, r_pnp, t_pnp, K, D)
rms_pnp = float(np.sqrt(np.mean(np.sum((q_pnp.reshape(-1, 2) - noisy) ** 2, axis=1))))

K0 = np.array([[2000.0, 0, W / 2 - 0.5], [0, 2000.0, H / 2 - 0.5], [0, 0, 1]])
flags = cv2.CALIB_USE_INTRINSIC_GUESS
rms, K_cc, D_cc, rvecs, tvecs = cv2.calibrateCamera([obj.astype(np.float32)], [img.astype(np.float32)], (W, H), K0.copy(), np.zeros(5), flags=flags,
                                                    criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 1000, 1e-15))
R_cc, _ = cv2.Rodrigues(rvecs[0])
C_cc = -R_cc.T @ tvecs[0].ravel()

out = {
    "opencv": cv2.__version__,
    "resolution": [W, H],
    "points": [{"pixel": p.tolist(), "world": w.tolist()} for p, w in zip(noisy, world)],
    "truth": {"model": "LENSMODEL_OPENCV5", "intrinsics": [2150.0, 2146.0, 968.5, 1012.0] + D.tolist(),
              "rvec_world_to_camera": rvec.tolist(), "centre": C.tolist(), "pixels": truth_px.reshape(-1, 2).tolist()},
    "solvePnP_true_lens": {"rms": rms_pnp, "rvec": r_pnp.ravel().tolist(), "tvec": t_pnp.ravel().tolist()},
    "calibrateCamera": {"rms": float(rms), "intrinsics": [K_cc[0, 0], K_cc[1, 1], K_cc[0, 2], K_cc[1, 2]] + D_cc.ravel()[:5].tolist(),
                        "rvec": rvecs[0].ravel().tolist(), "tvec": tvecs[0].ravel().tolist(), "centre": C_cc.tolist()},
}
with open(f"{sys.argv[1]}/opencv_cylinder.json", "w") as fh:
    json.dump(out, fh, indent=1)
print(f"calibrateCamera rms {rms:.4f} px, fx {K_cc[0,0]:.2f}; solvePnP rms {rms_pnp:.4f}")
