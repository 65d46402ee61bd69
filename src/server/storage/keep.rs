//! Computed warps kept on disk (`warps/<id>-<hash>.exr`) so a restarted daemon serves them
//! without recomputing: written after the answer that computed them, by one thread, once the
//! channel has had no newer warp for [`QUIET`].

use super::cache::Computed;
use crate::image_io::{Access, atomic_write_as, create_private_dir_durably};
use std::sync::{Arc, Condvar, Mutex, Once};
use std::time::{Duration, Instant};

/// Where a channel's warp computed from inputs with hash `key` is kept.
pub fn warp_file(id: &str, key: u64) -> String {
    format!("warps/{id}-{key:016x}.exr")
}

/// How long a channel's newest warp waits before it is written. While a technician edits,
/// each edit's warp replaces the last one waiting, so the writing (a 1080p warp is 32 MB of
/// EXR, encoded and synced) does not take a core from the previews of the edits that follow;
/// it is a cache for a restart, which recomputes whatever was not yet written.
const QUIET: Duration = Duration::from_secs(1);

/// Writes computed warps to disk in the background, one at a time, the newest per channel.
pub struct Keeper {
    pending: Arc<(Mutex<Vec<Keep>>, Condvar)>,
    started: Once,
}

/// One warp to keep.
struct Keep {
    dir: std::path::PathBuf,
    id: String,
    key: u64,
    computed: Arc<Computed>,
    revisions: (u64, u64),
    /// When it was queued.
    at: Instant,
}

impl Default for Keeper {
    fn default() -> Self {
        Keeper {
            pending: Arc::new((Mutex::new(Vec::new()), Condvar::new())),
            started: Once::new(),
        }
    }
}

impl Keeper {
    pub fn keep(
        &self,
        dir: std::path::PathBuf,
        id: &str,
        key: u64,
        computed: Arc<Computed>,
        rig_revision: u64,
        tiles_revision: u64,
    ) {
        let pending = self.pending.clone();
        self.started.call_once(|| {
            let pending = pending.clone();
            let spawned = std::thread::Builder::new()
                .name("keep-warps".into())
                .spawn(move || {
                    loop {
                        let next = {
                            let (lock, ready) = &*pending;
                            let mut queue = lock.lock().expect("keeper lock");
                            // The oldest first: a newer warp of a channel replaces its
                            // waiting one at the back of the queue.
                            loop {
                                let waited = match queue.first() {
                                    Some(k) => k.at.elapsed(),
                                    None => {
                                        queue = ready.wait(queue).expect("keeper lock");
                                        continue;
                                    }
                                };
                                if waited >= QUIET {
                                    break queue.remove(0);
                                }
                                queue = ready
                                    .wait_timeout(queue, QUIET - waited)
                                    .expect("keeper lock")
                                    .0;
                            }
                        };
                        let (r, t) = next.revisions;
                        keep_warp(&next.dir, &next.id, next.key, &next.computed, r, t);
                    }
                });
            if let Err(e) = spawned {
                tracing::error!(error = %e, "no thread to keep warps with");
            }
        });
        let (lock, ready) = &*self.pending;
        let mut queue = lock.lock().expect("keeper lock");
        queue.retain(|k| k.id != id);
        queue.push(Keep {
            dir,
            id: id.to_string(),
            key,
            computed,
            revisions: (rig_revision, tiles_revision),
            at: Instant::now(),
        });
        ready.notify_one();
    }
}

/// Writes the warp map under `warps/` so a restarted daemon serves it without recomputing; a
/// failure costs only that, so it is logged, not returned.
fn keep_warp(
    dir: &std::path::Path,
    id: &str,
    key: u64,
    computed: &Computed,
    rig_revision: u64,
    tiles_revision: u64,
) {
    let path = dir.join(warp_file(id, key));
    let written = create_private_dir_durably(&dir.join("warps"))
        .and_then(|_| computed.exr(rig_revision, tiles_revision))
        .and_then(|bytes| {
            atomic_write_as(&path, Access::Private, true, |f| {
                std::io::Write::write_all(f, bytes).map_err(|e| crate::Error::file(&path, e))
            })
        });
    match written {
        Ok(_) => remove_older_warps(dir, id, &path),
        Err(e) => tracing::error!(error = %e, "could not keep the warp map"),
    }
}

fn remove_older_warps(dir: &std::path::Path, id: &str, keep: &std::path::Path) {
    let Ok(entries) = std::fs::read_dir(dir.join("warps")) else {
        return;
    };
    let prefix = format!("{id}-");
    for e in entries.flatten() {
        let p = e.path();
        let name = e.file_name().to_string_lossy().into_owned();
        // Another channel's id may start with this one's: match the hash's length too.
        let ours = name
            .strip_prefix(&prefix)
            .and_then(|rest| rest.strip_suffix(".exr"))
            .is_some_and(|hash| hash.len() == 16 && hash.bytes().all(|b| b.is_ascii_hexdigit()));
        if p != keep && ours {
            let _ = std::fs::remove_file(p);
        }
    }
}
