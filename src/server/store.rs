//! What the daemon holds and how it is kept: the rig (with its revision), each channel's content
//! canvas and tile screen (each with its own revision), and calibration proposals.
//!
//! Every write goes through [`save`]: the previous good file is kept as `<name>.prev` and the new
//! one is written atomically (temp file, fsync, rename, fsync dir), so an acknowledged edit
//! survives a crash and a damaged file falls back to the last good revision. Layout under the
//! data directory: `rig.json`, `channels/<id>.json`, `proposals/<n>.json`, `meshes/<name>.obj`
//! (uploaded mesh screens) and `warps/` (computed warp maps, a cache).
//!
//! What is read from disk is accepted as if a client had sent it: the same validation and
//! limits run at start-up, a file that fails them falls back to its `.prev` (the reason
//! logged), and when both fail the daemon refuses to start unless told to `reset` — a damaged
//! data directory is never silently replaced, not even by the demo rig.

use crate::image_io::{atomic_write, create_dir_durably, remove_leftovers};
use crate::rig::{Rig, RigDoc};
use crate::tiles::TileScreen;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicU64;
use std::sync::{Arc, Mutex, RwLock};

/// A value and its revision, as stored.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Versioned<T> {
    pub revision: u64,
    pub value: T,
}

/// The persisted rig.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct SavedRig {
    revision: u64,
    rig: RigDoc,
}

crate::projection::doc::view_document! {
    /// The content image a channel's 2d exports point into: a projection and view (as for
    /// `render`) and the image's size in pixels.
    pub struct Canvas {
        /// Width and height, pixels.
        pub size: [u32; 2],
    }
}

impl Default for Canvas {
    /// The whole sphere, equirectangular, 4096×2048.
    fn default() -> Self {
        Canvas {
            projection: "equirect".into(),
            params: crate::projection::Params {
                hfov: Some(360.0),
                vfov: Some(180.0),
                ..Default::default()
            },
            look_to: crate::projection::view::default_look_to(),
            look_up: crate::projection::view::default_look_up(),
            offaxis: [0.0; 3],
            zoom: 1.0,
            size: [4096, 2048],
        }
    }
}

impl Canvas {
    /// The canvas's view, checked; errors name the field.
    pub fn view(&self) -> crate::Result<crate::projection::View> {
        let [w, h] = self.size;
        if w == 0 || h == 0 || w > 65535 || h > 65535 {
            return Err(crate::Error::invalid(
                "/size",
                format!("must be 1–65535 pixels each way, got {w}×{h}"),
            ));
        }
        self.doc()
            .view(f64::from(h) / f64::from(w))
            .map_err(crate::projection::doc::pointer)
    }
}

/// A channel's editable state. A tile screen of `None` means the warp follows the geometry
/// exactly; the first tile edit samples the geometry into a grid and from then on the screen
/// defines which content direction each pixel shows (where the light lands stays the
/// geometry's, so blending is unchanged).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChannelData {
    pub content: Versioned<Canvas>,
    pub tiles: Versioned<Option<TileScreen>>,
}

impl Default for ChannelData {
    fn default() -> Self {
        ChannelData {
            content: Versioned {
                revision: 1,
                value: Canvas::default(),
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
}

pub struct Store {
    pub dir: Option<PathBuf>,
    pub meshes: MeshDirs,
    current: RwLock<(Arc<Rig>, u64)>,
    /// Serialises rig writers, so revision checks and durability happen in order.
    pub rig_writer: tokio::sync::Mutex<()>,
    channels: Mutex<HashMap<String, Arc<tokio::sync::Mutex<ChannelData>>>>,
    pub proposals: Mutex<HashMap<u64, Arc<Proposal>>>,
    pub next_proposal: AtomicU64,
}

/// How a store is opened.
#[derive(Debug, Clone)]
pub struct OpenOptions {
    /// The rig to start from when the data directory holds none.
    pub initial: Option<RigDoc>,
    /// Start from `initial` even when the data directory's files are damaged beyond their
    /// `.prev` (the damaged files are kept beside as `<name>.damaged`).
    pub reset: bool,
    /// Warps of all channels together may take this many bytes.
    pub memory_budget: u64,
    pub assets: Option<PathBuf>,
}

impl Default for OpenOptions {
    fn default() -> Self {
        OpenOptions {
            initial: None,
            reset: false,
            memory_budget: crate::limits::MEMORY_BUDGET,
            assets: None,
        }
    }
}

/// Writes `bytes` as `dir/name`, keeping the previous file as `name.prev` when it still parses
/// as `T` (a damaged file must not overwrite the last good one).
pub fn save<T: DeserializeOwned>(dir: &Path, name: &str, bytes: &[u8]) -> crate::Result<()> {
    let path = dir.join(name);
    if let Some(parent) = path.parent() {
        create_dir_durably(parent)?;
    }
    if let Ok(old) = std::fs::read(&path)
        && serde_json::from_slice::<T>(&old).is_ok()
    {
        let prev = dir.join(format!("{name}.prev"));
        atomic_write(&prev, |f| {
            std::io::Write::write_all(f, &old).map_err(|e| crate::Error::file(&prev, e))
        })?;
    }
    atomic_write(&path, |f| {
        std::io::Write::write_all(f, bytes).map_err(|e| crate::Error::file(&path, e))
    })
}

/// What reading a file and its `.prev` gave.
pub enum Loaded<T> {
    /// Neither file exists.
    Missing,
    Found(T),
    /// Both exist but fail; the reasons, for the refusal to start.
    Damaged(Vec<String>),
}

/// Reads `dir/name`, or `name.prev` when the first is missing or fails `parse` (which
/// validates as a request would); each failure is logged with its reason.
pub fn load<T>(dir: &Path, name: &str, parse: impl Fn(&Path) -> crate::Result<T>) -> Loaded<T> {
    let mut reasons = Vec::new();
    for file in [name.to_string(), format!("{name}.prev")] {
        let path = dir.join(&file);
        if !path.exists() {
            continue;
        }
        match parse(&path) {
            Ok(v) => return Loaded::Found(v),
            Err(e) => {
                tracing::error!(file = %path.display(), error = %e,
                    "refused on loading; trying the previous good one");
                reasons.push(format!("{}: {e}", path.display()));
            }
        }
    }
    if reasons.is_empty() {
        Loaded::Missing
    } else {
        Loaded::Damaged(reasons)
    }
}

/// Reads a JSON file of at most `MAX_FILE` bytes.
fn parse_json<T: DeserializeOwned>(path: &Path) -> crate::Result<T> {
    use std::io::Read;
    let file = std::fs::File::open(path).map_err(|e| crate::Error::file(path, e))?;
    let mut text = Vec::new();
    file.take(MAX_FILE + 1)
        .read_to_end(&mut text)
        .map_err(|e| crate::Error::file(path, e))?;
    if text.len() as u64 > MAX_FILE {
        return Err(crate::Error::file(path, format!("above {MAX_FILE} bytes")));
    }
    serde_json::from_slice(&text).map_err(|e| crate::Error::file(path, e))
}

/// Largest state file read back, bytes: a request body can be no larger than this either.
const MAX_FILE: u64 = 16 << 20;

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

    pub fn open_with(dir: Option<PathBuf>, o: OpenOptions) -> crate::Result<Store> {
        let meshes = MeshDirs {
            data: dir.as_ref().map(|d| d.join("meshes")),
            assets: o.assets.clone(),
        };
        let mut loaded = Loaded::Missing;
        if let Some(d) = &dir {
            std::fs::create_dir_all(d).map_err(|e| crate::Error::file(d, e))?;
            for sub in ["", "channels", "proposals", "warps", "meshes"] {
                let n = remove_leftovers(&d.join(sub));
                if n > 0 {
                    tracing::warn!(dir = %d.join(sub).display(), n,
                        "removed temporary files a killed process left");
                }
            }
            loaded = load(d, "rig.json", |p| load_rig(p, &meshes, o.memory_budget));
        }
        let (rig, revision) = match (loaded, &o.initial) {
            (Loaded::Found(found), _) => found,
            (Loaded::Damaged(reasons), _) if !o.reset => {
                return Err(damaged("rig.json", &reasons));
            }
            (Loaded::Damaged(_), _) => {
                set_aside(dir.as_deref(), "rig.json");
                match &o.initial {
                    Some(doc) => (meshes.accept(doc.clone(), o.memory_budget)?, 1),
                    None => {
                        return Err(crate::Error::invalid(
                            "data",
                            "--reset needs a rig to start from: give --demo",
                        ));
                    }
                }
            }
            (_, Some(doc)) => (meshes.accept(doc.clone(), o.memory_budget)?, 1),
            (_, None) => {
                return Err(crate::Error::invalid(
                    "data",
                    "no rig in the data directory; start with --demo or put a rig.json there",
                ));
            }
        };
        let mut channels = HashMap::new();
        let mut proposals = HashMap::new();
        if let Some(d) = &dir {
            // The rig's channels are validated now, so a damaged file stops the start.
            for ch in &rig.channels {
                let data = match load(d, &channel_file(&ch.id), parse_channel) {
                    Loaded::Found(data) => data,
                    Loaded::Missing => ChannelData::default(),
                    Loaded::Damaged(_) if o.reset => {
                        set_aside(Some(d), &channel_file(&ch.id));
                        ChannelData::default()
                    }
                    Loaded::Damaged(reasons) => {
                        return Err(damaged(&channel_file(&ch.id), &reasons));
                    }
                };
                channels.insert(ch.id.clone(), Arc::new(tokio::sync::Mutex::new(data)));
            }
            proposals = load_proposals(d, &rig);
        }
        let next = proposals.keys().max().map_or(1, |m| m + 1);
        let store = Store {
            dir,
            meshes,
            current: RwLock::new((Arc::new(rig), revision)),
            rig_writer: tokio::sync::Mutex::new(()),
            channels: Mutex::new(channels),
            proposals: Mutex::new(proposals),
            next_proposal: AtomicU64::new(next),
        };
        let (rig, revision) = store.snapshot();
        store.save_rig(&rig.doc, revision)?;
        Ok(store)
    }

    /// Where mesh `name` is read from (see [`MeshDirs::path`]).
    pub fn mesh_path(&self, name: &str) -> crate::Result<PathBuf> {
        self.meshes.path(name)
    }

    /// A rig document from a client: parsed, its mesh read from the mesh directories only,
    /// validated, and within `budget`.
    pub fn accept_rig(&self, text: &str, budget: u64) -> crate::Result<Rig> {
        self.meshes.accept(RigDoc::parse(text)?, budget)
    }

    pub fn snapshot(&self) -> (Arc<Rig>, u64) {
        let g = self
            .current
            .read()
            .expect("no writer panics while holding the lock");
        (g.0.clone(), g.1)
    }

    /// Durably writes the rig (blocking).
    pub fn save_rig(&self, doc: &RigDoc, revision: u64) -> crate::Result<()> {
        let Some(dir) = &self.dir else { return Ok(()) };
        let bytes = serde_json::to_vec_pretty(&SavedRig {
            revision,
            rig: doc.clone(),
        })
        .expect("rigs serialise");
        save::<SavedRig>(dir, "rig.json", &bytes)
    }

    /// Makes `rig` current; call after [`Store::save_rig`] succeeded.
    pub fn install(&self, rig: Rig, revision: u64) {
        *self
            .current
            .write()
            .expect("no writer panics while holding the lock") = (Arc::new(rig), revision);
    }

    /// The editable state of channel `id` of the current rig (a channel new to the rig starts
    /// from the defaults, or from a valid file a former rig left).
    pub fn channel(&self, id: &str) -> Option<Arc<tokio::sync::Mutex<ChannelData>>> {
        let (rig, _) = self.snapshot();
        rig.channel(id).ok()?;
        let mut map = self.channels.lock().expect("channel map lock");
        let entry = map.entry(id.to_string()).or_insert_with(|| {
            let data = match self
                .dir
                .as_ref()
                .map(|d| load(d, &channel_file(id), parse_channel))
            {
                Some(Loaded::Found(data)) => data,
                _ => ChannelData::default(),
            };
            Arc::new(tokio::sync::Mutex::new(data))
        });
        Some(entry.clone())
    }

    /// Durably writes a channel's state (blocking).
    pub fn save_channel(&self, id: &str, data: &ChannelData) -> crate::Result<()> {
        let Some(dir) = &self.dir else { return Ok(()) };
        let bytes = serde_json::to_vec(data).expect("channel state serialises");
        save::<ChannelData>(dir, &channel_file(id), &bytes)
    }

    pub fn save_proposal(&self, p: &Proposal) -> crate::Result<()> {
        let Some(dir) = &self.dir else { return Ok(()) };
        let bytes = serde_json::to_vec_pretty(p).expect("proposals serialise");
        save::<Proposal>(dir, &format!("proposals/{}.json", p.id), &bytes)
    }

    /// Keeps `p` and drops the oldest proposals beyond [`crate::limits::PROPOSALS`] (their
    /// files too); returns the ids dropped.
    pub fn keep_proposal(&self, p: Proposal) -> Vec<u64> {
        let mut map = self.proposals.lock().expect("proposal lock");
        map.insert(p.id, Arc::new(p));
        let mut ids: Vec<u64> = map.keys().copied().collect();
        ids.sort_unstable();
        let excess = ids.len().saturating_sub(crate::limits::PROPOSALS);
        let dropped: Vec<u64> = ids[..excess].to_vec();
        for id in &dropped {
            map.remove(id);
            if let Some(d) = &self.dir {
                for f in [format!("{id}.json"), format!("{id}.json.prev")] {
                    let _ = std::fs::remove_file(d.join("proposals").join(f));
                }
            }
        }
        dropped
    }
}

/// Keeps a damaged file and its `.prev` as `<name>.damaged` and `<name>.prev.damaged`, for
/// whoever wants to look at them after a `--reset`.
fn set_aside(dir: Option<&Path>, name: &str) {
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

fn damaged(name: &str, reasons: &[String]) -> crate::Error {
    crate::Error::invalid(
        "data",
        format!(
            "{name} and its .prev are both damaged ({}); restore them, or start with --reset to \
             begin again from --demo or an empty state",
            reasons.join("; ")
        ),
    )
}

/// A channel's saved state, validated as a PUT of its content and tiles would be.
fn parse_channel(path: &Path) -> crate::Result<ChannelData> {
    let data: ChannelData = parse_json(path)?;
    data.content
        .value
        .view()
        .map_err(|e| crate::Error::file(path, format!("content: {e}")))?;
    if let Some(t) = &data.tiles.value {
        t.validate()
            .map_err(|e| crate::Error::file(path, format!("tiles: {e}")))?;
    }
    Ok(data)
}

/// The proposals kept under `dir/proposals`, each one checked by putting its channel into `rig`
/// (refused ones are logged and left out), the newest [`crate::limits::PROPOSALS`] only.
fn load_proposals(dir: &Path, rig: &Rig) -> HashMap<u64, Arc<Proposal>> {
    let mut found = HashMap::new();
    let Ok(entries) = std::fs::read_dir(dir.join("proposals")) else {
        return found;
    };
    for e in entries.flatten() {
        let path = e.path();
        if path.extension().is_none_or(|x| x != "json") {
            continue;
        }
        let checked = parse_json::<Proposal>(&path).and_then(|p| {
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
            Err(e) => {
                tracing::error!(file = %path.display(), error = %e, "proposal refused on loading")
            }
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
        doc.screen.load_with("/screen", |n| self.path(n))?;
        let rig = Rig::from_doc(doc)?;
        rig.check_budget(budget)?;
        Ok(rig)
    }
}

fn load_rig(path: &Path, meshes: &MeshDirs, budget: u64) -> crate::Result<(Rig, u64)> {
    let saved: SavedRig = parse_json(path)?;
    Ok((meshes.accept(saved.rig, budget)?, saved.revision))
}

/// Channel ids are restricted to a file-safe alphabet by rig validation.
fn channel_file(id: &str) -> String {
    format!("channels/{id}.json")
}
