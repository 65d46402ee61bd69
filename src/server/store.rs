//! What the daemon holds and how it is kept: the rig (with its revision), each channel's content
//! canvas and tile screen (each with its own revision), and calibration proposals.
//!
//! Every write goes through [`save`]: the previous good file is kept as `<name>.prev` and the new
//! one is written atomically (temp file, fsync, rename, fsync dir), so an acknowledged edit
//! survives a crash and a damaged file falls back to the last good revision. Layout under the
//! data directory: `rig.json`, `channels/<id>.json`, `proposals/<n>.json`.

use crate::image_io::atomic_write;
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
    current: RwLock<(Arc<Rig>, u64)>,
    /// Serialises rig writers, so revision checks and durability happen in order.
    pub rig_writer: tokio::sync::Mutex<()>,
    channels: Mutex<HashMap<String, Arc<tokio::sync::Mutex<ChannelData>>>>,
    pub proposals: Mutex<HashMap<u64, Arc<Proposal>>>,
    pub next_proposal: AtomicU64,
}

/// Writes `bytes` as `dir/name`, keeping the previous file as `name.prev` when it still parses
/// as `T` (a damaged file must not overwrite the last good one).
pub fn save<T: DeserializeOwned>(dir: &Path, name: &str, bytes: &[u8]) -> crate::Result<()> {
    let path = dir.join(name);
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).map_err(|e| crate::Error::file(parent, e))?;
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

/// Reads `dir/name`, or `name.prev` when the first is missing or damaged (said in the log).
pub fn load<T>(dir: &Path, name: &str, parse: impl Fn(&Path) -> crate::Result<T>) -> Option<T> {
    for file in [name.to_string(), format!("{name}.prev")] {
        let path = dir.join(&file);
        if !path.exists() {
            continue;
        }
        match parse(&path) {
            Ok(v) => return Some(v),
            Err(e) => tracing::error!(file = %path.display(), error = %e,
                "unreadable file; trying the previous good one"),
        }
    }
    None
}

fn parse_json<T: DeserializeOwned>(path: &Path) -> crate::Result<T> {
    let text = std::fs::read(path).map_err(|e| crate::Error::file(path, e))?;
    serde_json::from_slice(&text).map_err(|e| crate::Error::file(path, e))
}

fn load_rig(path: &Path) -> crate::Result<(Rig, u64)> {
    let saved: SavedRig = parse_json(path)?;
    let mut doc = saved.rig;
    doc.screen
        .load(path.parent().unwrap_or(Path::new(".")), "/rig/screen")?;
    Ok((Rig::from_doc(doc)?, saved.revision))
}

impl Store {
    /// Loads the rig and the proposals from `dir`, else starts from `initial`.
    pub fn open(dir: Option<PathBuf>, initial: Option<RigDoc>) -> crate::Result<Store> {
        let mut loaded = None;
        let mut proposals = HashMap::new();
        if let Some(d) = &dir {
            std::fs::create_dir_all(d).map_err(|e| crate::Error::file(d, e))?;
            loaded = load(d, "rig.json", load_rig);
            if let Ok(entries) = std::fs::read_dir(d.join("proposals")) {
                for e in entries.flatten() {
                    let path = e.path();
                    if path.extension().is_some_and(|x| x == "json") {
                        match parse_json::<Proposal>(&path) {
                            Ok(p) => {
                                proposals.insert(p.id, Arc::new(p));
                            }
                            Err(e) => tracing::error!(error = %e, "unreadable proposal"),
                        }
                    }
                }
            }
        }
        let (rig, revision) = match (loaded, initial) {
            (Some(found), _) => found,
            (None, Some(doc)) => (Rig::from_doc(doc)?, 1),
            (None, None) => {
                return Err(crate::Error::invalid(
                    "data",
                    "no rig in the data directory; start with --demo or put a rig.json there",
                ));
            }
        };
        let next = proposals.keys().max().map_or(1, |m| m + 1);
        let store = Store {
            dir,
            current: RwLock::new((Arc::new(rig), revision)),
            rig_writer: tokio::sync::Mutex::new(()),
            channels: Mutex::new(HashMap::new()),
            proposals: Mutex::new(proposals),
            next_proposal: AtomicU64::new(next),
        };
        let (rig, revision) = store.snapshot();
        store.save_rig(&rig.doc, revision)?;
        Ok(store)
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

    /// The editable state of channel `id` of the current rig (loaded on first use).
    pub fn channel(&self, id: &str) -> Option<Arc<tokio::sync::Mutex<ChannelData>>> {
        let (rig, _) = self.snapshot();
        rig.channel(id).ok()?;
        let mut map = self.channels.lock().expect("channel map lock");
        let entry = map.entry(id.to_string()).or_insert_with(|| {
            let data = self
                .dir
                .as_ref()
                .and_then(|d| load(d, &channel_file(id), parse_json::<ChannelData>))
                .unwrap_or_default();
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
}

/// Channel ids are restricted to a file-safe alphabet by rig validation.
fn channel_file(id: &str) -> String {
    format!("channels/{id}.json")
}
