//! Heavy work off the async runtime: a bounded pool of worker permits (503 + Retry-After beyond
//! it), cancellation when the client goes away, and the channel's computed warp, cached in
//! memory and kept on disk by a hash of its inputs.

use super::state::AppState;
use crate::rig::Canvas;
use crate::rig::Rig;
use crate::server::ApiError;
use crate::server::storage::cache::{Computed, Geometry};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// What a job worked from.
pub struct Job {
    pub rig: Arc<Rig>,
    pub rig_revision: u64,
    pub tiles_revision: u64,
    pub canvas: Canvas,
    pub computed: Arc<Computed>,
    /// A hash of everything the computed warp depends on (see [`keys`]).
    pub key: u64,
    /// How long computing the warp took, where this job computed it (`None`: it was kept).
    pub computed_in: Option<std::time::Duration>,
}

impl Job {
    /// `"<hash>-<rig>.<tiles>"`: changes whenever the output can, also when a revision number
    /// comes back after a fallback to a `.prev` file with other contents.
    pub fn etag(&self) -> String {
        etag(self.key, self.rig_revision, self.tiles_revision)
    }

    /// [`Job::etag`] with a hash of the canvas after it, for what the canvas shapes besides
    /// the warp (the exports).
    pub fn export_etag(&self) -> String {
        format!(
            "{}-{:016x}\"",
            self.etag().trim_end_matches('"'),
            self.canvas_digest()
        )
    }

    /// A hash of the channel's canvas.
    pub fn canvas_digest(&self) -> u64 {
        use std::hash::{Hash, Hasher};
        let mut h = std::collections::hash_map::DefaultHasher::new();
        serde_json::to_vec(&self.canvas)
            .expect("canvases serialise")
            .hash(&mut h);
        h.finish()
    }
}

pub fn etag(key: u64, rig_revision: u64, tiles_revision: u64) -> String {
    format!("\"{key:016x}-{rig_revision}.{tiles_revision}\"")
}

/// Cache keys by content, not revision number: the geometry's from the rig document and the
/// channel, the computed warp's from that, the tile screen and the canvas's projection centre.
/// (Revision numbers can repeat after a damaged file falls back to its `.prev`; contents that
/// differ cannot share a key.)
pub fn keys(
    rig: &Rig,
    id: &str,
    tiles: &Option<crate::tiles::TileScreen>,
    project_from: Option<[f64; 3]>,
) -> (u64, u64) {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    id.hash(&mut h);
    // The show's canvas is in the rig document but not in its geometry: a new canvas keeps
    // the warps (its projection centre, which moves them, is hashed below).
    let geometry = crate::rig::RigDoc {
        canvas: None,
        ..rig.doc.clone()
    };
    serde_json::to_vec(&geometry)
        .expect("rigs serialise")
        .hash(&mut h);
    // The document names a mesh; a mesh deleted and uploaded again under its name is another.
    if let crate::surface::Screen::Mesh {
        loaded: Some(mesh), ..
    } = &rig.doc.screen
    {
        mesh.digest().hash(&mut h);
    }
    let geometry = h.finish();
    serde_json::to_vec(tiles)
        .expect("tile screens serialise")
        .hash(&mut h);
    if let Some(c) = project_from {
        c.map(f64::to_bits).hash(&mut h);
    }
    (geometry, h.finish())
}

/// Sets the flag when dropped: a handler future dropped because its client went away stops
/// the blocking work it started.
struct CancelOnDrop(Arc<AtomicBool>);

impl Drop for CancelOnDrop {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Relaxed);
    }
}

/// Runs `work` on the blocking pool under a worker permit (503 when none is free). `work` sees
/// a flag that is set when the client goes away and should return [`crate::Error::Cancelled`]
/// soon after.
pub async fn run_job<T: Send + 'static>(
    s: &Arc<AppState>,
    work: impl FnOnce(&AtomicBool) -> Result<T, ApiError> + Send + 'static,
) -> Result<T, ApiError> {
    let permit = s
        .workers
        .clone()
        .try_acquire_owned()
        .map_err(|_| ApiError::Busy)?;
    run_with(s, permit, work).await
}

/// How long a write waits for a worker before it is answered 503: writes are short, so they
/// queue behind renders instead of failing at once.
pub const WRITE_WAIT: std::time::Duration = std::time::Duration::from_secs(5);

/// [`run_job`] for writes (tile edits, rig and mesh uploads): waits up to [`WRITE_WAIT`] for a
/// worker instead of answering 503 at once.
pub async fn run_write<T: Send + 'static>(
    s: &Arc<AppState>,
    work: impl FnOnce(&AtomicBool) -> Result<T, ApiError> + Send + 'static,
) -> Result<T, ApiError> {
    let permit = tokio::time::timeout(WRITE_WAIT, s.workers.clone().acquire_owned())
        .await
        .map_err(|_| ApiError::Busy)?
        .map_err(|_| ApiError::Busy)?;
    run_with(s, permit, work).await
}

/// The permit moves into the blocking task: a worker counts as busy until its work has
/// really stopped, not merely until the client left.
async fn run_with<T: Send + 'static>(
    s: &Arc<AppState>,
    permit: tokio::sync::OwnedSemaphorePermit,
    work: impl FnOnce(&AtomicBool) -> Result<T, ApiError> + Send + 'static,
) -> Result<T, ApiError> {
    let flag = Arc::new(AtomicBool::new(false));
    let _guard = CancelOnDrop(flag.clone());
    let state = s.clone();
    tokio::task::spawn_blocking(move || {
        let _permit = permit;
        let out = work(&flag);
        let counter = if flag.load(Ordering::Relaxed) {
            &state.jobs_cancelled
        } else {
            &state.jobs_done
        };
        counter.fetch_add(1, Ordering::Relaxed);
        out
    })
    .await
    .map_err(|e| ApiError::Internal(e.to_string()))?
}

fn cancelled(cancel: &AtomicBool) -> Result<(), ApiError> {
    if cancel.load(Ordering::Relaxed) {
        Err(crate::Error::Cancelled.into())
    } else {
        Ok(())
    }
}

/// What a channel's outputs are computed from right now, with its cache keys (see [`keys`]).
pub struct Inputs {
    pub rig: Arc<Rig>,
    pub rig_revision: u64,
    pub tiles: Option<crate::tiles::TileScreen>,
    pub tiles_revision: u64,
    pub canvas: Canvas,
    pub geometry_key: u64,
    pub key: u64,
}

/// The channel's current state, read once under its lock.
pub async fn inputs(s: &Arc<AppState>, id: &str) -> Result<Inputs, ApiError> {
    let (rig, rig_revision) = s.store.snapshot();
    let data = s
        .store
        .channel(id)
        .ok_or_else(|| ApiError::NotFound(format!("no channel `{id}`")))?;
    let (tiles, tiles_revision, canvas) = {
        let now = data.read();
        (
            now.tiles.value.clone(),
            now.tiles.revision,
            now.content.value.clone().unwrap_or_else(|| rig.canvas()),
        )
    };
    let (geometry_key, key) = keys(&rig, id, &tiles, canvas.project_from);
    Ok(Inputs {
        rig,
        rig_revision,
        tiles,
        tiles_revision,
        canvas,
        geometry_key,
        key,
    })
}

/// The channel's current state and its computed warp (from the cache, or computed now).
pub async fn job(s: &Arc<AppState>, id: &str) -> Result<Job, ApiError> {
    job_from(s, id, inputs(s, id).await?).await
}

/// [`job`] from inputs already read.
pub async fn job_from(s: &Arc<AppState>, id: &str, inputs: Inputs) -> Result<Job, ApiError> {
    let Inputs {
        rig,
        rig_revision,
        tiles,
        tiles_revision,
        canvas,
        geometry_key,
        key,
    } = inputs;
    // The channel's entry: its warp now, or the one before this change.
    let kept = s
        .computed
        .lock()
        .expect("cache lock")
        .iter()
        .find(|(k, _)| k.0 == id)
        .map(|(k, c)| (k.1, c.clone()));
    let previous = match kept {
        Some((k, c)) if k == key => {
            return Ok(Job {
                rig,
                rig_revision,
                tiles_revision,
                canvas,
                computed: c,
                key,
                computed_in: None,
            });
        }
        kept => kept.map(|(_, c)| c),
    };
    let started = std::time::Instant::now();
    let geometry = s
        .warps
        .lock()
        .expect("cache lock")
        .get(&(id.to_string(), geometry_key))
        .cloned();
    let centre = canvas.centre(&rig).map_err(|e| {
        ApiError::refused(
            axum::http::StatusCode::CONFLICT,
            Some("/project_from"),
            format!(
                "the content canvas's projection centre does not fit the current rig ({}); \
                 PUT /v1/channels/{id}/content with another",
                e.reason()
            ),
        )
    })?;
    let (r, id2, state) = (rig.clone(), id.to_string(), s.clone());
    let computed = run_job(s, move |cancel| {
        let ch = r.channel(&id2)?;
        let geometry = match geometry {
            Some(g) => g,
            None => {
                let warp = r.warp_unless(ch, cancel).ok_or(crate::Error::Cancelled)?;
                let weights = r.blend_weights(ch, &warp.points);
                // Every channel is lifted to the rig's one black (docs/photometry.md); the
                // target is searched again per channel, a fraction of its warp's time.
                let lift = r
                    .has_black()
                    .then(|| r.black_lift(ch, &warp.points, &weights, r.black_target()));
                Arc::new(Geometry {
                    warp,
                    weights,
                    lift,
                })
            }
        };
        {
            // One geometry per channel: the one of the rig now current.
            let mut warps = state.warps.lock().expect("cache lock");
            warps.retain(|k, _| k.0 != id2);
            warps.insert((id2.clone(), geometry_key), geometry.clone());
        }
        let (map, f, redrawn) = match &tiles {
            Some(t) => {
                let (map, f, rows) = tile_map(t, &geometry, previous.as_deref());
                (map, Some(f), rows)
            }
            None => (geometry.warp.map.clone(), None, None),
        };
        let drawn_from = tiles.clone().filter(|_| centre.is_none());
        // A projected panorama (seed 001): the tile screen's directions, or the geometry's
        // wall points where no screen moved them, seen from the canvas's centre.
        let map = match centre {
            Some(c) => {
                let points = tiles.is_none().then_some(&geometry.warp.points[..]);
                r.projected(&map, points, c, cancel)
                    .ok_or(crate::Error::Cancelled)?
            }
            None => map,
        };
        cancelled(cancel)?;
        Ok(Arc::new(Computed {
            geometry,
            map,
            f,
            drawn_from,
            redrawn,
            exr: Default::default(),
        }))
    })
    .await?;
    if let Some(dir) = s.store.dir.clone() {
        // Kept for a restart, not needed by this request: written (32 MB of EXR for a 1080p
        // channel, with an fsync) after the answer, by one writer that skips to the newest
        // warp of each channel when edits come faster than it writes.
        s.keeper
            .keep(dir, id, key, computed.clone(), rig_revision, tiles_revision);
    }
    {
        let mut cache = s.computed.lock().expect("cache lock");
        cache.retain(|k, _| k.0 != id);
        cache.insert((id.to_string(), key), computed.clone());
    }
    Ok(Job {
        rig,
        rig_revision,
        tiles_revision,
        canvas,
        computed,
        key,
        computed_in: Some(started.elapsed()),
    })
}

/// A tile screen's map and f for a channel. After an edit of the screen the channel's previous
/// warp was drawn from (on the same geometry), only the rows the edit changed are drawn again,
/// into copies of the previous map and f (the rows, returned): the same values as drawing it
/// all, in a fraction of the time when an edit moves a few features.
fn tile_map(
    t: &crate::tiles::TileScreen,
    geometry: &Arc<Geometry>,
    previous: Option<&Computed>,
) -> (
    crate::normalmap::NormalMap,
    Vec<f32>,
    Option<std::ops::Range<usize>>,
) {
    let mask = &geometry.warp.map;
    let (w, h) = (mask.width(), mask.height());
    let draw = |rows: std::ops::Range<usize>| {
        let mut fm = t.feature_rows(w, h, rows);
        fm.cut_by(mask);
        fm
    };
    if let Some(p) = previous.filter(|p| Arc::ptr_eq(&p.geometry, geometry))
        && let (Some(before), Some(f)) = (&p.drawn_from, &p.f)
        && let Some(rows) = before.rows_changed(t, h)
        && let Some((map, f)) = draw(rows.clone()).spliced(&p.map, f)
    {
        return (map, f, Some(rows));
    }
    let fm = draw(0..h);
    (fm.normal_map(), fm.f(), None)
}
