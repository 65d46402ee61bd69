//! Durability that a killed process cannot show: the page cache outlives the process, so a
//! missing fsync passes every kill -9 test. The daemon's state lives in SQLite (WAL,
//! `synchronous = FULL`: its own journal makes that guarantee); the files it still writes
//! itself — uploaded meshes, the warp cache, every file the CLI writes — go through
//! `image_io::atomic_write`. Here those writes run under a journal of their steps
//! (`image_io::journal`), and a model of what a file system keeps after power loss (a file's
//! contents only once synced, a rename only once its directory is synced) replays them: at
//! every point of a write a crash leaves each file old or new, never torn, and once a write
//! returns the new contents are durable. Each step is then failed in turn, as a full disk would:
//! the write reports the error and no temporary file stays.

use omniwarp::image_io::{Step, atomic_write, create_dir_durably, journal};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// What each file may hold after a power loss: one of several versions (`None`: torn, a name
/// whose contents were never synced).
type Possible = HashMap<PathBuf, Vec<Option<Vec<u8>>>>;

/// The files a crash after `steps` could leave, starting from `before` (all durable).
fn after_power_loss(before: &HashMap<PathBuf, Vec<u8>>, steps: &[Step]) -> Possible {
    let mut durable: HashMap<PathBuf, Option<Vec<u8>>> = before
        .iter()
        .map(|(p, b)| (p.clone(), Some(b.clone())))
        .collect();
    let mut temps: HashMap<PathBuf, (Vec<u8>, bool)> = HashMap::new();
    let mut pending: Vec<(PathBuf, Option<Vec<u8>>)> = Vec::new();
    for s in steps {
        match s {
            Step::Write { temp, bytes } => {
                temps.insert(temp.clone(), (bytes.clone(), false));
            }
            Step::SyncFile { temp } => {
                if let Some(t) = temps.get_mut(temp) {
                    t.1 = true;
                }
            }
            Step::Rename { temp, to } => {
                let contents = temps
                    .remove(temp)
                    .and_then(|(b, synced)| synced.then_some(b));
                pending.push((to.clone(), contents));
            }
            Step::SyncDir { dir } => {
                pending.retain(|(to, contents)| {
                    if to.parent() == Some(dir.as_path()) {
                        durable.insert(to.clone(), contents.clone());
                        false
                    } else {
                        true
                    }
                });
            }
        }
    }
    let mut possible: Possible = durable.into_iter().map(|(p, c)| (p, vec![c])).collect();
    // A rename whose directory was not synced may or may not have reached the disk.
    for (to, contents) in pending {
        possible.entry(to).or_default().push(contents);
    }
    possible
}

fn files(dir: &Path) -> HashMap<PathBuf, Vec<u8>> {
    let mut out = HashMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.insert(p.clone(), std::fs::read(&p).unwrap());
            }
        }
    }
    out
}

/// Two files written once, as a mesh upload and a kept warp map are (a file in a directory
/// made durably on first use).
fn store(dir: &Path) -> &Path {
    writes(dir, b"first").unwrap();
    dir
}

/// Both files rewritten.
fn writes(dir: &Path, bytes: &[u8]) -> omniwarp::Result<()> {
    for name in ["meshes/wall.obj", "warps/left-0123456789abcdef.exr"] {
        let path = dir.join(name);
        create_dir_durably(path.parent().unwrap())?;
        atomic_write(&path, |f| {
            std::io::Write::write_all(f, bytes).map_err(|e| omniwarp::Error::file(&path, e))
        })?;
    }
    Ok(())
}

#[test]
fn every_crash_point_leaves_old_or_new_and_an_acknowledged_write_is_durable() {
    let dir = tempfile::tempdir().unwrap();
    let s = store(dir.path());
    let before = files(dir.path());
    let (result, steps) = journal(None, || writes(s, b"second"));
    result.unwrap();
    let after = files(dir.path());
    assert!(steps.len() >= 8, "{steps:?}");
    for k in 0..=steps.len() {
        for (path, versions) in after_power_loss(&before, &steps[..k]) {
            for v in versions {
                let v = v.unwrap_or_else(|| {
                    panic!("a crash after step {k} can leave {} torn", path.display())
                });
                let old = before.get(&path);
                let new = after.get(&path);
                assert!(
                    Some(&v) == old || Some(&v) == new,
                    "a crash after step {k} leaves {} neither old nor new",
                    path.display()
                );
            }
        }
    }
    // Returned Ok: every file is durably what is on disk now.
    for (path, versions) in after_power_loss(&before, &steps) {
        if path.to_string_lossy().contains(".omniwarp-") {
            continue;
        }
        assert_eq!(
            versions,
            vec![after.get(&path).cloned()],
            "{} is not durable when the write returns",
            path.display()
        );
    }
    for written in ["meshes/wall.obj", "warps/left-0123456789abcdef.exr"] {
        assert_eq!(after[&dir.path().join(written)], b"second", "{written}");
    }
}

#[test]
fn a_write_failing_at_any_step_reports_it_and_leaves_old_or_new() {
    let probe = tempfile::tempdir().unwrap();
    let s = store(probe.path());
    let ((), steps) = {
        let (r, steps) = journal(None, || writes(s, b"second"));
        (r.unwrap(), steps)
    };
    for k in 0..steps.len() {
        let dir = tempfile::tempdir().unwrap();
        let s = store(dir.path());
        let (result, taken) = journal(Some(k), || writes(s, b"second"));
        let e = result.expect_err("an injected fault must be reported");
        assert!(e.to_string().contains("injected fault"), "step {k}: {e}");
        assert_eq!(
            taken.len(),
            k + 1,
            "step {k}: the write went on after the fault"
        );
        let leftovers: Vec<_> = files(dir.path())
            .into_keys()
            .filter(|p| p.to_string_lossy().contains(".omniwarp-"))
            .collect();
        assert!(leftovers.is_empty(), "step {k}: {leftovers:?}");
        for (path, bytes) in files(dir.path()) {
            assert!(
                bytes == b"first" || bytes == b"second",
                "step {k}: {} holds neither version",
                path.display()
            );
        }
    }
}

#[test]
fn the_model_catches_a_missing_fsync_and_a_missing_directory_sync() {
    let before = HashMap::from([(PathBuf::from("/d/f"), b"old".to_vec())]);
    let write = Step::Write {
        temp: "/d/.t".into(),
        bytes: b"new".to_vec(),
    };
    let sync = Step::SyncFile {
        temp: "/d/.t".into(),
    };
    let rename = Step::Rename {
        temp: "/d/.t".into(),
        to: "/d/f".into(),
    };
    let dir = Step::SyncDir { dir: "/d".into() };
    let f = PathBuf::from("/d/f");
    let full = after_power_loss(
        &before,
        &[write.clone(), sync.clone(), rename.clone(), dir.clone()],
    );
    assert_eq!(full[&f], vec![Some(b"new".to_vec())]);
    let no_fsync = after_power_loss(&before, &[write.clone(), rename.clone(), dir.clone()]);
    assert_eq!(no_fsync[&f], vec![None]);
    let no_dir_sync = after_power_loss(&before, &[write, sync, rename]);
    assert_eq!(
        no_dir_sync[&f],
        vec![Some(b"old".to_vec()), Some(b"new".to_vec())]
    );
}
