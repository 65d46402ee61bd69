//! Render jobs: a movie or an image sequence from the daemon's media folder through the warps of
//! chosen channels, one blended movie per channel from a single decode (the `render --out-dir`
//! frame loop), run one at a time beside the API under a worker permit, with progress on the
//! change feed.
//!
//! Each job keeps its outputs and a `job.json` record in `<media>/renders/<id>/`, written
//! atomically at every change of state, so the list survives a restart; a job the daemon
//! stopped in (killed, or shut down) comes back failed, its partial files removed.

mod run;

use crate::media::{Encoding, Input};
use crate::render::Filter;
use crate::rig::Canvas;
use crate::server::storage::cache::Computed;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

/// Where a job stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum State {
    /// Waiting for its turn (one job runs at a time).
    Queued,
    /// Decoding, warping and encoding.
    Running,
    /// Finished: its files are complete.
    Done,
    /// Stopped by an error; nothing of it kept.
    Failed,
    /// Stopped on request (or by the daemon's shutdown); nothing of it kept.
    Cancelled,
}

impl State {
    /// Whether the job has stopped for good.
    pub fn finished(self) -> bool {
        matches!(self, State::Done | State::Failed | State::Cancelled)
    }
}

/// What the blend does to a job's outputs.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Blend {
    /// Multiplied into the frames.
    #[default]
    Baked,
    /// Written beside each movie as `<channel>-blend.png`, the frames left unblended.
    Separate,
    /// Left out.
    None,
}

/// A file a job made.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct File {
    /// Its name in the job's folder (and in `GET /v1/jobs/{id}/files/{name}`).
    pub name: String,
    /// The channel it is for.
    pub channel: String,
    /// Its size, bytes.
    pub bytes: u64,
}

/// Why a job failed: the field at fault where there is one, and the reason.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Failure {
    /// The field at fault (a JSON pointer), where there is one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub field: Option<String>,
    /// What went wrong.
    pub reason: String,
}

/// A job as the API shows it and `job.json` keeps it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Record {
    /// The job's number, never reused while the media folder keeps its folder.
    pub id: u64,
    /// Where it stands.
    pub state: State,
    /// The content, as a path under the media folder.
    pub content: String,
    /// The channels rendered, in order.
    pub channels: Vec<String>,
    /// The container of the outputs (`mp4`, `mov`, `mkv`, `nut`).
    pub container: String,
    /// What the blend does to the outputs.
    pub blend: Blend,
    /// The rig revision the warps were taken from.
    pub rig_revision: u64,
    /// When the job was asked for, milliseconds since 1970.
    pub created_ms: i64,
    /// When it ended, milliseconds since 1970.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub finished_ms: Option<i64>,
    /// Frames done.
    pub frame: u64,
    /// Frames in all, when the content says.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frames: Option<u64>,
    /// Frames a second so far.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fps: Option<f64>,
    /// Seconds left at that rate.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub eta_seconds: Option<f64>,
    /// What a finished job made.
    pub files: Vec<File>,
    /// Why it failed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<Failure>,
}

/// One channel of a job: its warp as the daemon had computed it when the job was asked for.
pub struct Channel {
    /// The channel's id.
    pub id: String,
    /// Its warp map, blend weights and tile screen's saturation.
    pub computed: Arc<Computed>,
}

/// Everything a job runs from, checked when it was asked for.
pub struct Work {
    /// The content, probed.
    pub input: Input,
    /// The channels, in the order of the outputs.
    pub channels: Vec<Channel>,
    /// The content canvas all the channels share.
    pub canvas: Canvas,
    /// How the movies are encoded.
    pub encoding: Encoding,
    /// The texture filter.
    pub filter: Filter,
}

struct Entry {
    record: Mutex<Record>,
    stop: AtomicBool,
    /// Held from reading the record to having kept and announced it, so that two changes
    /// are kept in the order they were made; true once the job's folder is deleted, after
    /// which nothing is kept (a late change would bring the record back).
    saving: Mutex<bool>,
}

impl Entry {
    fn new(record: Record) -> Arc<Entry> {
        Arc::new(Entry {
            record: Mutex::new(record),
            stop: AtomicBool::new(false),
            saving: Mutex::new(false),
        })
    }

    /// The record, also after a panic elsewhere left its lock poisoned.
    fn record(&self) -> std::sync::MutexGuard<'_, Record> {
        self.record.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// The daemon's render jobs and its media folder.
pub struct Renders {
    /// The media folder, canonical (`serve --media`); `None`: jobs are refused.
    pub folder: Option<PathBuf>,
    jobs: Mutex<BTreeMap<u64, Arc<Entry>>>,
    next: AtomicU64,
    /// One job runs at a time: a movie keeps every core busy by itself.
    turn: Arc<tokio::sync::Semaphore>,
    /// Set when the daemon shuts down: no job is taken or started after it.
    closed: AtomicBool,
}

/// The `job.json` name in a job's folder.
const RECORD: &str = "job.json";

fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as i64)
}

/// Containers a job writes.
pub const CONTAINERS: [&str; 4] = ["mp4", "mov", "mkv", "nut"];

/// Whether a record read back from disk names only what a job of its own makes: its own
/// folder's number, a known container, and files `<channel>.<container>` or
/// `<channel>-blend.png` of its channels (a hand-edited record could otherwise point a
/// download anywhere).
fn sound(record: &Record, dir: &Path) -> bool {
    let plain = |c: &str| {
        !c.is_empty()
            && c.bytes()
                .all(|b| b.is_ascii_alphanumeric() || b"._-".contains(&b))
            && !c.starts_with('.')
    };
    dir.file_name() == Some(std::ffi::OsStr::new(&record.id.to_string()))
        && CONTAINERS.contains(&record.container.as_str())
        && record.channels.iter().all(|c| plain(c))
        && record.files.iter().all(|f| {
            record.channels.contains(&f.channel)
                && (f.name == format!("{}.{}", f.channel, record.container)
                    || f.name == format!("{}-blend.png", f.channel))
        })
}

/// Whether `path` is a real folder, not a symbolic link to one.
fn real_dir(path: &Path) -> bool {
    std::fs::symlink_metadata(path).is_ok_and(|m| m.is_dir())
}

impl Renders {
    /// The jobs kept under `folder`'s `renders/`; a job the daemon stopped in is marked failed
    /// and its partial files removed. Records that cannot be read, name what their job could
    /// not have made, or sit behind a symbolic link are left alone, with a warning.
    pub fn open(folder: Option<&Path>) -> Renders {
        let mut jobs = BTreeMap::new();
        let mut taken = 0;
        let root = folder.map(|f| f.join("renders"));
        let mut folder = folder;
        if let Some(root) = root.as_ref().filter(|r| r.exists() && !real_dir(r)) {
            tracing::warn!(path = %root.display(), "renders/ is not a folder of its own; render jobs are off");
            folder = None;
        } else if let Some(dirs) = root.and_then(|r| std::fs::read_dir(r).ok()) {
            let dirs: Vec<PathBuf> = dirs.flatten().map(|d| d.path()).collect();
            // New jobs take numbers after every folder there, read or not.
            taken = dirs
                .iter()
                .filter_map(|d| d.file_name()?.to_str()?.parse::<u64>().ok())
                .filter(|&n| n < 1 << 40)
                .max()
                .unwrap_or(0);
            for dir in dirs.into_iter().filter(|d| real_dir(d)) {
                let path = dir.join(RECORD);
                let Ok(text) = std::fs::read(&path) else {
                    continue;
                };
                let mut record: Record = match serde_json::from_slice(&text) {
                    Ok(r) if sound(&r, &dir) => r,
                    Ok(_) => {
                        tracing::warn!(path = %path.display(), "a render job's record names files its job could not have made; left alone");
                        continue;
                    }
                    Err(e) => {
                        tracing::warn!(path = %path.display(), error = %e, "a render job's record cannot be read; left alone");
                        continue;
                    }
                };
                if !record.state.finished() {
                    clear(&dir);
                    record.state = State::Failed;
                    record.finished_ms = Some(now_ms());
                    record.files.clear();
                    record.error = Some(Failure {
                        field: None,
                        reason: "the daemon stopped before the job finished; nothing of it was \
                                 kept"
                            .into(),
                    });
                    if let Err(e) = save(&dir, &record) {
                        tracing::warn!(error = %e, "cannot mark an interrupted render job failed");
                    }
                }
                jobs.insert(record.id, Entry::new(record));
            }
        }
        let next = taken.max(jobs.keys().next_back().copied().unwrap_or(0)) + 1;
        Renders {
            folder: folder.map(Path::to_path_buf),
            jobs: Mutex::new(jobs),
            next: AtomicU64::new(next),
            turn: Arc::new(tokio::sync::Semaphore::new(1)),
            closed: AtomicBool::new(false),
        }
    }

    fn jobs(&self) -> std::sync::MutexGuard<'_, BTreeMap<u64, Arc<Entry>>> {
        self.jobs.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Every job, newest first.
    pub fn list(&self) -> Vec<Record> {
        self.jobs()
            .values()
            .rev()
            .map(|e| e.record().clone())
            .collect()
    }

    /// Job `id` as it stands.
    pub fn get(&self, id: u64) -> Option<Record> {
        self.jobs().get(&id).map(|e| e.record().clone())
    }

    /// The folder of job `id`.
    pub fn dir(&self, id: u64) -> Option<PathBuf> {
        self.folder
            .as_ref()
            .map(|f| f.join("renders").join(id.to_string()))
    }

    /// Whether a new job would be taken: `Err(true)` when too many wait (or the daemon is
    /// shutting down), `Err(false)` when the list is full.
    pub fn room(&self) -> Result<(), bool> {
        Self::room_in(&self.jobs(), &self.closed)
    }

    fn room_in(jobs: &BTreeMap<u64, Arc<Entry>>, closed: &AtomicBool) -> Result<(), bool> {
        let active = jobs
            .values()
            .filter(|e| !e.record().state.finished())
            .count();
        if active > crate::limits::RENDER_JOBS_WAITING || closed.load(Ordering::Relaxed) {
            return Err(true);
        }
        if jobs.len() >= crate::limits::RENDER_JOBS {
            return Err(false);
        }
        Ok(())
    }

    /// Takes a new job, queued, if [`Renders::room`] says so.
    fn admit(&self, mut record: Record) -> Result<(Arc<Entry>, PathBuf), bool> {
        let mut jobs = self.jobs();
        Self::room_in(&jobs, &self.closed)?;
        record.id = self.next.fetch_add(1, Ordering::Relaxed);
        let dir = self
            .dir(record.id)
            .expect("admitted only with a media folder");
        let entry = Entry::new(record.clone());
        jobs.insert(record.id, entry.clone());
        Ok((entry, dir))
    }

    /// Whether job `id` has ended, so that it may be deleted: `Err` with its record when it
    /// has not.
    pub fn ended(&self, id: u64) -> Option<Result<(), Record>> {
        let record = self.jobs().get(&id)?.record().clone();
        Some(if record.state.finished() {
            Ok(())
        } else {
            Err(record)
        })
    }

    /// Deletes ended job `id`: its folder, then the job itself. A change of its record still
    /// on its way is dropped rather than bringing the folder back. Blocking.
    pub fn delete(&self, id: u64) -> std::io::Result<()> {
        let Some(entry) = self.jobs().get(&id).cloned() else {
            return Ok(());
        };
        let mut gone = entry.saving.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(dir) = self.dir(id) {
            match std::fs::remove_dir_all(&dir) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => return Err(e),
                _ => {}
            }
        }
        *gone = true;
        self.jobs().remove(&id);
        Ok(())
    }

    /// Stops every job and takes no more (the daemon is shutting down), then waits up to
    /// `wait` for the running one to clean up after itself.
    pub async fn stop_all(&self, wait: std::time::Duration) {
        let entries: Vec<_> = {
            let jobs = self.jobs();
            self.closed.store(true, Ordering::Relaxed);
            jobs.values().cloned().collect()
        };
        for e in &entries {
            e.stop.store(true, Ordering::Relaxed);
        }
        let until = tokio::time::Instant::now() + wait;
        while entries.iter().any(|e| e.record().state == State::Running)
            && tokio::time::Instant::now() < until
        {
            tokio::time::sleep(std::time::Duration::from_millis(20)).await;
        }
    }
}

/// Writes a job's record atomically into its folder.
fn save(dir: &Path, record: &Record) -> crate::Result<()> {
    let text = serde_json::to_vec_pretty(record).expect("records serialise");
    crate::image_io::atomic_write(&dir.join(RECORD), |f| {
        std::io::Write::write_all(f, &text).map_err(|e| crate::Error::file(dir.join(RECORD), e))
    })
}

/// Removes every file of a job's folder but its record.
fn clear(dir: &Path) {
    if let Ok(files) = std::fs::read_dir(dir) {
        for f in files.flatten() {
            if f.file_name() != RECORD {
                let _ = std::fs::remove_file(f.path());
            }
        }
    }
}

/// Queues `record` for `work`, kept on disk before this returns, and starts it when its turn
/// comes: the queued record, `Err(true)` when too many wait, `Err(false)` when the list is
/// full.
pub async fn submit(
    s: &Arc<crate::server::AppState>,
    record: Record,
    work: Work,
    blend: Blend,
) -> Result<Record, bool> {
    let (entry, dir) = s.renders.admit(record)?;
    let queued = entry.record().clone();
    let (kept, written) = tokio::sync::oneshot::channel();
    // The job's own task from here on: a client that goes away while its record is written
    // leaves a job that still runs, not one queued for ever.
    let state = s.clone();
    tokio::spawn(async move {
        let (st, e, d) = (state.clone(), entry.clone(), dir.clone());
        let made = tokio::task::spawn_blocking(move || {
            // A folder of its own: one already there (planted, or left by hand) is not used.
            if let Some(renders) = d.parent() {
                std::fs::create_dir_all(renders).map_err(|err| crate::Error::file(renders, err))?;
            }
            std::fs::create_dir(&d).map_err(|err| crate::Error::file(&d, err))?;
            update(&st, &e, &d, |_| {});
            Ok::<_, crate::Error>(())
        })
        .await
        .unwrap_or_else(|e| Err(crate::Error::invalid("job", e.to_string())));
        if let Err(e) = made {
            tracing::warn!(error = %e, "a render job's folder cannot be made");
            let mut r = entry.record();
            r.state = State::Failed;
            r.finished_ms = Some(now_ms());
            r.error = Some(Failure {
                field: None,
                reason: "its folder under renders/ could not be made".into(),
            });
            return;
        }
        let _ = kept.send(());
        turn(state, entry, dir, work, blend).await;
    });
    let _ = written.await;
    Ok(queued)
}

/// A job from the queue to its end: its turn, a worker permit for the whole run (previews
/// keep the others), the run on the blocking pool, the outcome kept.
async fn turn(
    s: Arc<crate::server::AppState>,
    entry: Arc<Entry>,
    dir: PathBuf,
    work: Work,
    blend: Blend,
) {
    // A job cancelled while it waits lets go at once, not when its turn would have come.
    let cancelled = async {
        while !entry.stop.load(Ordering::Relaxed) {
            tokio::time::sleep(std::time::Duration::from_millis(100)).await;
        }
    };
    let ready = async {
        let turn = s.renders.turn.clone().acquire_owned().await;
        let permit = s.workers.clone().acquire_owned().await;
        (turn, permit)
    };
    let (Ok(_turn), Ok(permit)) = (tokio::select! {
        got = ready => got,
        () = cancelled => return,
    }) else {
        return;
    };
    let (st, e, d) = (s.clone(), entry.clone(), dir.clone());
    let ran = tokio::task::spawn_blocking(move || {
        let _permit = permit;
        let started = {
            let mut r = e.record();
            let go = r.state == State::Queued
                && !e.stop.load(Ordering::Relaxed)
                && !st.renders.closed.load(Ordering::Relaxed);
            if go {
                r.state = State::Running;
            }
            go
        };
        if !started {
            // Cancelled while it waited (the cancel kept that), or the daemon is stopping.
            return None;
        }
        update(&st, &e, &d, |_| {});
        Some(run::run(&st, &e, &d, work, blend))
    })
    .await;
    let outcome = match ran {
        Ok(None) => return,
        Ok(Some(outcome)) => outcome,
        // A panic in the frame loop: the job ends failed, not running for ever.
        Err(e) => {
            tracing::error!(error = %e, "a render job stopped on an internal error");
            Err(crate::Error::invalid(
                "job",
                "the job stopped on an internal error; the daemon's log has its detail",
            ))
        }
    };
    let stopping = *s.stopping.borrow();
    let folder = s.renders.folder.clone().unwrap_or_default();
    let _ = tokio::task::spawn_blocking(move || {
        if outcome.is_err() {
            clear(&dir);
        }
        update(&s, &entry, &dir, |r| {
            r.finished_ms = Some(now_ms());
            r.eta_seconds = None;
            match outcome {
                Ok(files) => {
                    r.state = State::Done;
                    r.files = files;
                }
                Err(crate::Error::Cancelled) => {
                    r.state = State::Cancelled;
                    if stopping {
                        r.error = Some(Failure {
                            field: None,
                            reason: "the daemon was stopped".into(),
                        });
                    }
                }
                Err(e) => {
                    tracing::warn!(job = r.id, error = %e, "render job failed");
                    r.state = State::Failed;
                    let (field, reason) = match e {
                        crate::Error::Invalid { name, reason } => (Some(name), reason),
                        other => (None, other.to_string()),
                    };
                    r.error = Some(Failure {
                        field,
                        reason: private(&reason, &folder),
                    });
                }
            }
        });
    })
    .await;
}

/// `reason` without where the media folder is: paths in it as the client names them.
pub fn private(reason: &str, folder: &Path) -> String {
    let folder = folder.display().to_string();
    if folder.is_empty() {
        return reason.to_string();
    }
    reason
        .replace(&format!("{folder}/"), "")
        .replace(&folder, "the media folder")
}

/// Asks job `id` to stop and waits (up to `wait`) until it has: a queued job is cancelled at
/// once, a running one between two frames. Its record, `None` if there is no such job.
pub async fn cancel(
    s: &Arc<crate::server::AppState>,
    id: u64,
    wait: std::time::Duration,
) -> Option<Record> {
    let entry = s.renders.jobs().get(&id).cloned()?;
    entry.stop.store(true, Ordering::Relaxed);
    let was_queued = {
        let mut r = entry.record();
        let queued = r.state == State::Queued;
        if queued {
            r.state = State::Cancelled;
            r.finished_ms = Some(now_ms());
        }
        queued
    };
    if was_queued && let Some(dir) = s.renders.dir(id) {
        let (st, e) = (s.clone(), entry.clone());
        let _ = tokio::task::spawn_blocking(move || update(&st, &e, &dir, |_| {})).await;
    }
    let until = tokio::time::Instant::now() + wait;
    loop {
        let r = entry.record().clone();
        if r.state.finished() || tokio::time::Instant::now() >= until {
            return Some(r);
        }
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    }
}

/// Changes a job's record, keeps it and announces it, in the order the changes are made.
fn update(
    s: &crate::server::AppState,
    entry: &Entry,
    dir: &Path,
    change: impl FnOnce(&mut Record),
) {
    let gone = entry.saving.lock().unwrap_or_else(|e| e.into_inner());
    let record = {
        let mut r = entry.record();
        change(&mut r);
        r.clone()
    };
    if *gone {
        return;
    }
    if let Err(e) = save(dir, &record) {
        tracing::warn!(job = record.id, error = %e, "cannot keep a render job's record");
    }
    announce(s, &record);
}

fn announce(s: &crate::server::AppState, r: &Record) {
    s.announce(serde_json::json!({
        "kind": "job", "id": r.id, "state": r.state, "frame": r.frame, "frames": r.frames,
        "fps": r.fps, "eta_seconds": r.eta_seconds,
    }));
}
