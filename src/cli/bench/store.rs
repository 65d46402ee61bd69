//! `omniwarp bench store`: what keeping an edit costs. The same tile edits (one feature of a
//! 33×19 screen, ~60 KB of JSON) are made durable by the SQLite store with its history and by
//! the file store it replaced (0.1.0: the previous file copied to `.prev`, the new one written
//! atomically, both fsynced), with 8 and 32 writers in one run; then the cost of reading back
//! (reverting to) the revision furthest from a snapshot, and the history's size after many edits.

use anyhow::Result;
use clap::Args;
use omniwarp::image_io::atomic_write;
use omniwarp::projection::Params;
use omniwarp::server::storage::db::{Db, Meta, SNAPSHOT_EVERY};
use omniwarp::tiles::build::{Source, from_source};
use omniwarp::tiles::{Layout, TileScreen};
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

#[derive(Args)]
pub struct StoreBenchArgs {
    /// Edits each writer makes.
    #[arg(long, default_value_t = 50)]
    edits: usize,
    /// Edits of one screen for the history's size (kept in memory: the size does not depend on
    /// the disk).
    #[arg(long, default_value_t = 100_000)]
    history: usize,
}

fn screen() -> Result<TileScreen> {
    let p = Params {
        hfov: Some(90.0),
        vfov: Some(54.0),
        ..Params::default()
    };
    Ok(from_source(
        &Source::new("cylindrical", p, 9.0 / 16.0),
        33,
        19,
    )?)
}

/// `screen` with feature `n mod 627` nudged, as a tile PATCH would leave it.
fn edited(screen: &TileScreen, n: usize) -> TileScreen {
    let mut t = screen.clone();
    t.revision = n as u64 + 2;
    if let Layout::Grid { features, .. } = &mut t.layout {
        let i = n % features.len();
        features[i].theta += 0.001 * ((n % 7) as f64 - 3.0);
    }
    t
}

/// Tile screens always serialise.
fn value(t: &TileScreen) -> serde_json::Value {
    serde_json::to_value(t).expect("tile screens serialise")
}

fn meta() -> Meta {
    Meta {
        who: "bench".into(),
        action: "patch",
        request: None,
        undo_to: None,
        redo_to: None,
    }
}

/// The 0.1.0 file store's write: the old file kept as `.prev` when it parses, the new one
/// written atomically.
fn file_write(dir: &Path, name: &str, bytes: &[u8]) -> omniwarp::Result<()> {
    let path = dir.join(name);
    if let Ok(old) = std::fs::read(&path)
        && serde_json::from_slice::<serde_json::Value>(&old).is_ok()
    {
        let prev = dir.join(format!("{name}.prev"));
        atomic_write(&prev, |f| {
            std::io::Write::write_all(f, &old).map_err(|e| omniwarp::Error::file(&prev, e))
        })?;
    }
    atomic_write(&path, |f| {
        std::io::Write::write_all(f, bytes).map_err(|e| omniwarp::Error::file(&path, e))
    })
}

fn percentile(v: &mut [f64], p: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * p).round() as usize]
}

/// One store's write: writer, revision, the screen before and after.
type Writer = dyn Fn(usize, u64, &TileScreen, &TileScreen) -> omniwarp::Result<()> + Send + Sync;

/// `writers` threads each making `edits` edits of its own channel's screen through `write`;
/// edits per second and every latency, milliseconds.
fn run_writers(
    writers: usize,
    edits: usize,
    base: &TileScreen,
    write: Arc<Writer>,
) -> Result<(f64, Vec<f64>)> {
    let t = Instant::now();
    let threads: Vec<_> = (0..writers)
        .map(|w| {
            let (write, base) = (write.clone(), base.clone());
            std::thread::spawn(move || -> omniwarp::Result<Vec<f64>> {
                let mut before = base.clone();
                let mut out = Vec::with_capacity(edits);
                for n in 0..edits {
                    let after = edited(&before, n);
                    let started = Instant::now();
                    write(w, n as u64 + 2, &before, &after)?;
                    out.push(started.elapsed().as_secs_f64() * 1e3);
                    before = after;
                }
                Ok(out)
            })
        })
        .collect();
    let mut all = Vec::new();
    for th in threads {
        all.extend(th.join().expect("writer thread")?);
    }
    Ok(((writers * edits) as f64 / t.elapsed().as_secs_f64(), all))
}

pub fn run(a: StoreBenchArgs) -> Result<()> {
    let base = screen()?;
    let doc_bytes = serde_json::to_vec(&base)?.len();
    outln!(
        "one tile edit of a 33×19 screen ({doc_bytes} bytes of JSON), {} edits per writer, on {}",
        a.edits,
        std::env::temp_dir().display()
    );
    outln!("store      writers   edits/s   p50 ms   p99 ms");
    for writers in [8, 32] {
        let dir = tempfile::tempdir()?;
        let db = Arc::new(Db::open(Some(&dir.path().join("omniwarp.db")))?);
        let sqlite = move |w: usize, rev: u64, before: &TileScreen, after: &TileScreen| {
            let (b, af) = (value(before), value(after));
            db.write(
                &format!("channels/c{w}/tiles"),
                Some((rev - 1, &b)),
                (rev, &af),
                &meta(),
            )
        };
        let (rate, mut lat) = run_writers(writers, a.edits, &base, Arc::new(sqlite))?;
        outln!(
            "sqlite     {writers:>7} {rate:>9.0} {:>8.2} {:>8.2}",
            percentile(&mut lat, 0.5),
            percentile(&mut lat, 0.99)
        );
        let files = tempfile::tempdir()?;
        let root = files.path().to_path_buf();
        let file = move |w: usize, rev: u64, _: &TileScreen, after: &TileScreen| {
            let mut doc = value(after);
            doc["revision"] = rev.into();
            file_write(&root, &format!("c{w}.json"), doc.to_string().as_bytes())
        };
        let (rate, mut lat) = run_writers(writers, a.edits, &base, Arc::new(file))?;
        outln!(
            "files 0.1  {writers:>7} {rate:>9.0} {:>8.2} {:>8.2}",
            percentile(&mut lat, 0.5),
            percentile(&mut lat, 0.99)
        );
    }

    // Reading back the revision furthest from a snapshot (what a revert or ?revision=N does).
    let dir = tempfile::tempdir()?;
    let db = Db::open(Some(&dir.path().join("omniwarp.db")))?;
    let mut before = base.clone();
    for n in 0..2 * SNAPSHOT_EVERY as usize {
        let after = edited(&before, n);
        let (b, af) = (value(&before), value(&after));
        db.write("t", Some((n as u64 + 1, &b)), (n as u64 + 2, &af), &meta())?;
        before = after;
    }
    let worst = SNAPSHOT_EVERY + SNAPSHOT_EVERY - 1;
    let t = Instant::now();
    let runs = 20;
    for _ in 0..runs {
        db.at("t", worst)?.expect("kept");
    }
    outln!(
        "revision {worst} rebuilt from the snapshot at {SNAPSHOT_EVERY} and {} patches: {:.2} ms",
        SNAPSHOT_EVERY - 1,
        t.elapsed().as_secs_f64() * 1e3 / runs as f64
    );

    // The history's size after many edits of one screen.
    let db = Db::open(None)?;
    let mut before = base.clone();
    let t = Instant::now();
    for n in 0..a.history {
        let after = edited(&before, n);
        let (b, af) = (value(&before), value(&after));
        db.write("t", Some((n as u64 + 1, &b)), (n as u64 + 2, &af), &meta())?;
        before = after;
    }
    let (rows, bytes) = db.size()?;
    outln!(
        "history after {} edits: {rows} rows, {:.1} MB of patches and snapshots ({:.0} bytes an edit; \
         a copy of the screen per edit would be {:.1} MB), written in {:.1} s",
        a.history,
        bytes as f64 / 1e6,
        bytes as f64 / a.history as f64,
        (a.history * doc_bytes) as f64 / 1e6,
        t.elapsed().as_secs_f64()
    );
    Ok(())
}
