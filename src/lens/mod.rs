//! Lens models: a projector is an inverse camera, so every projector pixel's ray comes from its
//! lens model's unprojection. Names, intrinsics layouts and pixel conventions follow mrcal and
//! OpenCV (docs/lens-models.md): intrinsics start fx, fy, cx, cy; pixel (0, 0) is the centre of the
//! top-left pixel; the camera frame has x right, y down, z forward.
//!
//! Every formula is written once, generic over [`Real`], so that the same code runs on plain
//! `f64` and on forward-mode dual numbers (num-dual): the Jacobians with respect to the point and
//! to the intrinsics are exact derivatives of the very code that projects, not a second
//! hand-derived copy that could drift from it.

mod cahvor;
mod central;
pub mod files;
mod fisheye;
mod model;
mod opencv;
mod solve;
mod splined;

pub use model::{LensModel, Meta};

use crate::error::{Error, Result};
use glam::DVec3;
use num_dual::{Derivative, DualNum, DualSVec64};

/// A number the lens formulas run on: `f64`, or a dual number carrying derivatives.
pub trait Real: DualNum<Primitive = f64> + Copy {}
impl<T: DualNum<Primitive = f64> + Copy> Real for T {}

/// Why a point has no pixel, or a pixel no ray.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct NoImage(pub &'static str);

/// A lens: model plus intrinsics.
#[derive(Debug, Clone, PartialEq)]
pub struct Lens {
    model: LensModel,
    intrinsics: Vec<f64>,
    /// OpenCV pinhole models: the normalised radius up to which the radial distortion keeps
    /// rising (beyond it two rays share a pixel); infinite where it never folds. The fisheye:
    /// the largest usable angle from the axis.
    fold: f64,
}

/// The most derivatives one projection carries: the point (3) and up to 18 intrinsics.
const LANES: usize = 21;
type Grad = DualSVec64<LANES>;

/// Projection with its derivatives.
#[derive(Debug, Clone, PartialEq)]
pub struct Projected {
    /// The pixel (x right, y down, pixel centres at integers).
    pub q: [f64; 2],
    /// ∂q/∂p, rows u and v.
    pub dq_dp: [[f64; 3]; 2],
    /// ∂q/∂intrinsics, rows u and v, one column per intrinsic.
    pub dq_dintrinsics: [Vec<f64>; 2],
}

impl Lens {
    /// Checks the intrinsics against the model: count, finiteness, non-zero focal lengths.
    pub fn new(model: LensModel, intrinsics: Vec<f64>) -> Result<Self> {
        if !model.meta().supported {
            return Err(Error::invalid(
                "model",
                format!("{model} is known but not computed by omniwarp yet"),
            ));
        }
        let want = model.intrinsics_len();
        if intrinsics.len() != want {
            return Err(Error::invalid(
                "intrinsics",
                format!(
                    "{model} takes {want} intrinsics ({}), got {}",
                    model.intrinsics_names().join(", "),
                    intrinsics.len()
                ),
            ));
        }
        let names = model.intrinsics_names();
        for (name, v) in names.iter().zip(&intrinsics) {
            if !v.is_finite() {
                return Err(Error::invalid(
                    "intrinsics",
                    format!("{name} must be finite, got {v}"),
                ));
            }
        }
        for (i, name) in ["fx", "fy"].iter().enumerate() {
            if intrinsics[i] == 0.0 {
                return Err(Error::invalid(
                    "intrinsics",
                    format!("{name} must not be zero"),
                ));
            }
        }
        let fold = match model {
            LensModel::OpenCv(_) => radial_fold(&intrinsics[4..]),
            LensModel::OpenCvFisheye => {
                fisheye::theta_limit([intrinsics[4], intrinsics[5], intrinsics[6], intrinsics[7]])
            }
            _ => f64::INFINITY,
        };
        Ok(Lens {
            model,
            intrinsics,
            fold,
        })
    }

    /// The lens model.
    pub fn model(&self) -> LensModel {
        self.model
    }

    /// The intrinsics in the model's order: fx, fy, cx, cy, then the model's own
    /// ([`LensModel::intrinsics_names`]).
    pub fn intrinsics(&self) -> &[f64] {
        &self.intrinsics
    }

    /// Normalised radius (x/z) where an OpenCV pinhole model's radial distortion folds over;
    /// infinite for every other model. Projection and unprojection stay inside it.
    pub fn fold_radius(&self) -> f64 {
        match self.model {
            LensModel::OpenCv(_) => self.fold,
            _ => f64::INFINITY,
        }
    }

    /// The model's formula on any [`Real`], with intrinsics `intr` in place of the lens's own
    /// (the calibration solver differentiates through it). No domain checks: see
    /// [`Lens::project`].
    pub fn formula<T: Real>(&self, intr: &[T], p: [T; 3]) -> [T; 2] {
        let core = [intr[0], intr[1], intr[2], intr[3]];
        match self.model {
            LensModel::Pinhole => opencv::project(core, &[], p),
            LensModel::OpenCv(_) => opencv::project(core, &intr[4..], p),
            LensModel::OpenCvFisheye => fisheye::project(core, &intr[4..8], p),
            LensModel::Stereographic => central::stereographic(core, p),
            LensModel::LonLat => central::lonlat(core, p),
            LensModel::LatLon => central::latlon(core, p),
            LensModel::Cahvor => cahvor::project(core, &intr[4..9], p),
            LensModel::SplinedStereographic { .. } => splined::project(&self.splined(), intr, p),
        }
    }

    fn splined(&self) -> splined::Config {
        match self.model {
            LensModel::SplinedStereographic {
                order,
                nx,
                ny,
                fov_x_deg,
            } => splined::Config {
                order,
                nx: nx as usize,
                ny: ny as usize,
                fov_x_deg: f64::from(fov_x_deg),
            },
            _ => unreachable!("only the splined model has a spline"),
        }
    }

    /// Whether the model maps this camera-frame point to a pixel of its own.
    fn check_point(&self, p: DVec3) -> std::result::Result<(), NoImage> {
        if !p.is_finite() || p == DVec3::ZERO {
            return Err(NoImage("the point is not a finite, non-zero vector"));
        }
        match self.model {
            LensModel::Pinhole | LensModel::OpenCv(_) => {
                if p.z <= 0.0 {
                    return Err(NoImage("the point is not in front of the camera"));
                }
                if p.x.hypot(p.y) / p.z > self.fold {
                    return Err(NoImage(
                        "the point lies beyond the radius where the distortion folds over",
                    ));
                }
            }
            LensModel::OpenCvFisheye => {
                if p.z <= 0.0 {
                    return Err(NoImage(
                        "the fisheye model cannot represent rays at 90° or more from its axis",
                    ));
                }
            }
            LensModel::Stereographic => {
                if p.x == 0.0 && p.y == 0.0 && p.z < 0.0 {
                    return Err(NoImage("straight behind a stereographic lens has no pixel"));
                }
            }
            LensModel::LonLat => {
                if p.x == 0.0 && p.z == 0.0 {
                    return Err(NoImage("the poles of a LONLAT lens have no single pixel"));
                }
            }
            LensModel::LatLon => {
                if p.y == 0.0 && p.z == 0.0 {
                    return Err(NoImage(
                        "the ±x poles of a LATLON lens have no single pixel",
                    ));
                }
            }
            LensModel::Cahvor => {
                let (omega, z) = cahvor::depths(&self.intrinsics[4..9], p.to_array());
                if p.z <= 0.0 || omega <= 0.0 || z <= 0.0 {
                    return Err(NoImage("the point is not in front of the CAHVOR lens"));
                }
            }
            LensModel::SplinedStereographic { .. } => {
                if p.x == 0.0 && p.y == 0.0 && p.z < 0.0 {
                    return Err(NoImage("straight behind a stereographic lens has no pixel"));
                }
            }
        }
        Ok(())
    }

    /// The pixel of camera-frame point `p` (any length).
    pub fn project(&self, p: DVec3) -> std::result::Result<[f64; 2], NoImage> {
        self.check_point(p)?;
        let q = self.formula(&self.intrinsics, p.to_array());
        if q.iter().all(|v| v.is_finite()) {
            Ok(q)
        } else {
            Err(NoImage("the projection is not finite"))
        }
    }

    /// [`Lens::project`] of each point, in order.
    pub fn project_batch(&self, points: &[DVec3]) -> Vec<std::result::Result<[f64; 2], NoImage>> {
        points.iter().map(|p| self.project(*p)).collect()
    }

    /// The pixel of `p` and its exact derivatives with respect to `p` and the intrinsics.
    pub fn project_with_jacobians(&self, p: DVec3) -> std::result::Result<Projected, NoImage> {
        let q = self.project(p)?;
        let n = self.intrinsics.len();
        if n + 3 > LANES {
            return Ok(self.splined_jacobians(p, q));
        }
        let lane = |v: f64, i: usize| Grad::from_re(v).derivative(i);
        let pd = [lane(p.x, 0), lane(p.y, 1), lane(p.z, 2)];
        let id: Vec<Grad> = self
            .intrinsics
            .iter()
            .enumerate()
            .map(|(i, &v)| lane(v, 3 + i))
            .collect();
        let out = self.formula(&id, pd);
        let grads = out.map(|o| gradient(&o.eps));
        Ok(Projected {
            q,
            dq_dp: grads.map(|g| [g[0], g[1], g[2]]),
            dq_dintrinsics: grads.map(|g| g[3..3 + n].to_vec()),
        })
    }

    /// The splined model has hundreds of intrinsics, but each pixel depends on the core and
    /// (order + 1)² knots only: the core and the point by dual numbers, the knots directly
    /// (q = f·(u + Σ w·C) + c is linear in them, ∂q/∂C = f·w).
    fn splined_jacobians(&self, p: DVec3, q: [f64; 2]) -> Projected {
        let cfg = self.splined();
        let lane = |v: f64, i: usize| Grad::from_re(v).derivative(i);
        let pd = [lane(p.x, 0), lane(p.y, 1), lane(p.z, 2)];
        let mut intr: Vec<Grad> = self.intrinsics.iter().map(|&v| Grad::from_re(v)).collect();
        for (i, v) in intr.iter_mut().take(4).enumerate() {
            *v = lane(self.intrinsics[i], 3 + i);
        }
        let out = splined::project(&cfg, &intr, pd);
        let grads = out.map(|o| gradient(&o.eps));
        let mut di = [
            vec![0.0; self.intrinsics.len()],
            vec![0.0; self.intrinsics.len()],
        ];
        for (row, g) in di.iter_mut().zip(&grads) {
            row[..4].copy_from_slice(&g[3..7]);
        }
        let u = splined::stereographic_u(p.to_array());
        for (at, w) in cfg.weights(u) {
            di[0][at] = self.intrinsics[0] * w;
            di[1][at + 1] = self.intrinsics[1] * w;
        }
        Projected {
            q,
            dq_dp: grads.map(|g| [g[0], g[1], g[2]]),
            dq_dintrinsics: di,
        }
    }

    /// The unit ray of pixel `q` (pixel centres at integers).
    pub fn unproject(&self, q: [f64; 2]) -> std::result::Result<DVec3, NoImage> {
        self.unproject_near(q, None)
    }

    /// Unprojects pixels met one after another along a row (or any evenly stepped line),
    /// each started from the answers before it: see [`Walk`].
    pub fn walk(&self) -> Walk<'_> {
        Walk {
            lens: self,
            last: [None, None],
            steps: 0,
        }
    }

    /// [`Lens::unproject`] started from `guess`, a ray close to the answer (a neighbouring
    /// pixel's): iterative models then converge in a step or two. The answer is the same.
    pub fn unproject_near(
        &self,
        q: [f64; 2],
        guess: Option<DVec3>,
    ) -> std::result::Result<DVec3, NoImage> {
        if !q.iter().all(|v| v.is_finite()) {
            return Err(NoImage("the pixel is not finite"));
        }
        let i = &self.intrinsics;
        let (u, v) = ((q[0] - i[2]) / i[0], (q[1] - i[3]) / i[1]);
        let ray = match self.model {
            LensModel::Pinhole => DVec3::new(u, v, 1.0).normalize(),
            LensModel::Stereographic => central::unproject_stereographic(u, v),
            LensModel::LonLat | LensModel::LatLon => {
                let (a, b) = if self.model == LensModel::LonLat {
                    (u, v)
                } else {
                    (v, u)
                };
                // a is the longitude-like angle, b the latitude-like one.
                if a.abs() > std::f64::consts::PI || b.abs() > std::f64::consts::FRAC_PI_2 {
                    return Err(NoImage(
                        "the pixel lies outside the model's ±180°×±90° range",
                    ));
                }
                if self.model == LensModel::LonLat {
                    central::unproject_lonlat(u, v)
                } else {
                    central::unproject_latlon(u, v)
                }
            }
            LensModel::OpenCvFisheye => {
                let k = [i[4], i[5], i[6], i[7]];
                let rho = u.hypot(v);
                let theta = fisheye::solve_theta(k, rho, self.fold).ok_or(NoImage(
                    "the pixel lies beyond the fisheye's 90° or where its distortion turns back",
                ))?;
                if rho == 0.0 {
                    DVec3::Z
                } else {
                    let s = theta.sin() / rho;
                    DVec3::new(u * s, v * s, theta.cos())
                }
            }
            LensModel::OpenCv(n) if n <= 12 => {
                // Closed-form Newton from the neighbour's answer (or the undistorted point);
                // the general solver where it gives up.
                let start = guess
                    .filter(|g| g.z > 0.0)
                    .map_or([u, v], |g| [g.x / g.z, g.y / g.z]);
                let core = [i[0], i[1], i[2], i[3]];
                match opencv::undistort(core, &i[4..], q, start, self.fold) {
                    Some(([x, y], _)) => DVec3::new(x, y, 1.0).normalize(),
                    None => solve::unproject(self, q, guess)?,
                }
            }
            LensModel::OpenCv(_) | LensModel::Cahvor | LensModel::SplinedStereographic { .. } => {
                solve::unproject(self, q, guess)?
            }
        };
        Ok(ray)
    }

    /// [`Lens::unproject`] of each pixel, in order.
    pub fn unproject_batch(&self, pixels: &[[f64; 2]]) -> Vec<std::result::Result<DVec3, NoImage>> {
        pixels.iter().map(|q| self.unproject(*q)).collect()
    }
}

/// A lens unprojecting evenly spaced pixels in order ([`Lens::walk`]). Each pixel's iterative
/// unprojection starts on the line through the last two answers, on the plane z = 1 where the
/// OpenCV models solve: the image point moves smoothly from pixel to pixel, so the line lands
/// within a second-order step of the answer and Newton needs one step where the neighbouring
/// answer alone needs two. The answers are [`Lens::unproject`]'s (the same root, to its
/// 1e-10 px). After a pixel with no ray, the next starts afresh.
pub struct Walk<'a> {
    lens: &'a Lens,
    /// The last two answers on the plane z = 1, newest first (`None`: no ray, or one at or
    /// behind the plane's horizon).
    last: [Option<[f64; 2]>; 2],
    /// Newton steps taken on the line so far (the closed form's; see [`Walk::steps`]).
    steps: u64,
}

impl Walk<'_> {
    /// How many Newton steps the pixels started on the line took: about one a pixel where
    /// the line works (two from the neighbouring answer alone). What the tests hold it to.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// The unit ray of pixel `q`, the next along the walk.
    #[inline]
    pub fn unproject(&mut self, q: [f64; 2]) -> std::result::Result<DVec3, NoImage> {
        let lens = self.lens;
        // The closed-form Newton of the OpenCV models works on the plane itself: its answer
        // is the next start as it is, with no division on the way.
        if let (LensModel::OpenCv(n), [Some(a), Some(b)]) = (lens.model, self.last)
            && n <= 12
        {
            let i = &lens.intrinsics;
            let start = on_the_line(a, b);
            let core = [i[0], i[1], i[2], i[3]];
            if let Some(([x, y], steps)) = opencv::undistort(core, &i[4..], q, start, lens.fold) {
                self.last = [Some([x, y]), Some(a)];
                self.steps += u64::from(steps);
                return Ok(DVec3::new(x, y, 1.0).normalize());
            }
        }
        self.afresh(q)
    }

    /// Every other case: a row's first pixels, a model without a plane to walk on, a pixel
    /// the closed form gives up on.
    fn afresh(&mut self, q: [f64; 2]) -> std::result::Result<DVec3, NoImage> {
        let lens = self.lens;
        if !matches!(
            lens.model,
            LensModel::OpenCv(_) | LensModel::Cahvor | LensModel::SplinedStereographic { .. }
        ) {
            // Closed forms: nothing to start from.
            return lens.unproject(q);
        }
        let guess = match self.last {
            [Some(a), Some(b)] => Some(on_the_line(a, b)),
            [a, _] => a,
        };
        let ray = lens.unproject_near(q, guess.map(|[x, y]| DVec3::new(x, y, 1.0)));
        let plane = match ray {
            Ok(r) if r.z > 1e-9 => Some([r.x / r.z, r.y / r.z]),
            _ => None,
        };
        self.last = [plane, self.last[0]];
        ray
    }
}

/// The next point on the line through the last answer `a` and the one before it `b`, a
/// pixel's step on: within a second-order step of the next pixel's answer.
#[inline(always)]
fn on_the_line(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [2.0 * a[0] - b[0], 2.0 * a[1] - b[1]]
}

fn gradient(eps: &Derivative<f64, nalgebra::Const<LANES>, nalgebra::U1>) -> [f64; LANES] {
    let m = eps.unwrap_generic(nalgebra::Const::<LANES>, nalgebra::U1);
    std::array::from_fn(|i| m[i])
}

/// Where ρ·g(ρ) of OpenCV's radial distortion stops rising (or infinity if it never does
/// within ρ ≤ 20, about 87° from the axis).
fn radial_fold(d: &[f64]) -> f64 {
    let k = |i: usize| d.get(i).copied().unwrap_or(0.0);
    let radial = |r: f64| {
        let r2 = r * r;
        r * (1.0 + k(0) * r2 + k(1) * r2 * r2 + k(4) * r2 * r2 * r2)
            / (1.0 + k(5) * r2 + k(6) * r2 * r2 + k(7) * r2 * r2 * r2)
    };
    let steps = 20_000;
    let mut last = 0.0;
    for s in 1..=steps {
        let r = 20.0 * s as f64 / steps as f64;
        let v = radial(r);
        if !v.is_finite() || v <= last {
            return 20.0 * (s - 1) as f64 / steps as f64;
        }
        last = v;
    }
    f64::INFINITY
}
