//! Camera calibration over HTTP. While the channel shows frame n of its structured-light
//! sequence (`GET …/pattern/{n}`), the camera's image of it is uploaded as
//! `PUT …/captures/{n}`; once every frame is in, `POST …/captures` with the camera (its pose
//! known) decodes them and either proposes a calibration, like the correspondences route, or
//! checks the channel's current one and says whether the projector moved.

use super::calib::{keep_offer, offer};
use crate::calibration::ModelChoice;
use crate::rig::{Channel, ChannelDoc};
use crate::server::ApiError;
use crate::server::http::jobs::run_job;
use crate::server::http::state::{AppState, Query, parse_body};
use crate::structured::decode::{DecodeOptions, decode};
use crate::structured::triangulate::{fit_screen, triangulate};
use crate::structured::{Grey, PatternSet, calibrate_captures, calibrate_decoded, check};
use axum::Json;
use axum::body::Bytes;
use axum::extract::{Path, State};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use std::sync::Arc;

/// One reading of the rig for a capture request, so that the sequence decoded and the channel
/// checked or fitted are the same rig's.
struct Reading {
    rig: Arc<crate::rig::Rig>,
    revision: u64,
    channel: Channel,
    set: PatternSet,
}

/// How a request names the sequence shown: its phase period (default 16) and its code
/// (default `gray`), and where an error on either points: `at` is "" for query parameters,
/// "/" for fields of the body.
#[derive(Clone, Copy)]
pub(super) struct Named<'a> {
    pub period: Option<u32>,
    pub code: Option<&'a str>,
    pub at: &'a str,
}

/// Channel `id` (404 if the rig has none) and the sequence `named`.
fn read_channel(s: &AppState, id: &str, named: Named) -> Result<Reading, ApiError> {
    let (rig, revision) = s.store.snapshot();
    let channel = rig
        .channel(id)
        .map_err(|_| ApiError::NotFound(format!("no channel `{id}`")))?
        .clone();
    let set = sequence_of(&channel, named)?;
    Ok(Reading {
        rig,
        revision,
        channel,
        set,
    })
}

/// The sequence `named` on `channel`.
fn sequence_of(channel: &Channel, named: Named) -> Result<PatternSet, ApiError> {
    let invalid = |what: &str, e: crate::Error| ApiError::Invalid {
        field: format!("{}{what}", named.at),
        reason: e.reason(),
    };
    let mut set = PatternSet::new(channel.width, channel.height)?;
    if let Some(p) = named.period {
        set = set.with_period(p).map_err(|e| invalid("period", e))?;
    }
    if let Some(c) = named.code {
        set = set.with_code(c.parse().map_err(|e| invalid("code", e))?);
    }
    Ok(set)
}

/// A 400 naming the camera's resolution (`field`) unless `frames` (`whose` captures) have
/// the camera's size.
fn camera_sized(
    frames: &[Arc<Grey>],
    camera: &Channel,
    field: &str,
    whose: &str,
) -> Result<(), ApiError> {
    match frames.first() {
        Some(f) if (f.width, f.height) != (camera.width, camera.height) => Err(ApiError::Invalid {
            field: field.into(),
            reason: format!(
                "is {}×{}, {whose} {}×{}",
                camera.width, camera.height, f.width, f.height
            ),
        }),
        _ => Ok(()),
    }
}

/// The channel's pattern sequence, as [`read_channel`] reads it.
pub(super) fn sequence(s: &AppState, id: &str, named: Named) -> Result<PatternSet, ApiError> {
    Ok(read_channel(s, id, named)?.set)
}

/// Which camera's captures a request means: several cameras can film the same channel (to
/// measure the wall from two of them), each under a view name; without one, the channel's
/// default view.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ViewQuery {
    #[serde(default)]
    view: Option<String>,
    /// The sequence's phase period, as the patterns were shown with it.
    #[serde(default)]
    period: Option<u32>,
    /// The sequence's code (`gray` or `xor`), as the patterns were shown with it.
    #[serde(default)]
    code: Option<String>,
}

impl ViewQuery {
    fn named(&self) -> Named<'_> {
        Named {
            period: self.period,
            code: self.code.as_deref(),
            at: "",
        }
    }
}

/// The capture store's key for channel `id`'s captures of `view` in sequence `set`; `field`
/// names the view in an error. Sequences of other periods or codes have other frames, so each
/// is kept apart.
fn slot(id: &str, view: Option<&str>, set: &PatternSet, field: &str) -> Result<String, ApiError> {
    // The unit separator cannot appear in an id or a view name, so keys never collide.
    let key = |view: &str| {
        format!(
            "{id}\u{1f}{}\u{1f}{}\u{1f}{view}",
            set.period,
            set.code.name()
        )
    };
    match view {
        None => Ok(key("")),
        Some(v)
            if (1..=32).contains(&v.len())
                && v.bytes()
                    .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_') =>
        {
            Ok(key(v))
        }
        Some(v) => Err(ApiError::Invalid {
            field: field.into(),
            reason: format!("must be 1–32 letters, digits, `-` or `_`, got `{v}`"),
        }),
    }
}

fn status(s: &AppState, id: &str, set: &PatternSet) -> serde_json::Value {
    let (got, size) = s.captures.status(id, set.len());
    let missing: Vec<usize> = (0..set.len()).filter(|n| !got.contains(n)).collect();
    serde_json::json!({"frames": set.len(), "received": got, "missing": missing, "size": size})
}

pub async fn get_captures(
    State(s): State<Arc<AppState>>,
    Path(id): Path<String>,
    Query(q): Query<ViewQuery>,
) -> Result<Response, ApiError> {
    let set = sequence(&s, &id, q.named())?;
    let key = slot(&id, q.view.as_deref(), &set, "view")?;
    Ok(Json(status(&s, &key, &set)).into_response())
}

pub async fn delete_captures(
    State(s): State<Arc<AppState>>,
    Path(id): Path<String>,
    Query(q): Query<ViewQuery>,
) -> Result<Response, ApiError> {
    let set = sequence(&s, &id, q.named())?;
    let dropped = s
        .captures
        .clear(&slot(&id, q.view.as_deref(), &set, "view")?);
    Ok(Json(serde_json::json!({"dropped": dropped})).into_response())
}

/// A frame number as a path segment: decimal digits only (`+1` or ` 1` is not a name the
/// pattern's URLs use, so it is not one a capture is filed under).
pub(super) fn frame_number(n: &str, set: &PatternSet) -> Result<usize, ApiError> {
    n.bytes()
        .all(|b| b.is_ascii_digit())
        .then(|| n.parse().ok())
        .flatten()
        .ok_or_else(|| ApiError::Invalid {
            field: "n".into(),
            reason: format!("must be a frame number, 0–{}, got `{n}`", set.len() - 1),
        })
}

pub async fn put_capture(
    State(s): State<Arc<AppState>>,
    Path((id, n)): Path<(String, String)>,
    Query(q): Query<ViewQuery>,
    body: Bytes,
) -> Result<Response, ApiError> {
    let set = sequence(&s, &id, q.named())?;
    let key = slot(&id, q.view.as_deref(), &set, "view")?;
    let n = frame_number(&n, &set)?;
    set.frame(n, "n")?;
    let grey = run_job(&s, move |_| Ok(Grey::decode(&body, "body")?)).await?;
    s.captures.put(&key, n, set.len(), grey)?;
    Ok(Json(status(&s, &key, &set)).into_response())
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct DecodeBody {
    /// The camera that took the captures, its pose known.
    camera: ChannelDoc,
    /// `auto` (default) or a lens model name.
    #[serde(default)]
    model: Option<String>,
    /// Decoded pixels used as correspondences, at most.
    #[serde(default = "default_points")]
    points: usize,
    /// Wall points of known position and the camera pixels where they appear: the camera's
    /// pose is solved from them (its lens kept) instead of taken from `camera`.
    #[serde(default)]
    markers: Option<Vec<crate::calibration::Correspondence>>,
    /// Instead of `markers`: another channel, already calibrated, whose captures (under the
    /// same view) the camera took from where it stands; the camera's pose is solved from them.
    #[serde(default)]
    pose_from: Option<String>,
    /// Compare with the channel's current calibration instead of proposing one.
    #[serde(default)]
    check: bool,
    /// With `check`: when the projector moved, also propose a calibration fitted to the same
    /// captures.
    #[serde(default)]
    refit: bool,
}

fn default_points() -> usize {
    5000
}

pub async fn post_captures(
    State(s): State<Arc<AppState>>,
    Path(id): Path<String>,
    Query(q): Query<ViewQuery>,
    body: Bytes,
) -> Result<Response, ApiError> {
    let b: DecodeBody = parse_body(&body)?;
    let Reading {
        rig,
        revision: rig_revision,
        channel: projector,
        set,
    } = read_channel(&s, &id, q.named())?;
    let key = slot(&id, q.view.as_deref(), &set, "view")?;
    let mut camera = Channel::from_doc(&b.camera, "/camera")?;
    if b.markers.is_some() && b.pose_from.is_some() {
        return Err(ApiError::Invalid {
            field: "/pose_from".into(),
            reason: "the camera is posed from markers or from another channel, not both".into(),
        });
    }
    if let Some(markers) = &b.markers {
        crate::limits::at_most("/markers", markers.len(), crate::limits::CALIBRATION_POINTS)?;
        let (c, markers) = (camera.clone(), markers.clone());
        camera = run_job(&s, move |_| {
            crate::structured::camera_pose(&c, &markers)
                .map(|(posed, _)| posed)
                .map_err(invalid_at("/markers"))
        })
        .await?;
    }
    crate::limits::at_most("/points", b.points, crate::limits::CALIBRATION_POINTS)?;
    if let Some(anchor) = &b.pose_from {
        camera = pose_from(&s, &rig, anchor, &id, &q, camera, b.points).await?;
    }
    let choice = match b.model.as_deref().unwrap_or("auto") {
        "auto" => ModelChoice::Auto,
        m => ModelChoice::Fixed(m.parse().map_err(|e: crate::Error| ApiError::Invalid {
            field: "/model".into(),
            reason: e.reason(),
        })?),
    };
    let frames = complete(&s, &key, &set, "captures")?;
    camera_sized(&frames, &camera, "/camera/resolution", "the captures")?;
    let opts = DecodeOptions::default();
    let resolution = [projector.width, projector.height];
    if b.refit && !b.check {
        return Err(ApiError::Invalid {
            field: "/refit".into(),
            reason: "applies to a check; without `check` the captures are fitted anyway".into(),
        });
    }
    if b.check {
        let screen = rig.doc.screen.clone();
        let refit = b.refit;
        let (mut report, refitted) = run_job(&s, move |cancel| {
            let decoded = decode(&set, &frames, &opts)?;
            let c = check(&decoded, &camera, &screen, &projector);
            let report = serde_json::json!({
                "count": c.count,
                "p50": finite(c.p50), "p95": finite(c.p95), "max": finite(c.max),
                "threshold": c.threshold,
                "moved": c.moved,
                "rejected": rejected(&decoded.rejected),
            });
            if !(refit && c.moved) {
                return Ok((report, None));
            }
            let found = calibrate_decoded(
                decoded, resolution, &camera, &screen, choice, b.points, cancel,
            )
            .map_err(invalid_as_field)?;
            Ok((report, Some(found.calibration)))
        })
        .await?;
        if refit {
            report["proposal"] = match refitted {
                Some(cal) => {
                    let p = keep_offer(&s, &id, rig_revision, resolution, &cal).await?;
                    serde_json::to_value(&p).expect("proposals serialise")
                }
                None => serde_json::Value::Null,
            };
        }
        return Ok(Json(report).into_response());
    }
    let screen = rig.doc.screen.clone();
    let found = run_job(&s, move |cancel| {
        calibrate_captures(
            &set, &frames, &camera, &screen, choice, b.points, &opts, cancel,
        )
        .map_err(invalid_as_field)
    })
    .await?;
    offer(&s, &id, rig_revision, resolution, &found.calibration).await
}

/// The camera posed from the captures of channel `anchor` (already calibrated, not `id`)
/// under the request's view.
async fn pose_from(
    s: &Arc<AppState>,
    rig: &crate::rig::Rig,
    anchor: &str,
    id: &str,
    q: &ViewQuery,
    camera: Channel,
    points: usize,
) -> Result<Channel, ApiError> {
    let invalid = |reason: String| ApiError::Invalid {
        field: "/pose_from".into(),
        reason,
    };
    if anchor == id {
        return Err(invalid(
            "is the channel being calibrated; the camera is posed from another one, already \
             calibrated"
                .into(),
        ));
    }
    let projector = rig
        .channel(anchor)
        .map_err(|_| invalid(format!("the rig has no channel `{anchor}`")))?
        .clone();
    let set = sequence_of(&projector, q.named())?;
    let key = slot(anchor, q.view.as_deref(), &set, "view")?;
    let frames = complete(s, &key, &set, "/pose_from")?;
    camera_sized(
        &frames,
        &camera,
        "/camera/resolution",
        &format!("`{anchor}`'s captures"),
    )?;
    let screen = rig.doc.screen.clone();
    run_job(s, move |_| {
        let decoded = decode(&set, &frames, &DecodeOptions::default())?;
        crate::structured::camera_pose_from_projector(
            &decoded, &camera, &projector, &screen, points,
        )
        .map(|(posed, _)| posed)
        .map_err(invalid_at("/pose_from"))
    })
    .await
}

/// Every frame of the captures under `key`, or an error naming `field` with those missing.
fn complete(
    s: &AppState,
    key: &str,
    set: &PatternSet,
    field: &str,
) -> Result<Vec<Arc<Grey>>, ApiError> {
    s.captures
        .all(key, set.len())
        .map_err(|missing| ApiError::Invalid {
            field: field.into(),
            reason: format!(
                "{} of the {} frames are missing: {missing:?} (PUT …/captures/{{n}})",
                missing.len(),
                set.len()
            ),
        })
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct WallBody {
    /// The two cameras' captures of the channel: each camera, its pose known, and the view its
    /// captures were uploaded under (none: the default view).
    views: Vec<WallView>,
    /// Every n-th decoded pixel of the first view, each way.
    #[serde(default = "default_step")]
    step: u32,
    /// Pixel pairs whose rays pass further apart are left out, metres.
    #[serde(default = "default_gap")]
    gap: f64,
    /// The phase period the patterns were shown with.
    #[serde(default)]
    period: Option<u32>,
    /// The code the patterns were shown with (`gray` or `xor`).
    #[serde(default)]
    code: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct WallView {
    camera: ChannelDoc,
    #[serde(default)]
    view: Option<String>,
}

fn default_step() -> u32 {
    2
}

fn default_gap() -> f64 {
    0.01
}

/// The wall measured from two views' captures of the channel: the points triangulated and the
/// rig's kind of wall fitted to them. The answer holds the fitted screen beside the rig's;
/// applying it is an ordinary rig edit (PUT /v1/rig), the client's decision.
pub async fn post_wall(
    State(s): State<Arc<AppState>>,
    Path(id): Path<String>,
    body: Bytes,
) -> Result<Response, ApiError> {
    let b: WallBody = parse_body(&body)?;
    if b.views.len() != 2 {
        return Err(ApiError::Invalid {
            field: "/views".into(),
            reason: format!("must hold two views, got {}", b.views.len()),
        });
    }
    if !(1..=64).contains(&b.step) {
        return Err(ApiError::Invalid {
            field: "/step".into(),
            reason: format!("must lie within 1–64, got {}", b.step),
        });
    }
    if !(b.gap.is_finite() && b.gap > 0.0 && b.gap <= 1.0) {
        return Err(ApiError::Invalid {
            field: "/gap".into(),
            reason: format!("must lie within 0–1 m, got {}", b.gap),
        });
    }
    let Reading {
        rig,
        revision: rig_revision,
        set,
        ..
    } = read_channel(
        &s,
        &id,
        Named {
            period: b.period,
            code: b.code.as_deref(),
            at: "/",
        },
    )?;
    let mut views = Vec::new();
    for (i, v) in b.views.iter().enumerate() {
        let camera = Channel::from_doc(&v.camera, &format!("/views/{i}/camera"))?;
        let key = slot(&id, v.view.as_deref(), &set, &format!("/views/{i}/view"))?;
        let frames = complete(&s, &key, &set, &format!("/views/{i}/view"))?;
        camera_sized(
            &frames,
            &camera,
            &format!("/views/{i}/camera/resolution"),
            "the captures",
        )?;
        views.push((camera, frames));
    }
    let screen = rig.doc.screen.clone();
    let (step, gap) = (b.step, b.gap);
    let fit = run_job(&s, move |_| {
        let opts = DecodeOptions::default();
        let decoded = views
            .iter()
            .map(|(_, frames)| decode(&set, frames, &opts))
            .collect::<crate::Result<Vec<_>>>()?;
        let points = triangulate(
            (&decoded[0], &views[0].0),
            (&decoded[1], &views[1].0),
            [set.width, set.height],
            step,
            gap,
        );
        fit_screen(&screen, &points).map_err(invalid_as_field)
    })
    .await?;
    Ok(Json(serde_json::json!({
        "count": fit.count,
        "outliers": fit.outliers,
        "rms": fit.rms,
        "max": fit.max,
        "screen": fit.screen,
        "rig_screen": rig.doc.screen,
        "rig_revision": rig_revision,
    }))
    .into_response())
}

/// A library error naming its field, as the API names it.
/// A library refusal as a 400 naming `field` of the request, whatever the library called it.
fn invalid_at(field: &'static str) -> impl Fn(crate::Error) -> ApiError {
    move |e| match e {
        crate::Error::Invalid { reason, .. } => ApiError::Invalid {
            field: field.into(),
            reason,
        },
        other => other.into(),
    }
}

fn invalid_as_field(e: crate::Error) -> ApiError {
    match e {
        crate::Error::Invalid { name, reason } => ApiError::Invalid {
            field: name,
            reason,
        },
        other => other.into(),
    }
}

/// JSON has no NaN: a figure over no pixels is null.
fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

fn rejected(r: &crate::structured::decode::Rejected) -> serde_json::Value {
    serde_json::json!({"dark": r.dark, "flat": r.flat, "inconsistent": r.inconsistent,
        "outside": r.outside, "noisy": r.noisy, "edge": r.edge})
}
