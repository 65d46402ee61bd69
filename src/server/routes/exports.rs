//! Exports for media servers over HTTP: per channel an ST-map, PFMs (2d and a3), a Paul Bourke
//! mesh and ffmpeg remap maps; for the whole rig an MPCDI package. Grids are chosen from a
//! tolerance (`?tolerance=`, content pixels for 2d and meshes, millimetres for a3); the chosen
//! size and its measured worst error come back in `X-Omniwarp-Grid` and `X-Omniwarp-Max-Error`.

use super::outputs::file;
use crate::export::bourke::MeshReader;
use crate::export::channel::{Sources, Tolerance};
use crate::export::mpcdi::{self, Profile, Reader, Version};
use crate::export::{content_uv_unbounded, inside, pfm_bytes, remap_pgm_bytes, stmap};
use crate::image_io::{Precision, exr_bytes};
use crate::server::ApiError;
use crate::server::http::jobs::{Job, job, run_job};
use crate::server::http::state::{AppState, Query};
use axum::extract::{Path, State};
use axum::http::HeaderValue;
use axum::http::StatusCode;
use axum::response::Response;
use serde::Deserialize;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExportQuery {
    #[serde(default)]
    tolerance: Option<f64>,
    /// Whose way of filling a cell `mesh.data`'s grid is sized for (any, the default;
    /// bilinear, celestia, sgct).
    #[serde(default)]
    reader: Option<String>,
}

/// Default tolerances: half a content pixel, one millimetre on the wall.
const TOL_2D: f64 = 0.5;
const TOL_A3_MM: f64 = 1.0;

fn tolerance(q: Option<f64>, default: f64) -> Result<Tolerance, ApiError> {
    Tolerance::checked(q.unwrap_or(default), "tolerance").map_err(ApiError::from)
}

fn with_grid(mut resp: Response, columns: usize, rows: usize, err: f64) -> Response {
    let h = resp.headers_mut();
    if let Ok(v) = HeaderValue::from_str(&format!("{columns}x{rows}")) {
        h.insert("x-omniwarp-grid", v);
    }
    if let Ok(v) = HeaderValue::from_str(&format!("{err:.6}")) {
        h.insert("x-omniwarp-max-error", v);
    }
    resp
}

/// Everything an export of one channel is computed from, owned for a blocking job.
struct Owned {
    id: String,
    width: usize,
    height: usize,
    /// Unbounded content coordinates (see [`Sources::uv`]).
    uv: Vec<Option<[f64; 2]>>,
    content_size: [u32; 2],
    job: Job,
}

impl Owned {
    /// The coordinates inside the canvas only.
    fn bounded(&self) -> Vec<Option<[f64; 2]>> {
        self.uv.iter().map(|p| p.filter(|&uv| inside(uv))).collect()
    }

    fn sources<'a>(&'a self, cancel: &'a AtomicBool) -> Sources<'a> {
        Sources {
            id: &self.id,
            width: self.width,
            height: self.height,
            uv: &self.uv,
            content_size: self.content_size,
            points: &self.job.computed.geometry.warp.points,
            eye: self.job.rig.eye,
            weights: &self.job.computed.geometry.weights,
            lift: None,
            cancel,
        }
    }
}

fn owned(j: Job, id: &str) -> Result<Owned, ApiError> {
    let view = j.canvas.view()?;
    let uv = content_uv_unbounded(&j.computed.map, &view);
    Ok(Owned {
        id: id.to_string(),
        width: j.computed.map.width(),
        height: j.computed.map.height(),
        uv,
        content_size: j.canvas.size,
        job: j,
    })
}

pub async fn channel_export(
    State(s): State<Arc<AppState>>,
    Path((id, name)): Path<(String, String)>,
    Query(q): Query<ExportQuery>,
) -> Result<Response, ApiError> {
    let known = [
        "stmap.exr",
        "warp-2d.pfm",
        "warp-a3.pfm",
        "mesh.data",
        "xmap.pgm",
        "ymap.pgm",
    ];
    if !known.contains(&name.as_str()) {
        return Err(ApiError::NotFound(format!(
            "no export `{name}`; there are {}",
            known.join(", ")
        )));
    }
    let tol = tolerance(
        q.tolerance,
        if name == "warp-a3.pfm" {
            TOL_A3_MM
        } else {
            TOL_2D
        },
    )?;
    let reader = match (q.reader.as_deref(), name.as_str()) {
        (None, _) => MeshReader::Any,
        (Some(r), "mesh.data") => MeshReader::parse(r, "reader")?,
        (Some(_), _) => {
            return Err(ApiError::Invalid {
                field: "reader".into(),
                reason: format!("only mesh.data is sized for a reader, not {name}"),
            });
        }
    };
    let j = job(&s, &id).await?;
    let etag = j.export_etag();
    let id2 = id.clone();
    let made = run_job(&s, move |cancel| {
        make(owned(j, &id2)?, &name, tol, reader, cancel)
    })
    .await
    .map_err(unmet)?;
    let resp = file(&s, made.bytes, made.mime, &etag)?;
    Ok(match made.grid {
        Some((c, r, e)) => with_grid(resp, c, r, e),
        None => resp,
    })
}

/// An export's bytes, type and (for grids) columns, rows and worst error.
struct Made {
    bytes: Vec<u8>,
    mime: &'static str,
    grid: Option<(usize, usize, f64)>,
}

/// The tolerance was checked when the request came in; a later error about it says the grid
/// limit stopped the search short of it: 422, with what was reached.
fn unmet(e: ApiError) -> ApiError {
    match e {
        ApiError::Invalid { field, reason } if field == "tolerance" => {
            ApiError::refused(StatusCode::UNPROCESSABLE_ENTITY, Some(&field), reason)
        }
        other => other,
    }
}

fn make(
    o: Owned,
    name: &str,
    tol: Tolerance,
    reader: MeshReader,
    cancel: &AtomicBool,
) -> Result<Made, ApiError> {
    let src = o.sources(cancel);
    let pfm = "image/x-portable-floatmap";
    Ok(match name {
        "stmap.exr" => {
            let img = stmap(&o.bounded(), o.width, o.height);
            let attrs = vec![(
                "omniwarp.export".to_string(),
                "stmap (origin bottom-left)".to_string(),
            )];
            Made {
                bytes: exr_bytes(&img, &attrs, Precision::Float)?,
                mime: "image/x-exr",
                grid: None,
            }
        }
        "warp-2d.pfm" => {
            let (c, rows) = src.grid_2d(tol)?;
            let (gw, gh) = (c.grid.columns, c.grid.rows);
            Made {
                bytes: pfm_bytes(gw, gh, &rows)?,
                mime: pfm,
                grid: Some((gw, gh, c.max_error)),
            }
        }
        "warp-a3.pfm" => {
            let (c, rows) = src.grid_a3(tol)?;
            let (gw, gh) = (c.grid.columns, c.grid.rows);
            Made {
                bytes: pfm_bytes(gw, gh, &rows)?,
                mime: pfm,
                grid: Some((gw, gh, c.max_error)),
            }
        }
        "mesh.data" => {
            let (text, c) = src.bourke(tol, reader)?;
            Made {
                bytes: text.into_bytes(),
                mime: "text/plain",
                grid: Some((c.grid.columns, c.grid.rows, c.max_error)),
            }
        }
        _ => {
            let [cw, ch] = o.content_size;
            let axis = usize::from(name == "ymap.pgm");
            let n = if axis == 0 { cw } else { ch };
            Made {
                bytes: remap_pgm_bytes(&o.bounded(), o.width, o.height, axis, n),
                mime: "image/x-portable-graymap",
                grid: None,
            }
        }
    })
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MpcdiQuery {
    #[serde(default)]
    profile: Option<String>,
    #[serde(default)]
    version: Option<String>,
    #[serde(default)]
    tolerance: Option<f64>,
    /// Bits of the alpha maps: 8 (the default; what readers decode) or 16.
    #[serde(default)]
    alpha_bits: Option<u8>,
    /// Whose conventions a 2d package follows (vesa, the default; ndisplay, watchout, pympcdi,
    /// sgct).
    #[serde(default)]
    reader: Option<String>,
}

pub async fn mpcdi_package(
    State(s): State<Arc<AppState>>,
    Query(q): Query<MpcdiQuery>,
) -> Result<Response, ApiError> {
    let profile = match q.profile.as_deref().unwrap_or("2d") {
        "2d" => Profile::TwoD,
        "a3" => Profile::A3,
        other => {
            return Err(ApiError::Invalid {
                field: "profile".into(),
                reason: format!("must be 2d or a3, got `{other}`"),
            });
        }
    };
    let reader = match q.reader.as_deref() {
        Some(r) => Reader::parse(r, "reader")?,
        None => Reader::Vesa,
    };
    let version = match q.version.as_deref() {
        Some(v) => Version::parse(v, "version")?,
        None => reader.version(),
    };
    let tol = tolerance(
        q.tolerance,
        match profile {
            Profile::TwoD => TOL_2D,
            Profile::A3 => TOL_A3_MM,
        },
    )?;
    let alpha_bits = q.alpha_bits.unwrap_or(mpcdi::ALPHA_BITS);
    if !matches!(alpha_bits, 8 | 16) {
        return Err(ApiError::Invalid {
            field: "alpha_bits".into(),
            reason: format!("must be 8 or 16, got {alpha_bits}"),
        });
    }
    let (rig, _) = s.store.snapshot();
    let mut jobs = Vec::new();
    for ch in &rig.channels {
        jobs.push((ch.id.clone(), job(&s, &ch.id).await?));
    }
    let etag = format!(
        "\"{}\"",
        jobs.iter()
            .map(|(_, j)| format!("{:016x}{:016x}", j.key, j.canvas_digest()))
            .collect::<Vec<_>>()
            .join("-")
    );
    let (bytes, worst) = run_job(&s, move |cancel| {
        let mut regions = Vec::new();
        let mut worst = 0.0f64;
        // A 2d buffer is a canvas the media server plays: channels with the same canvas share
        // one, each other canvas gets its own.
        let mut canvases: Vec<(String, [u32; 2])> = Vec::new();
        // Every channel is lifted to one black, the rig's (docs/photometry.md).
        let target = jobs.first().map_or(0.0, |(_, j)| j.rig.black_target());
        for (id, j) in jobs {
            let key = serde_json::to_string(&j.canvas).unwrap_or_default();
            let o = owned(j, &id)?;
            let rig = &o.job.rig;
            let geometry = &o.job.computed.geometry;
            let lift = rig
                .channels
                .iter()
                .find(|c| c.id == id && rig.has_black())
                .map(|ch| rig.black_lift(ch, &geometry.warp.points, &geometry.weights, target));
            let src = Sources {
                lift: lift.as_deref(),
                ..o.sources(cancel)
            };
            let (mut region, err) = src.region(profile, tol, alpha_bits, reader)?;
            region.buffer = canvases
                .iter()
                .position(|(k, _)| *k == key)
                .unwrap_or_else(|| {
                    canvases.push((key, o.content_size));
                    canvases.len() - 1
                });
            worst = worst.max(err);
            regions.push(region);
        }
        let buffers = match profile {
            Profile::TwoD => canvases.into_iter().map(|(_, size)| size).collect(),
            Profile::A3 => mpcdi::side_by_side(&mut regions),
        };
        let header = mpcdi::Header {
            version,
            profile,
            reader,
            buffers,
            unix_time: mpcdi::unix_now(),
        };
        Ok((mpcdi::package(&header, &regions)?, worst))
    })
    .await
    .map_err(unmet)?;
    let mut resp = file(&s, bytes, "application/zip", &etag)?;
    if let Ok(v) = HeaderValue::from_str(&format!("{worst:.6}")) {
        resp.headers_mut().insert("x-omniwarp-max-error", v);
    }
    resp.headers_mut().insert(
        axum::http::header::CONTENT_DISPOSITION,
        HeaderValue::from_static("attachment; filename=\"omniwarp.mpcdi\""),
    );
    Ok(resp)
}
