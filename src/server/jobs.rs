//! Heavy work off the async runtime: a bounded pool of worker permits (503 + Retry-After beyond
//! it), cancellation when the client goes away, and the channel's computed warp, cached in
//! memory and kept on disk.

use super::ApiError;
use super::cache::{Computed, Geometry};
use super::state::AppState;
use super::store::Canvas;
use crate::image_io::{Precision, atomic_write, exr_bytes};
use crate::rig::Rig;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// What a job worked from.
pub struct Job {
    pub rig: Arc<Rig>,
    pub rig_revision: u64,
    pub tiles_revision: u64,
    pub canvas: Canvas,
    pub computed: Arc<Computed>,
}

impl Job {
    /// `"<rig>.<tiles>"`: changes whenever the output can.
    pub fn etag(&self) -> String {
        format!("\"{}.{}\"", self.rig_revision, self.tiles_revision)
    }
}

/// Sets the flag when dropped: a handler future dropped because its client went away stops
/// the blocking work it started.
struct CancelOnDrop(Arc<AtomicBool>);

impl Drop for CancelOnDrop {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Relaxed);
    }
}

/// Runs `work` on the blocking pool under a worker permit; `None` from `work` means cancelled.
pub async fn run_job<T: Send + 'static>(
    s: &Arc<AppState>,
    work: impl FnOnce(&AtomicBool) -> Option<T> + Send + 'static,
) -> Result<T, ApiError> {
    let _permit = s.workers.try_acquire().map_err(|_| ApiError::Busy)?;
    let flag = Arc::new(AtomicBool::new(false));
    let _guard = CancelOnDrop(flag.clone());
    let state = s.clone();
    tokio::task::spawn_blocking(move || {
        let out = work(&flag);
        let counter = if out.is_some() {
            &state.jobs_done
        } else {
            &state.jobs_cancelled
        };
        counter.fetch_add(1, Ordering::Relaxed);
        out
    })
    .await
    .map_err(|e| ApiError::Internal(e.to_string()))?
    .ok_or_else(|| ApiError::Internal("cancelled".into()))
}

pub fn warp_file(id: &str, rig_revision: u64, tiles_revision: u64) -> String {
    format!("warps/{id}-r{rig_revision}-t{tiles_revision}.exr")
}

/// The channel's current state and its computed warp (from the cache, or computed now).
pub async fn job(s: &Arc<AppState>, id: &str) -> Result<Job, ApiError> {
    let (rig, rig_revision) = s.store.snapshot();
    let data = s
        .store
        .channel(id)
        .ok_or_else(|| ApiError::NotFound(format!("no channel `{id}`")))?;
    let (tiles, tiles_revision, canvas) = {
        let g = data.lock().await;
        (
            g.tiles.value.clone(),
            g.tiles.revision,
            g.content.value.clone(),
        )
    };
    let key = (id.to_string(), rig_revision, tiles_revision);
    if let Some(c) = s.computed.lock().expect("cache lock").get(&key) {
        return Ok(Job {
            rig,
            rig_revision,
            tiles_revision,
            canvas,
            computed: c.clone(),
        });
    }
    let geometry = s
        .warps
        .lock()
        .expect("cache lock")
        .get(&(id.to_string(), rig_revision))
        .cloned();
    let (r, id2, state) = (rig.clone(), id.to_string(), s.clone());
    let computed = run_job(s, move |cancel| {
        let ch = r.channel(&id2).ok()?;
        let geometry = match geometry {
            Some(g) => g,
            None => {
                let warp = r.warp_unless(ch, cancel)?;
                let weights = r.blend_weights(ch, &warp.points);
                Arc::new(Geometry { warp, weights })
            }
        };
        state
            .warps
            .lock()
            .expect("cache lock")
            .insert((id2.clone(), rig_revision), geometry.clone());
        let (map, f) = match &tiles {
            Some(t) => {
                let fm = t.feature_map(ch.width as usize, ch.height as usize);
                (fm.normal_map(), Some(fm.f()))
            }
            None => (geometry.warp.map.clone(), None),
        };
        if cancel.load(Ordering::Relaxed) {
            return None;
        }
        if let Some(dir) = &state.store.dir {
            let path = dir.join(warp_file(&id2, rig_revision, tiles_revision));
            let mut attrs = map.attributes.clone();
            attrs.push(("omniwarp.rig_revision".into(), rig_revision.to_string()));
            attrs.push(("omniwarp.tiles_revision".into(), tiles_revision.to_string()));
            let written = std::fs::create_dir_all(dir.join("warps"))
                .map_err(|e| crate::Error::file(dir, e))
                .and_then(|_| exr_bytes(map.pixels(), &attrs, Precision::Float))
                .and_then(|bytes| {
                    atomic_write(&path, |f| {
                        std::io::Write::write_all(f, &bytes)
                            .map_err(|e| crate::Error::file(&path, e))
                    })
                });
            match written {
                Ok(()) => remove_older_warps(dir, &id2, &path),
                Err(e) => tracing::error!(error = %e, "could not keep the warp map"),
            }
        }
        Some(Arc::new(Computed { geometry, map, f }))
    })
    .await?;
    s.computed
        .lock()
        .expect("cache lock")
        .insert(key, computed.clone());
    Ok(Job {
        rig,
        rig_revision,
        tiles_revision,
        canvas,
        computed,
    })
}

fn remove_older_warps(dir: &std::path::Path, id: &str, keep: &std::path::Path) {
    let Ok(entries) = std::fs::read_dir(dir.join("warps")) else {
        return;
    };
    let prefix = format!("{id}-r");
    for e in entries.flatten() {
        let p = e.path();
        let name = e.file_name().to_string_lossy().into_owned();
        if p != keep && name.starts_with(&prefix) && name.ends_with(".exr") {
            let _ = std::fs::remove_file(p);
        }
    }
}
