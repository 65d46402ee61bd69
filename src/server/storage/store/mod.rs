//! What the daemon holds and how it is kept: the rig (with its revision, and the show's content
//! canvas in it), each channel's own content canvas, if it has one, and tile screen (each with
//! its own revision), and calibration proposals.
//!
//! They live in memory as they are served and in SQLite ([`super::db`]) as they are kept: each
//! write is one transaction that makes the new document current and appends it to the history,
//! durable before the write is acknowledged. Resources are named `rig`,
//! `channels/<id>/content` and `channels/<id>/tiles`. Under the data directory: `omniwarp.db`
//! (with SQLite's `-wal` and `-shm`), `meshes/<name>.obj` (uploaded mesh screens) and `warps/`
//! (computed warp maps, a cache keyed by a hash of their inputs).
//!
//! What is read back is accepted as if a client had sent it: the same validation and limits run
//! at start-up; a document that fails them falls back to the newest earlier revision that
//! passes (kept as a new revision, the reason logged); when none does, or the database itself is
//! damaged, the daemon refuses to start unless told to `reset` — a damaged data directory is
//! never silently replaced, not even by the demo rig. A data directory of the file store
//! (0.1.0: `rig.json`, `channels/<id>.json`, `proposals/<n>.json`, each with a `.prev`) is
//! migrated on first start ([`migrate`]); its files are moved to `migrated-0.1/`.

mod migrate;

use super::db::{self, Db, Meta};
use crate::image_io::{create_private_dir_durably, remove_leftovers};
use crate::rig::Canvas;
use crate::rig::{Rig, RigDoc};
use crate::tiles::TileScreen;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, RwLock};

/// One channel's state: the last committed, which readers take and never wait for, and a lock
/// writers take turns on (a write holds it from its revision check to its commit, which may be
/// seconds of resampling). Only a writer holding the lock replaces the state.
pub struct Channel {
    writer: Arc<tokio::sync::Mutex<()>>,
    seen: RwLock<Arc<ChannelData>>,
}

impl Channel {
    fn new(data: ChannelData) -> Channel {
        Channel {
            seen: RwLock::new(Arc::new(data)),
            writer: Arc::new(tokio::sync::Mutex::new(())),
        }
    }

    /// The state as last committed.
    pub fn read(&self) -> Arc<ChannelData> {
        self.seen.read().expect("no reader panics").clone()
    }

    /// The channel for writing, once the writers before have finished.
    pub async fn write(self: &Arc<Self>) -> ChannelWriter {
        let held = self.writer.clone().lock_owned().await;
        ChannelWriter {
            now: self.read(),
            _held: held,
            channel: self.clone(),
        }
    }
}

/// A writer's hold on a channel (see [`Channel::write`]); reads as the current state.
pub struct ChannelWriter {
    now: Arc<ChannelData>,
    _held: tokio::sync::OwnedMutexGuard<()>,
    channel: Arc<Channel>,
}

impl ChannelWriter {
    /// Makes `next` the channel's state, for the next writer and for readers; call once it is
    /// durable.
    pub fn set(&mut self, next: ChannelData) {
        self.now = Arc::new(next);
        *self.channel.seen.write().expect("no reader panics") = self.now.clone();
    }
}

impl std::ops::Deref for ChannelWriter {
    type Target = ChannelData;
    fn deref(&self) -> &ChannelData {
        &self.now
    }
}

/// A value and its revision, as stored.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Versioned<T> {
    pub revision: u64,
    pub value: T,
}

/// A channel's editable state. A tile screen of `None` means the warp follows the geometry
/// exactly; the first tile edit samples the geometry into a grid and from then on the screen
/// defines which content direction each pixel shows (where the light lands stays the
/// geometry's, so blending is unchanged).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChannelData {
    /// The channel's own content canvas, with its revision; `None`: it plays the rig's
    /// (`canvas` in the rig document). Data directories from before the rig had a canvas keep
    /// each channel's canvas as its own.
    pub content: Versioned<Option<Canvas>>,
    /// The edited tile screen (`None`: the geometry's exact warp), with its revision.
    pub tiles: Versioned<Option<TileScreen>>,
}

impl Default for ChannelData {
    fn default() -> Self {
        ChannelData {
            content: Versioned {
                revision: 1,
                value: None,
            },
            tiles: Versioned {
                revision: 1,
                value: None,
            },
        }
    }
}

/// A solved projector waiting to be applied to the rig.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Proposal {
    pub id: u64,
    pub channel: String,
    /// The rig revision the points were measured against.
    pub rig_revision: u64,
    pub proposed: crate::rig::ChannelDoc,
    pub rms: f64,
    pub considered: Vec<serde_json::Value>,
    pub sigma: Vec<(String, f64)>,
    pub warnings: Vec<String>,
    /// Reprojection error of every point in the order sent, pixels (absent from proposals kept
    /// before it was reported).
    #[serde(default)]
    pub residuals: Vec<f64>,
    /// The points whose residual exceeds 3 robust σ, by index.
    #[serde(default)]
    pub outliers: Vec<usize>,
}

/// The daemon's state on disk and in memory: the rig as an immutable snapshot with its
/// revision, each channel's documents, the calibration proposals and the meshes.
pub struct Store {
    /// The data directory; `None` keeps everything in memory.
    pub dir: Option<PathBuf>,
    /// Where meshes named by the rig are read from.
    pub meshes: MeshDirs,
    /// Where everything is kept (in memory without a data directory).
    pub db: Db,
    current: RwLock<(Arc<Rig>, u64)>,
    /// Serialises rig writers, so revision checks and durability happen in order.
    pub rig_writer: Arc<tokio::sync::Mutex<()>>,
    channels: Mutex<HashMap<String, Arc<Channel>>>,
    /// Calibration proposals waiting to be applied, by id.
    pub proposals: Mutex<HashMap<u64, Arc<Proposal>>>,
    /// The id the next proposal gets, taken only by a proposal that is saved (see
    /// [`Store::save_new_proposal`]), so ids run without gaps.
    next_proposal: Mutex<u64>,
}

/// How a store is opened.
#[derive(Debug, Clone)]
pub struct OpenOptions {
    /// The rig to start from when the data directory holds none (`--demo`).
    pub initial: Option<RigDoc>,
    /// A rig file to serve (`--rig`): imported into a data directory that holds none; one that
    /// holds another rig is refused unless `replace`, which makes the file its next revision.
    pub import: Option<RigDoc>,
    /// See `import`.
    pub replace: bool,
    /// Start from `initial` even when the data directory is damaged beyond recovery (the
    /// damaged database or files are kept beside as `<name>.damaged`).
    pub reset: bool,
    /// Warps of all channels together may take this many bytes.
    pub memory_budget: u64,
    /// A read-only directory of meshes a rig may name besides uploaded ones (`--assets`).
    pub assets: Option<PathBuf>,
    /// How much of each document's history is kept.
    pub retention: db::Retention,
}

impl Default for OpenOptions {
    fn default() -> Self {
        OpenOptions {
            initial: None,
            import: None,
            replace: false,
            reset: false,
            memory_budget: crate::limits::MEMORY_BUDGET,
            assets: None,
            retention: db::Retention::default(),
        }
    }
}

/// The resource name of a channel's content canvas.
pub fn content_resource(id: &str) -> String {
    format!("channels/{id}/content")
}

/// The resource name of a channel's tile screen.
pub fn tiles_resource(id: &str) -> String {
    format!("channels/{id}/tiles")
}

/// How far back start-up looks for a revision that passes validation.
const RECOVER_DEPTH: u64 = 16;

/// The history entry of a write the daemon makes itself.
pub(super) fn by_daemon(action: &'static str) -> Meta {
    Meta {
        who: "omniwarp".into(),
        action,
        request: None,
        undo_to: None,
        redo_to: None,
    }
}

/// A kept document as `T`; a mismatch is reported like a damaged file.
pub(super) fn from_json<T: DeserializeOwned>(v: serde_json::Value) -> crate::Result<T> {
    serde_json::from_value(v).map_err(|e| crate::Error::invalid("data", e.to_string()))
}

pub(super) fn json_of(v: &impl Serialize) -> serde_json::Value {
    serde_json::to_value(v).expect("state documents serialise")
}

/// What reading a file and its `.prev` gave.
pub enum Loaded<T> {
    /// Neither file exists.
    Missing,
    Found(T),
    /// Both exist but fail; the reasons, for the refusal to start.
    Damaged(Vec<String>),
}

/// A mesh screen's name as the daemon accepts it: a plain file name of a safe alphabet ending in
/// `.obj`, so no path outside the mesh directories can be named.
pub fn mesh_name(name: &str) -> crate::Result<&str> {
    let safe = |c: char| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.');
    if name.len() <= 64
        && name.chars().all(safe)
        && !name.starts_with('.')
        && name.ends_with(".obj")
    {
        Ok(name)
    } else {
        Err(crate::Error::invalid(
            "obj",
            "must name a mesh uploaded with PUT /v1/meshes/{name} or kept in --assets: 1–64 \
             letters, digits, '-', '_' or '.', ending in .obj, no directories",
        ))
    }
}

impl Store {
    /// Loads the rig and the proposals from `dir`, else starts from `initial`.
    pub fn open(dir: Option<PathBuf>, initial: Option<RigDoc>) -> crate::Result<Store> {
        Self::open_with(
            dir,
            OpenOptions {
                initial,
                ..OpenOptions::default()
            },
        )
    }

    /// Opens the store in `dir` (in memory without one), creating or migrating it as needed.
    pub fn open_with(dir: Option<PathBuf>, o: OpenOptions) -> crate::Result<Store> {
        let meshes = MeshDirs {
            data: dir.as_ref().map(|d| d.join("meshes")),
            assets: o.assets.clone(),
        };
        let db = match &dir {
            Some(d) => {
                create_private_dir_durably(d)?;
                for sub in ["", "warps", "meshes"] {
                    let n = remove_leftovers(&d.join(sub));
                    if n > 0 {
                        tracing::warn!(dir = %d.join(sub).display(), n,
                            "removed temporary files a killed process left");
                    }
                }
                let db = match Db::open(Some(&d.join(db::FILE))) {
                    Ok(db) => db,
                    Err(e) if o.reset => {
                        tracing::error!(error = %e, "damaged database set aside (--reset)");
                        for f in ["", "-wal", "-shm"] {
                            set_aside(Some(d), &format!("{}{f}", db::FILE));
                        }
                        Db::open(Some(&d.join(db::FILE)))?
                    }
                    Err(e) => return Err(damaged(db::FILE, &[e.to_string()])),
                };
                migrate::migrate_files(d, &db, &meshes, &o)?;
                db
            }
            None => Db::open(None)?,
        };
        db.set_retention(o.retention)?;
        let loaded = load_valid(&db, "rig", |v| {
            let doc: RigDoc = from_json(v)?;
            meshes.accept(doc, o.memory_budget)
        })?;
        let (rig, revision) = match loaded {
            Loaded::Found((rig, revision)) => match &o.import {
                Some(doc) if json_of(doc) != json_of(&rig.doc) => {
                    if !o.replace {
                        return Err(crate::Error::invalid(
                            "rig",
                            format!(
                                "the data directory already holds another rig (revision \
                                 {revision}); give --replace-rig to make this file its revision \
                                 {}, or start with another --data",
                                revision + 1
                            ),
                        ));
                    }
                    let rig = meshes.accept(doc.clone(), o.memory_budget)?;
                    let doc = json_of(&rig.doc);
                    db.write("rig", None, (revision + 1, &doc), &by_daemon("import"))?;
                    (rig, revision + 1)
                }
                _ => (rig, revision),
            },
            Loaded::Damaged(reasons) if !o.reset => return Err(damaged("the rig", &reasons)),
            loaded => {
                let doc = o.import.clone().or_else(|| o.initial.clone());
                let doc = doc.ok_or_else(|| {
                    crate::Error::invalid(
                        "data",
                        if matches!(loaded, Loaded::Missing) {
                            "no rig in the data directory; start with --rig rig.json or --demo"
                        } else {
                            "--reset needs a rig to start from: give --rig or --demo"
                        },
                    )
                })?;
                let rig = meshes.accept(doc, o.memory_budget)?;
                let revision = db.current("rig")?.map_or(1, |(r, _)| r + 1);
                let action = match (revision, o.import.is_some()) {
                    (_, true) => "import",
                    (1, false) => "create",
                    _ => "reset",
                };
                db.write(
                    "rig",
                    None,
                    (revision, &json_of(&rig.doc)),
                    &by_daemon(action),
                )?;
                (rig, revision)
            }
        };
        let mut channels = HashMap::new();
        for ch in &rig.channels {
            let data = load_channel(&db, &ch.id, o.reset)?;
            channels.insert(ch.id.clone(), Arc::new(Channel::new(data)));
        }
        let proposals = load_proposals(&db, &rig);
        let next = proposals.keys().max().map_or(1, |m| m + 1);
        Ok(Store {
            dir,
            meshes,
            db,
            current: RwLock::new((Arc::new(rig), revision)),
            rig_writer: Arc::new(tokio::sync::Mutex::new(())),
            channels: Mutex::new(channels),
            proposals: Mutex::new(proposals),
            next_proposal: Mutex::new(next),
        })
    }

    /// Where mesh `name` is read from (see `MeshDirs::path`).
    pub fn mesh_path(&self, name: &str) -> crate::Result<PathBuf> {
        self.meshes.path(name)
    }

    /// A rig document from a client: parsed, its mesh read from the mesh directories only,
    /// validated, and within `budget`.
    pub fn accept_rig(&self, text: &str, budget: u64) -> crate::Result<Rig> {
        self.meshes.accept(RigDoc::parse(text)?, budget)
    }

    /// The current rig and its revision.
    pub fn snapshot(&self) -> (Arc<Rig>, u64) {
        let g = self
            .current
            .read()
            .expect("no writer panics while holding the lock");
        (g.0.clone(), g.1)
    }

    /// Durably writes the rig as `revision` with its history row (blocking).
    pub fn save_rig(&self, doc: &RigDoc, revision: u64, meta: &Meta) -> crate::Result<()> {
        self.db.write("rig", None, (revision, &json_of(doc)), meta)
    }

    /// Makes `rig` current; call after [`Store::save_rig`] succeeded.
    pub fn install(&self, rig: Rig, revision: u64) {
        *self
            .current
            .write()
            .expect("no writer panics while holding the lock") = (Arc::new(rig), revision);
    }

    /// The editable state of channel `id` of the current rig (a channel new to the rig starts
    /// from the defaults, or from what a former rig's channel of that id left).
    pub fn channel(&self, id: &str) -> Option<Arc<Channel>> {
        let (rig, _) = self.snapshot();
        rig.channel(id).ok()?;
        let mut map = self.channels.lock().expect("channel map lock");
        let entry = map.entry(id.to_string()).or_insert_with(|| {
            Arc::new(Channel::new(
                load_channel(&self.db, id, true).unwrap_or_default(),
            ))
        });
        Some(entry.clone())
    }

    /// Durably writes one of a channel's documents (`resource`, from `content_resource` or
    /// `tiles_resource`) with its history row (blocking); `before` is the revision it
    /// replaces, recorded first when the channel still had its defaults.
    pub fn save_doc(
        &self,
        resource: &str,
        before: (u64, &serde_json::Value),
        after: (u64, &serde_json::Value),
        meta: &Meta,
    ) -> crate::Result<()> {
        self.db.write(resource, Some(before), after, meta)
    }

    /// Keeps proposal `p` durably.
    pub fn save_proposal(&self, p: &Proposal) -> crate::Result<()> {
        self.db.put_proposal(p.id, &json_of(p))
    }

    /// Gives `p` the next proposal id and saves it; the id is used up only if the save
    /// succeeds.
    pub fn save_new_proposal(&self, mut p: Proposal) -> crate::Result<Proposal> {
        let mut next = self.next_proposal.lock().expect("proposal id lock");
        p.id = *next;
        self.save_proposal(&p)?;
        *next += 1;
        Ok(p)
    }

    /// Keeps `p` and drops the oldest proposals beyond [`crate::limits::PROPOSALS`] (from the
    /// database too); returns the ids dropped.
    pub fn keep_proposal(&self, p: Proposal) -> Vec<u64> {
        let mut map = self.proposals.lock().expect("proposal lock");
        map.insert(p.id, Arc::new(p));
        let mut ids: Vec<u64> = map.keys().copied().collect();
        ids.sort_unstable();
        let excess = ids.len().saturating_sub(crate::limits::PROPOSALS);
        let dropped: Vec<u64> = ids[..excess].to_vec();
        for id in &dropped {
            map.remove(id);
            if let Err(e) = self.db.delete_proposal(*id) {
                tracing::error!(id, error = %e, "could not drop a proposal");
            }
        }
        dropped
    }
}

/// The newest revision of `resource` that `accept` takes, looking back [`RECOVER_DEPTH`]
/// revisions; an older one found is written as a new revision so the history stays a line.
fn load_valid<T>(
    db: &Db,
    resource: &str,
    accept: impl Fn(serde_json::Value) -> crate::Result<T>,
) -> crate::Result<Loaded<(T, u64)>> {
    let Some((current, latest)) = db.current(resource)? else {
        return Ok(Loaded::Missing);
    };
    let mut reasons = Vec::new();
    for back in 0..=RECOVER_DEPTH.min(current.saturating_sub(1)) {
        let revision = current - back;
        let doc = if back == 0 {
            Some(latest.clone())
        } else {
            db.at(resource, revision)?
        };
        let Some(doc) = doc else { break };
        match accept(doc.clone()) {
            Ok(v) if back == 0 => return Ok(Loaded::Found((v, current))),
            Ok(v) => {
                tracing::error!(resource, revision, "recovered an earlier revision");
                db.write(resource, None, (current + 1, &doc), &by_daemon("recover"))?;
                return Ok(Loaded::Found((v, current + 1)));
            }
            Err(e) => {
                tracing::error!(resource, revision, error = %e,
                    "refused on loading; trying the revision before");
                reasons.push(format!("{resource} revision {revision}: {e}"));
            }
        }
    }
    Ok(Loaded::Damaged(reasons))
}

/// A channel's state from the database, validated as a PUT of its content and tiles would be;
/// the defaults where nothing is kept (or, with `reset`, where nothing kept is valid).
fn load_channel(db: &Db, id: &str, reset: bool) -> crate::Result<ChannelData> {
    let mut data = ChannelData::default();
    let content = load_valid(db, &content_resource(id), |v| {
        let c: Option<Canvas> = from_json(v)?;
        if let Some(c) = &c {
            c.view()?;
        }
        Ok(c)
    })?;
    match content {
        Loaded::Found((value, revision)) => data.content = Versioned { revision, value },
        Loaded::Damaged(reasons) if !reset => {
            return Err(damaged(&content_resource(id), &reasons));
        }
        Loaded::Damaged(_) => {
            data.content.revision = restart(db, &content_resource(id), &data.content.value)?;
        }
        Loaded::Missing => {}
    }
    let tiles = load_valid(db, &tiles_resource(id), |v| {
        let t: Option<TileScreen> = from_json(v)?;
        if let Some(t) = &t {
            t.validate()?;
        }
        Ok(t)
    })?;
    match tiles {
        Loaded::Found((value, revision)) => data.tiles = Versioned { revision, value },
        Loaded::Damaged(reasons) if !reset => {
            return Err(damaged(&tiles_resource(id), &reasons));
        }
        Loaded::Damaged(_) => {
            data.tiles.revision = restart(db, &tiles_resource(id), &data.tiles.value)?;
        }
        Loaded::Missing => {}
    }
    Ok(data)
}

/// Writes `value` (a default) as the next revision of a resource none of whose kept revisions
/// is valid (`--reset`); the damaged ones stay in the history.
fn restart(db: &Db, resource: &str, value: &impl Serialize) -> crate::Result<u64> {
    let next = db.current(resource)?.map_or(1, |(r, _)| r + 1);
    tracing::warn!(
        resource,
        revision = next,
        "started again from the defaults (--reset)"
    );
    db.write(resource, None, (next, &json_of(value)), &by_daemon("reset"))?;
    Ok(next)
}

/// Keeps a damaged file and its `.prev` as `<name>.damaged` and `<name>.prev.damaged`, for
/// whoever wants to look at them after a `--reset`.
pub(super) fn set_aside(dir: Option<&Path>, name: &str) {
    let Some(d) = dir else { return };
    for f in [name.to_string(), format!("{name}.prev")] {
        let from = d.join(&f);
        if from.exists() {
            let to = d.join(format!("{f}.damaged"));
            match std::fs::rename(&from, &to) {
                Ok(()) => tracing::warn!(file = %to.display(), "damaged file set aside (--reset)"),
                Err(e) => {
                    tracing::error!(file = %from.display(), error = %e, "could not set aside")
                }
            }
        }
    }
}

pub(super) fn damaged(name: &str, reasons: &[String]) -> crate::Error {
    crate::Error::invalid(
        "data",
        format!(
            "{name} and its .prev are both damaged ({}); restore them, or start with --reset to \
             begin again from --demo or an empty state",
            reasons.join("; ")
        ),
    )
}

/// The proposals kept in the database, each one checked by putting its channel into `rig`
/// (refused ones are logged and left out), the newest [`crate::limits::PROPOSALS`] only.
fn load_proposals(db: &Db, rig: &Rig) -> HashMap<u64, Arc<Proposal>> {
    let mut found = HashMap::new();
    let kept = db.proposals().unwrap_or_else(|e| {
        tracing::error!(error = %e, "proposals unreadable");
        Vec::new()
    });
    for (id, doc) in kept {
        let checked = from_json::<Proposal>(doc).and_then(|p| {
            let mut doc = rig.doc.clone();
            if let Some(slot) = doc.channels.iter_mut().find(|c| c.id == p.channel) {
                *slot = p.proposed.clone();
                Rig::from_doc(doc)?;
            }
            Ok(p)
        });
        match checked {
            Ok(p) => {
                found.insert(p.id, Arc::new(p));
            }
            Err(e) => tracing::error!(id, error = %e, "proposal refused on loading"),
        }
    }
    let mut ids: Vec<u64> = found.keys().copied().collect();
    ids.sort_unstable();
    for id in &ids[..ids.len().saturating_sub(crate::limits::PROPOSALS)] {
        found.remove(id);
    }
    found
}

/// Where mesh screens are read from: the data directory's `meshes/` (uploads), then the
/// `--assets` directory. No other path can be named.
#[derive(Debug, Clone)]
pub struct MeshDirs {
    pub data: Option<PathBuf>,
    pub assets: Option<PathBuf>,
}

impl MeshDirs {
    /// The file of mesh `name`; the answer for a name that is not allowed does not depend on
    /// what exists on disk.
    pub fn path(&self, name: &str) -> crate::Result<PathBuf> {
        let name = mesh_name(name)?;
        [&self.data, &self.assets]
            .into_iter()
            .flatten()
            .map(|d| d.join(name))
            .find(|p| p.is_file())
            .ok_or_else(|| {
                crate::Error::invalid(
                    "obj",
                    format!("no mesh `{name}`: upload it with PUT /v1/meshes/{name}"),
                )
            })
    }

    /// A rig document with its mesh loaded from these directories, validated and within
    /// `budget`.
    pub fn accept(&self, mut doc: RigDoc, budget: u64) -> crate::Result<Rig> {
        let left = budget.saturating_sub(doc.warp_bytes());
        doc.screen.load_with("/screen", |n| self.path(n), left)?;
        let rig = Rig::from_doc(doc)?;
        rig.check_budget(budget)?;
        Ok(rig)
    }
}
