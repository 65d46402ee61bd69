//! Render jobs over HTTP: `POST /v1/jobs` checks the request, the content and the channels'
//! warps at once (so a bad request is answered 400 or 409, not a failed job later), then queues
//! the job; the list, each job, cancelling, deleting and downloading what it made.

use crate::media::{Encoding, Input, Rate};
use crate::render::Filter;
use crate::server::ApiError;
use crate::server::http::jobs::{job, run_job};
use crate::server::http::state::{AppState, Query, parse_body};
use crate::server::renders::{self, Blend, CONTAINERS, Channel, Record, State, Work};
use axum::Json;
use axum::body::{Body, Bytes};
use axum::extract::{Path, State as With};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use std::path::{Component, PathBuf};
use std::sync::Arc;

/// The body of `POST /v1/jobs`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct JobRequest {
    /// A movie or an image sequence pattern (`shots/frame-%05d.png`) under the media folder.
    content: String,
    /// The channels to render (default: all of the rig's).
    #[serde(default)]
    channels: Option<Vec<String>>,
    /// `mp4` (default), `mov`, `mkv` or `nut`.
    #[serde(default)]
    container: Option<String>,
    encoder: Option<String>,
    crf: Option<u32>,
    preset: Option<String>,
    pix_fmt: Option<String>,
    #[serde(default)]
    blend: Blend,
    /// `nearest`, `bilinear` (default) or `bicubic`.
    #[serde(default)]
    filter: Option<String>,
    /// An image sequence's rate (`25`, `30000/1001`; default 30).
    frame_rate: Option<String>,
}

fn invalid(field: &str, reason: impl Into<String>) -> ApiError {
    ApiError::Invalid {
        field: field.into(),
        reason: reason.into(),
    }
}

/// The media folder, or 409 when the daemon was started without one.
fn folder(s: &AppState) -> Result<PathBuf, ApiError> {
    s.renders.folder.clone().ok_or_else(|| {
        ApiError::refused(
            StatusCode::CONFLICT,
            None,
            "the daemon has no media folder: start it with `serve --media DIR` to render movies",
        )
    })
}

/// `content` as a path inside the media folder: relative, without `..`, and (symlinks
/// followed) still inside it.
fn inside(folder: &std::path::Path, content: &str) -> Result<PathBuf, ApiError> {
    let field = "/content";
    if content.is_empty() || content.len() > crate::limits::MEDIA_PATH || content.contains('\0') {
        return Err(invalid(
            field,
            format!(
                "must be a path of 1–{} bytes under the media folder",
                crate::limits::MEDIA_PATH
            ),
        ));
    }
    let rel = std::path::Path::new(content);
    if !rel.components().all(|c| matches!(c, Component::Normal(_))) {
        return Err(invalid(
            field,
            "must be a path under the media folder: relative, without `..` or `.`",
        ));
    }
    let path = folder.join(rel);
    // A sequence's pattern names no file; its folder must be inside.
    let (checked, sequence) = if crate::media::Sequence::is_pattern(&path) {
        (path.parent().unwrap_or(folder).to_path_buf(), true)
    } else {
        (path.clone(), false)
    };
    let real = checked
        .canonicalize()
        .map_err(|e| invalid(field, format!("`{content}`: {e}")))?;
    if !real.starts_with(folder) {
        return Err(invalid(field, "leads out of the media folder"));
    }
    if !sequence && !real.is_file() {
        return Err(invalid(field, format!("`{content}` is not a file")));
    }
    if !crate::media::is_media(&path) {
        return Err(invalid(
            field,
            format!(
                "must be a movie ({}) or an image sequence pattern (frame-%05d.png)",
                crate::media::MOVIE_EXTENSIONS.join(", ")
            ),
        ));
    }
    Ok(if sequence {
        real.join(path.file_name().expect("a pattern names a file"))
    } else {
        real
    })
}

fn filter(name: Option<&str>) -> Result<Filter, ApiError> {
    match name.unwrap_or("bilinear") {
        "nearest" => Ok(Filter::Nearest),
        "bilinear" => Ok(Filter::Bilinear),
        "bicubic" => Ok(Filter::Bicubic),
        other => Err(invalid(
            "/filter",
            format!("`{other}` is not nearest, bilinear or bicubic"),
        )),
    }
}

/// The refusal when the jobs are at a limit: too many waiting (or the daemon stopping), or
/// the list full.
fn full(waiting: bool) -> ApiError {
    if waiting {
        ApiError::refused(
            StatusCode::SERVICE_UNAVAILABLE,
            None,
            format!(
                "{} render jobs already wait their turn (or the daemon is stopping); retry when \
                 one has finished",
                crate::limits::RENDER_JOBS_WAITING
            ),
        )
    } else {
        ApiError::refused(
            StatusCode::CONFLICT,
            None,
            format!(
                "the daemon lists {} render jobs at most; DELETE finished ones first",
                crate::limits::RENDER_JOBS
            ),
        )
    }
}

pub async fn create(With(s): With<Arc<AppState>>, body: Bytes) -> Result<Response, ApiError> {
    let b: JobRequest = parse_body(&body)?;
    let folder = folder(&s)?;
    let container = b.container.clone().unwrap_or_else(|| "mp4".into());
    if !CONTAINERS.contains(&container.as_str()) {
        return Err(invalid(
            "/container",
            format!("`{container}` is not one of {}", CONTAINERS.join(", ")),
        ));
    }
    let filter = filter(b.filter.as_deref())?;
    let rate = b
        .frame_rate
        .as_deref()
        .map(|r| {
            Rate::parse(r).ok_or_else(|| {
                invalid(
                    "/frame_rate",
                    format!("`{r}` is not a frame rate (25, 29.97, 30000/1001)"),
                )
            })
        })
        .transpose()?;
    if let Some(crf) = b.crf.filter(|&c| c > 63) {
        return Err(invalid("/crf", format!("must be 0–63, got {crf}")));
    }
    let encoding = Encoding {
        encoder: b.encoder.clone(),
        crf: b.crf,
        preset: b.preset.clone(),
        pix_fmt: b.pix_fmt.clone(),
        options: Vec::new(),
        half: false,
    };
    encoding.check().map_err(|e| match e {
        crate::Error::Invalid { name, reason } => {
            invalid(&format!("/{}", name.replace('-', "_")), reason)
        }
        other => other.into(),
    })?;
    let (rig, _) = s.store.snapshot();
    let ids: Vec<String> = match &b.channels {
        Some(ids) => ids.clone(),
        None => rig.doc.channels.iter().map(|c| c.id.clone()).collect(),
    };
    if ids.is_empty() || ids.len() > crate::limits::MEDIA_OUTPUTS {
        return Err(invalid(
            "/channels",
            format!("name 1–{} channels", crate::limits::MEDIA_OUTPUTS),
        ));
    }
    for (k, id) in ids.iter().enumerate() {
        if rig.channel(id).is_err() {
            return Err(invalid(
                &format!("/channels/{k}"),
                format!("the rig has no channel `{id}`"),
            ));
        }
        if ids[..k].contains(id) {
            return Err(invalid(
                &format!("/channels/{k}"),
                format!("`{id}` is named twice"),
            ));
        }
    }
    // Refused now if it would be refused after the work below.
    s.renders.room().map_err(full)?;
    let mut channels = Vec::new();
    let mut canvases = Vec::new();
    let mut rig_revision = None;
    for id in &ids {
        let j = job(&s, id).await?;
        rig_revision.get_or_insert(j.rig_revision);
        canvases.push((id.clone(), j.canvas.clone()));
        channels.push(Channel {
            id: id.clone(),
            computed: j.computed,
        });
    }
    let canvas = canvases[0].1.clone();
    // The path resolved, the content probed and laid out on every channel's canvas now, on
    // the blocking pool, so that what cannot work is refused here rather than failing later.
    let content = b.content.clone();
    let input = run_job(&s, move |_| {
        let path = inside(&folder, &content)?;
        let input = Input::open_within(&path, rate, Some(&folder)).map_err(|e| match e {
            crate::Error::Invalid { name, reason } if name == "frame-rate" => {
                invalid("/frame_rate", reason)
            }
            crate::Error::Invalid { reason, .. } => {
                invalid("/content", renders::private(&reason, &folder))
            }
            other => invalid("/content", renders::private(&other.to_string(), &folder)),
        })?;
        let mut first = None;
        for (id, c) in &canvases {
            let layout = c.layout(input.size()).map_err(|e| match e {
                crate::Error::Invalid { name, reason } => ApiError::refused(
                    StatusCode::CONFLICT,
                    Some(&name),
                    format!(
                        "channel `{id}`'s content canvas (GET /v1/channels/{id}/content) \
                         cannot hold this content: {reason}"
                    ),
                ),
                other => other.into(),
            })?;
            match &first {
                None => first = Some((id, layout)),
                Some((one, l)) if *l != layout => {
                    return Err(ApiError::refused(
                        StatusCode::CONFLICT,
                        Some("/channels"),
                        format!(
                            "channels `{one}` and `{id}` lay the content out on different \
                             canvases; render them in separate jobs"
                        ),
                    ));
                }
                Some(_) => {}
            }
        }
        Ok(input)
    })
    .await?;
    let record = Record {
        id: 0,
        state: State::Queued,
        content: b.content.clone(),
        channels: ids,
        container,
        blend: b.blend,
        rig_revision: rig_revision.unwrap_or_default(),
        created_ms: std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_millis() as i64),
        finished_ms: None,
        frame: 0,
        frames: input.frames(),
        fps: None,
        eta_seconds: None,
        files: Vec::new(),
        error: None,
    };
    let work = Work {
        input,
        channels,
        canvas,
        encoding,
        filter,
    };
    let queued = renders::submit(&s, record, work, b.blend)
        .await
        .map_err(full)?;
    let mut resp = (StatusCode::ACCEPTED, Json(&queued)).into_response();
    if let Ok(v) = format!("/v1/jobs/{}", queued.id).parse() {
        resp.headers_mut().insert(header::LOCATION, v);
    }
    Ok(resp)
}

pub async fn list(With(s): With<Arc<AppState>>) -> Json<serde_json::Value> {
    Json(serde_json::json!({ "jobs": s.renders.list() }))
}

/// A job id from the path; anything but a number names no job.
fn job_id(id: &str) -> Result<u64, ApiError> {
    id.parse()
        .map_err(|_| ApiError::NotFound(format!("no job `{id}`: ids are numbers")))
}

fn no_job(id: u64) -> ApiError {
    ApiError::NotFound(format!("no job {id}"))
}

/// `?wait=S` on a job's GET: answer once the job has ended, or after S seconds.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JobQuery {
    wait: Option<f64>,
}

/// The longest `?wait=` a job's GET takes, seconds.
const LONGEST_WAIT: f64 = 60.0;

pub async fn get_job(
    With(s): With<Arc<AppState>>,
    Path(id): Path<String>,
    Query(q): Query<JobQuery>,
) -> Result<Json<Record>, ApiError> {
    let id = job_id(&id)?;
    let wait = match q.wait {
        None => 0.0,
        Some(w) if (0.0..=LONGEST_WAIT).contains(&w) => w,
        Some(w) => {
            return Err(invalid(
                "wait",
                format!("must be 0–{LONGEST_WAIT} seconds, got {w}"),
            ));
        }
    };
    let until = tokio::time::Instant::now() + std::time::Duration::from_secs_f64(wait);
    loop {
        let r = s.renders.get(id).ok_or_else(|| no_job(id))?;
        if r.state.finished() || tokio::time::Instant::now() >= until {
            return Ok(Json(r));
        }
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
    }
}

/// How long a cancel waits for a running job to stop before answering with it still running.
const CANCEL_WAIT: std::time::Duration = std::time::Duration::from_secs(10);

pub async fn cancel(
    With(s): With<Arc<AppState>>,
    Path(id): Path<String>,
) -> Result<Json<Record>, ApiError> {
    let id = job_id(&id)?;
    match s.renders.get(id) {
        None => return Err(no_job(id)),
        Some(r) if r.state.finished() => {
            return Err(ApiError::refused(
                StatusCode::CONFLICT,
                None,
                format!("job {id} has already ended ({:?})", r.state).to_lowercase(),
            ));
        }
        Some(_) => {}
    }
    renders::cancel(&s, id, CANCEL_WAIT)
        .await
        .map(Json)
        .ok_or_else(|| no_job(id))
}

pub async fn delete(
    With(s): With<Arc<AppState>>,
    Path(id): Path<String>,
) -> Result<StatusCode, ApiError> {
    let id = job_id(&id)?;
    match s.renders.ended(id) {
        None => Err(no_job(id)),
        Some(Err(_)) => Err(ApiError::refused(
            StatusCode::CONFLICT,
            None,
            format!("job {id} has not ended: POST /v1/jobs/{id}/cancel first"),
        )),
        Some(Ok(())) => {
            // The folder first: a job whose files could not be removed stays listed.
            let state = s.clone();
            tokio::task::spawn_blocking(move || state.renders.delete(id))
                .await
                .map_err(|e| ApiError::Internal(e.to_string()))?
                .map_err(|e| ApiError::Internal(e.to_string()))?;
            Ok(StatusCode::NO_CONTENT)
        }
    }
}

/// A file a finished job made, streamed from disk (movies are large).
pub async fn file(
    With(s): With<Arc<AppState>>,
    Path((id, name)): Path<(String, String)>,
) -> Result<Response, ApiError> {
    let id = job_id(&id)?;
    let r = s.renders.get(id).ok_or_else(|| no_job(id))?;
    let Some(f) = r.files.iter().find(|f| f.name == name) else {
        let names: Vec<&str> = r.files.iter().map(|f| f.name.as_str()).collect();
        return Err(ApiError::NotFound(match r.state {
            State::Done => format!("job {id} made no `{name}`; it made {}", names.join(", ")),
            other => format!("job {id} is {other:?} and has no files").to_lowercase(),
        }));
    };
    let path = s.renders.dir(id).ok_or_else(|| no_job(id))?.join(&f.name);
    let gone = |e: std::io::Error| {
        ApiError::NotFound(format!("job {id}'s `{name}` is no longer there: {e}"))
    };
    // The job's own file, not a link someone put in its place.
    let file = tokio::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOFOLLOW)
        .open(&path)
        .await
        .map_err(gone)?;
    let bytes = file.metadata().await.map_err(gone)?.len();
    let kind = match name.rsplit('.').next() {
        Some("mp4") => "video/mp4",
        Some("mov") => "video/quicktime",
        Some("mkv") => "video/x-matroska",
        Some("png") => "image/png",
        _ => "application/octet-stream",
    };
    let chunks = futures_util::stream::unfold(file, |mut file| async move {
        use tokio::io::AsyncReadExt;
        let mut buf = vec![0u8; 256 << 10];
        match file.read(&mut buf).await {
            Ok(0) => None,
            Ok(n) => {
                buf.truncate(n);
                Some((Ok::<_, std::io::Error>(Bytes::from(buf)), file))
            }
            Err(e) => Some((Err(e), file)),
        }
    });
    Ok((
        [
            (header::CONTENT_TYPE, kind.to_string()),
            (header::CONTENT_LENGTH, bytes.to_string()),
            (
                header::CONTENT_DISPOSITION,
                format!("attachment; filename=\"{}\"", f.name),
            ),
        ],
        Body::from_stream(chunks),
    )
        .into_response())
}
