//! The rig as lines in space, for drawing it: the wall traced by rays from the eye along lines
//! of constant azimuth and elevation (so any wall a single centre of projection sees — cylinder,
//! dome, plane, mesh — is drawn the same way), and per channel the projector's position, the
//! four corner rays of its frustum and its footprint, the outline of its raster on the wall
//! (each traced by the channel's exact lens model, as the warp is). Polylines break where the
//! rays miss the wall; the part of a footprint beyond the wall's edge is given apart (`spill`).

use crate::rig::Rig;
use crate::server::ApiError;
use crate::server::http::jobs::run_job;
use crate::server::http::state::{AppState, tagged};
use axum::extract::State;
use axum::response::Response;
use glam::DVec3;
use std::sync::Arc;

/// Degrees between the traced lines of the wall, and along them.
const LINE_STEP: f64 = 15.0;
const TRACE_STEP: f64 = 2.0;
/// Samples along each side of a projector's raster.
const SIDE_SAMPLES: usize = 48;
/// Where a corner ray that misses the wall is drawn to, metres.
const MISS_LENGTH: f64 = 1.0;

/// Millimetres are enough for a drawing and keep the document small.
fn mm(p: DVec3) -> [f64; 3] {
    [p.x, p.y, p.z].map(|v| (v * 1000.0).round() / 1000.0)
}

/// Consecutive points joined, broken into separate polylines at every `None`.
fn polylines(points: impl Iterator<Item = Option<DVec3>>) -> Vec<Vec<[f64; 3]>> {
    let mut lines = vec![Vec::new()];
    for p in points {
        match p {
            Some(p) => lines.last_mut().expect("one line").push(mm(p)),
            None if lines.last().is_some_and(|l| !l.is_empty()) => lines.push(Vec::new()),
            None => {}
        }
    }
    lines.retain(|l| l.len() > 1);
    lines
}

/// World direction at azimuth `az` (0 ahead, −z; positive to the right, +x) and elevation `el`.
fn direction(az: f64, el: f64) -> DVec3 {
    let (a, e) = (az.to_radians(), el.to_radians());
    DVec3::new(e.cos() * a.sin(), e.sin(), -e.cos() * a.cos())
}

fn steps(from: f64, to: f64, step: f64) -> impl Iterator<Item = f64> {
    let n = ((to - from) / step).round() as usize;
    (0..=n).map(move |k| from + k as f64 * step)
}

pub fn describe(rig: &Rig) -> serde_json::Value {
    let hit = |d: DVec3| rig.doc.screen.intersect(rig.eye, d).point();
    let mut wall = Vec::new();
    for az in steps(-180.0, 165.0, LINE_STEP) {
        wall.extend(polylines(
            steps(-88.0, 88.0, TRACE_STEP).map(|el| hit(direction(az, el))),
        ));
    }
    for el in steps(-75.0, 75.0, LINE_STEP) {
        wall.extend(polylines(
            steps(-180.0, 180.0, TRACE_STEP).map(|az| hit(direction(az, el))),
        ));
    }
    // Where the raster's edge misses the wall, the light lands on the wall continued past its
    // edge: that part of the outline is the spill, drawn apart, so that a projector overfilling
    // the wall is still seen whole.
    let extended = rig.doc.screen.extended();
    let channels: Vec<_> = rig
        .channels
        .iter()
        .map(|ch| {
            let land = |q: [f64; 2]| -> (Option<DVec3>, bool) {
                if let Some(p) = rig.wall_point(ch, q) {
                    return (Some(p), true);
                }
                let ray = ch.lens.unproject(q).ok().map(|r| ch.rotation * r);
                let p = ray.and_then(|r| extended.intersect(ch.position, r).point());
                (p, false)
            };
            let (w, h) = (f64::from(ch.width - 1), f64::from(ch.height - 1));
            let corners = [[0.0, 0.0], [w, 0.0], [w, h], [0.0, h]];
            let frustum: Vec<_> = corners
                .iter()
                .map(|&q| {
                    land(q).0.or_else(|| {
                        let ray = ch.lens.unproject(q).ok()?;
                        Some(ch.position + ch.rotation * ray * MISS_LENGTH)
                    })
                })
                .map(|p| p.map(mm))
                .collect();
            // Clockwise round the raster from its top-left pixel, back to the start.
            let n = SIDE_SAMPLES;
            let samples: Vec<(Option<DVec3>, bool)> = (0..4 * n + 1)
                .map(|k| {
                    let t = (k % n) as f64 / n as f64;
                    let side = (k / n) % 4;
                    let [a, b] = [corners[side], corners[(side + 1) % 4]];
                    land([a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t])
                })
                .collect();
            // The spill keeps the on-wall samples next to it, so the two outlines join.
            let off = |j: usize| samples.get(j).is_some_and(|s| !s.1);
            let spill = (0..samples.len()).map(|k| {
                let near = off(k) || (k > 0 && off(k - 1)) || off(k + 1);
                samples[k].0.filter(|_| near)
            });
            serde_json::json!({
                "id": ch.id,
                "resolution": [ch.width, ch.height],
                "position": mm(ch.position),
                "frustum": frustum,
                "footprint": polylines(samples.iter().map(|&(p, on)| p.filter(|_| on))),
                "spill": polylines(spill),
            })
        })
        .collect();
    serde_json::json!({"eye": mm(rig.eye), "wall": wall, "channels": channels})
}

pub async fn geometry(State(s): State<Arc<AppState>>) -> Result<Response, ApiError> {
    let (rig, revision) = s.store.snapshot();
    let mut body = run_job(&s, move |_| Ok(describe(&rig))).await?;
    body["revision"] = revision.into();
    Ok(tagged(body, revision))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_demo_cylinder_is_traced_at_its_radius_and_the_spill_past_its_edge_apart() {
        let rig = Rig::from_json(crate::rig::DEMO_RIG, std::path::Path::new(".")).unwrap();
        let g = describe(&rig);
        let points = |v: &serde_json::Value| -> Vec<[f64; 3]> {
            v.as_array()
                .unwrap()
                .iter()
                .flat_map(|l| l.as_array().unwrap().iter())
                .map(|p| [0, 1, 2].map(|k| p[k].as_f64().unwrap()))
                .collect()
        };
        let on_wall = |[x, y, z]: [f64; 3]| {
            ((x * x + z * z).sqrt() - 2.0).abs() < 2e-3 && (-1.001..=1.201).contains(&y)
        };
        let wall = points(&g["wall"]);
        // 270° of the 360° traced, between the heights the wall has.
        assert!(wall.len() > 1000, "{}", wall.len());
        assert!(wall.iter().all(|&p| on_wall(p)));
        for ch in g["channels"].as_array().unwrap() {
            let (lit, spill) = (points(&ch["footprint"]), points(&ch["spill"]));
            assert!(lit.iter().all(|&p| on_wall(p)), "{}", ch["id"]);
            // The demo's projectors overfill the wall's height: their outlines leave it.
            assert!(spill.iter().any(|&p| !on_wall(p)), "{}", ch["id"]);
            assert!(lit.len() + spill.len() >= 4 * SIDE_SAMPLES, "{}", ch["id"]);
            assert_eq!(ch["frustum"].as_array().unwrap().len(), 4);
        }
    }
}
