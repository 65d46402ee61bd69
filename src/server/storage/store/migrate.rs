//! The file store of 0.1.0 (`rig.json`, `channels/<id>.json`, `proposals/<n>.json`, each with
//! a `.prev`), moved into the database on the first start of a later version. Each file is read
//! with its `.prev` fallback and validated as a request would be.

use super::super::db::Db;
use super::{
    ChannelData, Loaded, MeshDirs, OpenOptions, Proposal, by_daemon, content_resource, damaged,
    json_of, set_aside, tiles_resource,
};
use crate::image_io::create_private_dir_durably;
use crate::rig::{Rig, RigDoc};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The persisted rig.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct SavedRig {
    revision: u64,
    rig: RigDoc,
}

/// Reads `dir/name`, or `name.prev` when the first is missing or fails `parse` (which
/// validates as a request would); each failure is logged with its reason.
fn load<T>(dir: &Path, name: &str, parse: impl Fn(&Path) -> crate::Result<T>) -> Loaded<T> {
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

/// Moves a data directory of the file store (0.1.0) into the database, once: its rig, channel
/// files and proposals (each read with its `.prev` fallback and validated as before) become
/// revisions of the same numbers, and the files move to `migrated-0.1/` afterwards (a start
/// killed in between finds the database done and moves them then).
pub(super) fn migrate_files(
    dir: &Path,
    db: &Db,
    meshes: &MeshDirs,
    o: &OpenOptions,
) -> crate::Result<()> {
    let done = db.meta("migrated-0.1")?.is_some();
    if !done && dir.join("rig.json").exists() && db.current("rig")?.is_none() {
        let loaded = load(dir, "rig.json", |p| load_rig(p, meshes, o.memory_budget));
        let (rig, revision) = match loaded {
            Loaded::Found(found) => found,
            Loaded::Damaged(reasons) if !o.reset => return Err(damaged("rig.json", &reasons)),
            _ => {
                set_aside(Some(dir), "rig.json");
                return Ok(());
            }
        };
        let migrate = by_daemon("migrate");
        db.write("rig", None, (revision, &json_of(&rig.doc)), &migrate)?;
        for ch in &rig.channels {
            let data = match load(dir, &channel_file(&ch.id), parse_channel) {
                Loaded::Found(data) => data,
                Loaded::Missing => continue,
                Loaded::Damaged(reasons) if !o.reset => {
                    return Err(damaged(&channel_file(&ch.id), &reasons));
                }
                Loaded::Damaged(_) => {
                    set_aside(Some(dir), &channel_file(&ch.id));
                    continue;
                }
            };
            let (c, t) = (&data.content, &data.tiles);
            let content = (c.revision, &json_of(&c.value));
            db.write(&content_resource(&ch.id), None, content, &migrate)?;
            let tiles = (t.revision, &json_of(&t.value));
            db.write(&tiles_resource(&ch.id), None, tiles, &migrate)?;
        }
        for (id, p) in file_proposals(dir) {
            db.put_proposal(id, &p)?;
        }
        db.set_meta("migrated-0.1", "done")?;
        tracing::info!(dir = %dir.display(), "file store migrated into the database");
    }
    if db.meta("migrated-0.1")?.is_some() {
        let to = dir.join("migrated-0.1");
        for name in ["rig.json", "rig.json.prev", "channels", "proposals"] {
            let from = dir.join(name);
            if from.exists() {
                create_private_dir_durably(&to)?;
                std::fs::rename(&from, to.join(name)).map_err(|e| crate::Error::file(&from, e))?;
            }
        }
    }
    Ok(())
}

/// The proposals of a file store's `proposals/` directory, as JSON.
fn file_proposals(dir: &Path) -> Vec<(u64, serde_json::Value)> {
    let Ok(entries) = std::fs::read_dir(dir.join("proposals")) else {
        return Vec::new();
    };
    entries
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "json"))
        .filter_map(|p| match parse_json::<Proposal>(&p) {
            Ok(v) => Some((v.id, json_of(&v))),
            Err(e) => {
                tracing::error!(file = %p.display(), error = %e,
                    "proposal left out of the migration");
                None
            }
        })
        .collect()
}

/// A channel's saved state, validated as a PUT of its content and tiles would be.
fn parse_channel(path: &Path) -> crate::Result<ChannelData> {
    let data: ChannelData = parse_json(path)?;
    if let Some(c) = &data.content.value {
        c.view()
            .map_err(|e| crate::Error::file(path, format!("content: {e}")))?;
    }
    if let Some(t) = &data.tiles.value {
        t.validate()
            .map_err(|e| crate::Error::file(path, format!("tiles: {e}")))?;
    }
    Ok(data)
}

fn load_rig(path: &Path, meshes: &MeshDirs, budget: u64) -> crate::Result<(Rig, u64)> {
    let saved: SavedRig = parse_json(path)?;
    Ok((meshes.accept(saved.rig, budget)?, saved.revision))
}

/// Channel ids are restricted to a file-safe alphabet by rig validation.
fn channel_file(id: &str) -> String {
    format!("channels/{id}.json")
}
