//! The daemon's state in SQLite: every resource's current document, and its history.
//!
//! Why SQLite: every acknowledged write must be durable and must append to a history in the
//! same breath, so undo and "what did revision 40 look like" survive a crash; a process killed
//! between two files (the old store wrote `rig.json` and its `.prev`) cannot happen inside one
//! transaction. SQLite gives that with WAL and `synchronous = FULL` (a commit is on disk when it
//! returns), one file, no server, and its own integrity check; the bundled build needs no system
//! library. A log of JSON files would need our own compaction, index and recovery.
//!
//! Tables: `resources` (name → current revision) says what the daemon serves; `history` has a
//! row per revision of each resource (who, when, what was asked, the RFC 6902 patch from the
//! revision before, a full document every [`SNAPSHOT_EVERY`] revisions, and the undo/redo
//! targets); `proposals` the calibration proposals. A revision's document is rebuilt from the
//! nearest snapshot at or before it and the patches after, so 100,000 edits of one feature
//! cost their patches, not 100,000 copies of the screen — and an edit writes about a kilobyte,
//! not the whole document (the current one is rebuilt the same way, once, at start-up).

use rusqlite::{Connection, OptionalExtension, TransactionBehavior, params};
use serde_json::Value;
use std::path::Path;
use std::sync::{Arc, Mutex};

/// A full document is kept every this many revisions of a resource (and whenever the patch
/// would be larger than the document).
pub const SNAPSHOT_EVERY: u64 = 256;

/// The database file under the data directory.
pub const FILE: &str = "omniwarp.db";

const SCHEMA: &str = "
    CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
    CREATE TABLE IF NOT EXISTS resources (name TEXT PRIMARY KEY, revision INTEGER NOT NULL);
    CREATE TABLE IF NOT EXISTS history (
        seq INTEGER PRIMARY KEY AUTOINCREMENT,
        resource TEXT NOT NULL, revision INTEGER NOT NULL,
        at_ms INTEGER NOT NULL, who TEXT NOT NULL, action TEXT NOT NULL,
        request TEXT, patch TEXT, snapshot TEXT,
        undo_to INTEGER, redo_to INTEGER,
        UNIQUE (resource, revision));
    CREATE TABLE IF NOT EXISTS proposals (id INTEGER PRIMARY KEY, document TEXT NOT NULL);
";

/// One row of the history, as listed.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Row {
    /// The row's place in the history, increasing with every write.
    pub seq: i64,
    /// What was written: `rig`, `channels/<id>/content` or `channels/<id>/tiles`.
    pub resource: String,
    /// The resource's revision after this write.
    pub revision: u64,
    /// Milliseconds since the Unix epoch.
    pub at_ms: i64,
    /// Who wrote it: the token's name when one is required, `local` otherwise.
    pub who: String,
    /// create, import, migrate, put, patch, delete, apply, revert, undo, redo, recover or reset.
    pub action: String,
    /// What the client sent when it is small (a PATCH's edits, a revert's revision).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub request: Option<Value>,
    /// The revision an undo from this one goes back to.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub undo_to: Option<u64>,
    /// The revision a redo from this one goes forward to.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub redo_to: Option<u64>,
}

/// What a write records besides the document.
#[derive(Debug, Clone)]
pub struct Meta {
    /// Who writes (see [`Row::who`]).
    pub who: String,
    /// The kind of write (see [`Row::action`]).
    pub action: &'static str,
    /// What the client sent, when it is small.
    pub request: Option<Value>,
    /// The revision an undo from this write goes back to.
    pub undo_to: Option<u64>,
    /// The revision a redo from this write goes forward to.
    pub redo_to: Option<u64>,
}

/// How much of each document's history is kept: a row goes when it is beyond the newest
/// `revisions`, older than `max_age`, or beyond the newest `bytes` of that document's history,
/// whichever comes first; the current revision always stays, and the oldest row kept becomes a
/// full snapshot, so every revision still listed can be rebuilt, reverted to and merged from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Retention {
    /// Revisions of one document kept at most.
    pub revisions: u64,
    /// Rows older than this go.
    pub max_age: std::time::Duration,
    /// Bytes of one document's history (patches and snapshots) kept at most.
    pub bytes: u64,
}

impl Default for Retention {
    fn default() -> Self {
        Retention {
            revisions: 10_000,
            max_age: std::time::Duration::from_secs(365 * 86_400),
            bytes: 256 << 20,
        }
    }
}

/// A document's history is compacted whenever its revision reaches a multiple of this, so the
/// cost is spread over the writes.
pub const COMPACT_EVERY: u64 = 64;

/// The daemon's SQLite database (a file in the data directory, or in memory without one):
/// the current documents, their history and the calibration proposals.
pub struct Db {
    conn: Mutex<Connection>,
    committed: Mutex<Option<CommitHook>>,
    retention: Mutex<Retention>,
}

/// Called with the resource's name after each write is committed (see [`Db::on_commit`]).
pub type CommitHook = Arc<dyn Fn(&str) + Send + Sync>;

/// A write transaction, holding SQLite's write lock from its start: a deferred one starts as a
/// read and fails at once with "database is locked" when another process (a backup, `sqlite3`)
/// holds the lock, where an immediate one waits the busy timeout for it.
fn write_transaction(conn: &mut Connection) -> crate::Result<rusqlite::Transaction<'_>> {
    conn.transaction_with_behavior(TransactionBehavior::Immediate)
        .map_err(fail)
}

fn fail(e: impl std::fmt::Display + 'static) -> crate::Error {
    // SQLite says "database or disk is full" with its own code, not the system's: carried as
    // the I/O kind, so the answer can say the disk is full rather than "internal error".
    let full = (&e as &dyn std::any::Any)
        .downcast_ref::<rusqlite::Error>()
        .and_then(rusqlite::Error::sqlite_error_code)
        == Some(rusqlite::ErrorCode::DiskFull);
    if full {
        return crate::Error::file(
            FILE,
            std::io::Error::new(std::io::ErrorKind::StorageFull, e.to_string()),
        );
    }
    crate::Error::file(FILE, e)
}

/// Creates an empty database file readable by its owner only, unless one exists: SQLite
/// gives its `-wal` and `-shm` files the database file's mode, so the history stays private.
fn create_private(path: &Path) -> crate::Result<()> {
    let mut o = std::fs::OpenOptions::new();
    o.write(true).create_new(true);
    #[cfg(unix)]
    std::os::unix::fs::OpenOptionsExt::mode(&mut o, 0o600);
    match o.open(path) {
        Err(e) if e.kind() != std::io::ErrorKind::AlreadyExists => Err(crate::Error::file(path, e)),
        _ => Ok(()),
    }
}

fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as i64)
}

impl Db {
    /// Opens (or creates) the database at `path`, in memory without one; a file that is not a
    /// sound SQLite database is an error, never replaced.
    pub fn open(path: Option<&Path>) -> crate::Result<Db> {
        if let Some(p) = path {
            create_private(p)?;
        }
        let conn = match path {
            Some(p) => Connection::open(p).map_err(fail)?,
            None => Connection::open_in_memory().map_err(fail)?,
        };
        conn.busy_timeout(std::time::Duration::from_secs(5))
            .map_err(fail)?;
        conn.pragma_update(None, "journal_mode", "WAL")
            .map_err(fail)?;
        conn.pragma_update(None, "synchronous", "FULL")
            .map_err(fail)?;
        let ok: String = conn
            .query_row("PRAGMA quick_check", [], |r| r.get(0))
            .map_err(fail)?;
        if ok != "ok" {
            return Err(fail(format!("integrity check failed: {ok}")));
        }
        conn.execute_batch(SCHEMA).map_err(fail)?;
        Ok(Db {
            conn: Mutex::new(conn),
            committed: Mutex::new(None),
            retention: Mutex::new(Retention::default()),
        })
    }

    fn conn(&self) -> std::sync::MutexGuard<'_, Connection> {
        self.conn.lock().expect("no query panics")
    }

    /// The value kept under `key` in the database's own settings, if any.
    pub fn meta(&self, key: &str) -> crate::Result<Option<String>> {
        self.conn()
            .query_row("SELECT value FROM meta WHERE key = ?1", [key], |r| r.get(0))
            .optional()
            .map_err(fail)
    }

    /// Keeps `value` under `key` in the database's own settings.
    pub fn set_meta(&self, key: &str, value: &str) -> crate::Result<()> {
        self.conn()
            .execute(
                "INSERT OR REPLACE INTO meta (key, value) VALUES (?1, ?2)",
                params![key, value],
            )
            .map(|_| ())
            .map_err(fail)
    }

    /// The current revision and document of `resource`.
    pub fn current(&self, resource: &str) -> crate::Result<Option<(u64, Value)>> {
        let conn = self.conn();
        let Some(revision) = revision_in(&conn, resource)? else {
            return Ok(None);
        };
        let doc = at_in(&conn, resource, revision)?
            .ok_or_else(|| fail(format!("{resource} lost revision {revision}")))?;
        Ok(Some((revision, doc)))
    }

    /// Makes `after` the current document of `resource` and appends it to the history, in one
    /// transaction. `before` is the document it replaces: written first as a `create` row when
    /// the resource has no row yet (a channel's defaults), so every revision can be rebuilt.
    pub fn write(
        &self,
        resource: &str,
        before: Option<(u64, &Value)>,
        after: (u64, &Value),
        meta: &Meta,
    ) -> crate::Result<()> {
        let mut conn = self.conn();
        let tx = write_transaction(&mut conn)?;
        let stored = revision_in(&tx, resource)?;
        // The caller's `before` is the current document whenever its revision is the stored
        // one; only otherwise is it rebuilt (a write after a recovery, say).
        let previous: Option<(u64, std::borrow::Cow<Value>)> = match (stored, before) {
            (Some(rev), Some((b, doc))) if rev == b => Some((rev, std::borrow::Cow::Borrowed(doc))),
            (Some(rev), _) => {
                let doc = at_in(&tx, resource, rev)?
                    .ok_or_else(|| fail(format!("{resource} lost revision {rev}")))?;
                Some((rev, std::borrow::Cow::Owned(doc)))
            }
            (None, Some((rev, doc))) => {
                let created = Meta {
                    who: "omniwarp".into(),
                    action: "create",
                    request: None,
                    undo_to: None,
                    redo_to: None,
                };
                insert_row(&tx, resource, rev, None, doc, &created)?;
                Some((rev, std::borrow::Cow::Borrowed(doc)))
            }
            (None, None) => None,
        };
        insert_row(
            &tx,
            resource,
            after.0,
            previous.as_ref().map(|(r, d)| (*r, d.as_ref())),
            after.1,
            meta,
        )?;
        tx.execute(
            "INSERT OR REPLACE INTO resources (name, revision) VALUES (?1, ?2)",
            params![resource, after.0 as i64],
        )
        .map_err(fail)?;
        tx.commit().map_err(fail)?;
        drop(conn);
        self.committed(resource);
        self.compact_now_and_then(resource, after.0);
        Ok(())
    }

    /// [`Db::write`] when the patch from revision `from` is already known (a tile edit that
    /// changed a few features): nothing is rebuilt or compared, and `doc` is asked for only when
    /// a snapshot is due. `Ok(false)` (nothing written) when `from` is not the stored revision.
    pub fn write_patch(
        &self,
        resource: &str,
        (from, to): (u64, u64),
        patch: &json_patch::Patch,
        doc: &dyn Fn() -> Value,
        meta: &Meta,
    ) -> crate::Result<bool> {
        let mut conn = self.conn();
        let tx = write_transaction(&mut conn)?;
        if revision_in(&tx, resource)? != Some(from) {
            return Ok(false);
        }
        let text = serde_json::to_string(patch).expect("patches serialise");
        let snapshot =
            (to.is_multiple_of(SNAPSHOT_EVERY) || from + 1 != to).then(|| doc().to_string());
        insert(&tx, resource, to, Some(text), snapshot, meta)?;
        tx.execute(
            "INSERT OR REPLACE INTO resources (name, revision) VALUES (?1, ?2)",
            params![resource, to as i64],
        )
        .map_err(fail)?;
        tx.commit().map_err(fail)?;
        drop(conn);
        self.committed(resource);
        self.compact_now_and_then(resource, to);
        Ok(true)
    }

    /// Calls `hook` after every committed write from now on (`None`: no more). For tests that
    /// must act at the moment a write is durable, such as a client going away right then.
    #[doc(hidden)]
    pub fn on_commit(&self, hook: Option<CommitHook>) {
        *self.committed.lock().expect("hook lock") = hook;
    }

    fn committed(&self, resource: &str) {
        let hook = self.committed.lock().expect("hook lock").clone();
        if let Some(hook) = hook {
            hook(resource);
        }
    }

    /// Keeps the history within `retention` from now on, compacting every document now.
    pub fn set_retention(&self, retention: Retention) -> crate::Result<()> {
        *self.retention.lock().expect("retention lock") = retention;
        let names: Vec<String> = {
            let conn = self.conn();
            let mut st = conn.prepare("SELECT name FROM resources").map_err(fail)?;
            st.query_map([], |r| r.get(0))
                .map_err(fail)?
                .collect::<Result<_, _>>()
                .map_err(fail)?
        };
        for name in names {
            self.compact(&name)?;
        }
        Ok(())
    }

    /// A write is durable once committed: a compaction that fails after it is logged, not
    /// reported to the writer, and tried again at the next multiple.
    fn compact_now_and_then(&self, resource: &str, revision: u64) {
        if revision.is_multiple_of(COMPACT_EVERY)
            && let Err(e) = self.compact(resource)
        {
            tracing::error!(resource, error = %e, "could not compact the history");
        }
    }

    /// Drops the rows of `resource` beyond the retention (see [`Retention`]); returns how many
    /// went. The oldest row kept becomes a snapshot in the same transaction.
    pub fn compact(&self, resource: &str) -> crate::Result<usize> {
        let keep = *self.retention.lock().expect("retention lock");
        let oldest_ms = now_ms().saturating_sub(keep.max_age.as_millis() as i64);
        let mut conn = self.conn();
        let tx = write_transaction(&mut conn)?;
        let rows: Vec<(u64, i64, u64)> = {
            let mut st = tx
                .prepare(
                    "SELECT revision, at_ms, COALESCE(LENGTH(patch), 0)
                     + COALESCE(LENGTH(snapshot), 0) FROM history WHERE resource = ?1
                     ORDER BY revision DESC",
                )
                .map_err(fail)?;
            st.query_map([resource], |r| {
                Ok((
                    r.get::<_, i64>(0)? as u64,
                    r.get(1)?,
                    r.get::<_, i64>(2)? as u64,
                ))
            })
            .map_err(fail)?
            .collect::<Result<_, _>>()
            .map_err(fail)?
        };
        let mut bytes = 0u64;
        let mut first_kept = None;
        for (n, (revision, at_ms, size)) in rows.iter().enumerate() {
            bytes = bytes.saturating_add(*size);
            let within = (n as u64) < keep.revisions && *at_ms >= oldest_ms && bytes <= keep.bytes;
            if n > 0 && !within {
                break;
            }
            first_kept = Some(*revision);
        }
        let Some(first) = first_kept.filter(|_| first_kept != rows.last().map(|r| r.0)) else {
            return Ok(0);
        };
        let doc = at_in(&tx, resource, first)?
            .ok_or_else(|| fail(format!("{resource} lost revision {first}")))?;
        tx.execute(
            "UPDATE history SET snapshot = ?3 WHERE resource = ?1 AND revision = ?2",
            params![resource, first as i64, doc.to_string()],
        )
        .map_err(fail)?;
        let dropped = tx
            .execute(
                "DELETE FROM history WHERE resource = ?1 AND revision < ?2",
                params![resource, first as i64],
            )
            .map_err(fail)?;
        tx.commit().map_err(fail)?;
        Ok(dropped)
    }

    /// The document of `resource` at `revision`, rebuilt from its history.
    pub fn at(&self, resource: &str, revision: u64) -> crate::Result<Option<Value>> {
        at_in(&self.conn(), resource, revision)
    }

    /// The patch that made `revision` of `resource` from the one before (`None` for the first
    /// row, or where only a snapshot was kept).
    pub fn patch_of(
        &self,
        resource: &str,
        revision: u64,
    ) -> crate::Result<Option<json_patch::Patch>> {
        let p: Option<Option<String>> = self
            .conn()
            .query_row(
                "SELECT patch FROM history WHERE resource = ?1 AND revision = ?2",
                params![resource, revision as i64],
                |r| r.get(0),
            )
            .optional()
            .map_err(fail)?;
        p.flatten()
            .map(|p| serde_json::from_str(&p).map_err(fail))
            .transpose()
    }

    /// One history row.
    pub fn row(&self, resource: &str, revision: u64) -> crate::Result<Option<Row>> {
        let conn = self.conn();
        conn.query_row(
            &format!("{SELECT_ROW} WHERE resource = ?1 AND revision = ?2"),
            params![resource, revision as i64],
            read_row,
        )
        .optional()
        .map_err(fail)
    }

    /// The newest `limit` rows (of `resource` only, when given), newest first, older than
    /// `before` (a `seq`) when given.
    pub fn history(
        &self,
        resource: Option<&str>,
        limit: usize,
        before: Option<i64>,
    ) -> crate::Result<Vec<Row>> {
        let conn = self.conn();
        let mut st = conn
            .prepare(&format!(
                "{SELECT_ROW} WHERE (?1 IS NULL OR resource = ?1) AND (?2 IS NULL OR seq < ?2)
                 ORDER BY seq DESC LIMIT ?3"
            ))
            .map_err(fail)?;
        st.query_map(params![resource, before, limit as i64], read_row)
            .map_err(fail)?
            .collect::<Result<_, _>>()
            .map_err(fail)
    }

    /// Rows and bytes the history holds (for the benchmark and the health route).
    pub fn size(&self) -> crate::Result<(u64, u64)> {
        let conn = self.conn();
        let rows: i64 = conn
            .query_row("SELECT COUNT(*) FROM history", [], |r| r.get(0))
            .map_err(fail)?;
        let bytes: i64 = conn
            .query_row(
                "SELECT COALESCE(SUM(LENGTH(patch)), 0) + COALESCE(SUM(LENGTH(snapshot)), 0)
                 + COALESCE(SUM(LENGTH(request)), 0) FROM history",
                [],
                |r| r.get(0),
            )
            .map_err(fail)?;
        Ok((rows as u64, bytes as u64))
    }

    /// Keeps calibration proposal `id` (its JSON document), replacing one of that id.
    pub fn put_proposal(&self, id: u64, doc: &Value) -> crate::Result<()> {
        self.conn()
            .execute(
                "INSERT OR REPLACE INTO proposals (id, document) VALUES (?1, ?2)",
                params![id as i64, doc.to_string()],
            )
            .map(|_| ())
            .map_err(fail)
    }

    /// Forgets calibration proposal `id`.
    pub fn delete_proposal(&self, id: u64) -> crate::Result<()> {
        self.conn()
            .execute("DELETE FROM proposals WHERE id = ?1", [id as i64])
            .map(|_| ())
            .map_err(fail)
    }

    /// Every kept calibration proposal with its id.
    pub fn proposals(&self) -> crate::Result<Vec<(u64, Value)>> {
        let conn = self.conn();
        let mut st = conn
            .prepare("SELECT id, document FROM proposals ORDER BY id")
            .map_err(fail)?;
        let rows = st
            .query_map([], |r| Ok((r.get::<_, i64>(0)?, r.get::<_, String>(1)?)))
            .map_err(fail)?;
        let mut out = Vec::new();
        for r in rows {
            let (id, doc) = r.map_err(fail)?;
            match serde_json::from_str(&doc) {
                Ok(v) => out.push((id as u64, v)),
                Err(e) => tracing::error!(id, error = %e, "proposal unreadable, left out"),
            }
        }
        Ok(out)
    }
}

/// The document of `resource` at `revision`: the nearest snapshot at or before it, and the
/// patches after it.
fn at_in(conn: &Connection, resource: &str, revision: u64) -> crate::Result<Option<Value>> {
    let base: Option<(i64, String)> = conn
        .query_row(
            "SELECT revision, snapshot FROM history WHERE resource = ?1 AND revision <= ?2
             AND snapshot IS NOT NULL ORDER BY revision DESC LIMIT 1",
            params![resource, revision as i64],
            |r| Ok((r.get(0)?, r.get(1)?)),
        )
        .optional()
        .map_err(fail)?;
    let exists: bool = conn
        .query_row(
            "SELECT COUNT(*) FROM history WHERE resource = ?1 AND revision = ?2",
            params![resource, revision as i64],
            |r| r.get::<_, i64>(0),
        )
        .map_err(fail)?
        > 0;
    let Some((from, snapshot)) = base.filter(|_| exists) else {
        return Ok(None);
    };
    let mut doc: Value = serde_json::from_str(&snapshot).map_err(fail)?;
    let mut st = conn
        .prepare(
            "SELECT patch FROM history WHERE resource = ?1 AND revision > ?2
             AND revision <= ?3 ORDER BY revision",
        )
        .map_err(fail)?;
    let patches = st
        .query_map(params![resource, from, revision as i64], |r| {
            r.get::<_, Option<String>>(0)
        })
        .map_err(fail)?;
    for p in patches {
        let p = p
            .map_err(fail)?
            .ok_or_else(|| fail("a history row lost its patch"))?;
        let patch: json_patch::Patch = serde_json::from_str(&p).map_err(fail)?;
        json_patch::patch(&mut doc, &patch).map_err(fail)?;
    }
    Ok(Some(doc))
}

/// The current revision of `resource`, if it has one.
fn revision_in(conn: &Connection, resource: &str) -> crate::Result<Option<u64>> {
    conn.query_row(
        "SELECT revision FROM resources WHERE name = ?1",
        [resource],
        |r| r.get::<_, i64>(0),
    )
    .optional()
    .map(|r| r.map(|v| v as u64))
    .map_err(fail)
}

const SELECT_ROW: &str =
    "SELECT seq, resource, revision, at_ms, who, action, request, undo_to, redo_to FROM history";

fn read_row(r: &rusqlite::Row) -> rusqlite::Result<Row> {
    let request: Option<String> = r.get(6)?;
    Ok(Row {
        seq: r.get(0)?,
        resource: r.get(1)?,
        revision: r.get::<_, i64>(2)? as u64,
        at_ms: r.get(3)?,
        who: r.get(4)?,
        action: r.get(5)?,
        request: request.and_then(|t| serde_json::from_str(&t).ok()),
        undo_to: r.get::<_, Option<i64>>(7)?.map(|v| v as u64),
        redo_to: r.get::<_, Option<i64>>(8)?.map(|v| v as u64),
    })
}

/// Appends revision `revision` of `resource`: the patch from `previous`, and a snapshot where
/// one is due (the first row, every [`SNAPSHOT_EVERY`] revisions, a patch above the document).
fn insert_row(
    tx: &rusqlite::Transaction,
    resource: &str,
    revision: u64,
    previous: Option<(u64, &Value)>,
    doc: &Value,
    meta: &Meta,
) -> crate::Result<()> {
    let patch = previous
        .map(|(_, p)| serde_json::to_string(&json_patch::diff(p, doc)).expect("patches serialise"));
    // Only a large patch (a reset or a PUT replaces most of the document) is worth comparing
    // with the document: replaying it would cost more than a snapshot says.
    let small = |p: &str| p.len() < 4096 || p.len() < doc.to_string().len();
    let snapshot = match (&patch, previous) {
        (Some(p), Some((prev, _)))
            if !revision.is_multiple_of(SNAPSHOT_EVERY) && prev + 1 == revision && small(p) =>
        {
            None
        }
        _ => Some(doc.to_string()),
    };
    insert(tx, resource, revision, patch, snapshot, meta)
}

/// Appends one history row.
fn insert(
    tx: &rusqlite::Transaction,
    resource: &str,
    revision: u64,
    patch: Option<String>,
    snapshot: Option<String>,
    meta: &Meta,
) -> crate::Result<()> {
    tx.execute(
        "INSERT INTO history (resource, revision, at_ms, who, action, request, patch, snapshot,
         undo_to, redo_to) VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10)",
        params![
            resource,
            revision as i64,
            now_ms(),
            meta.who,
            meta.action,
            meta.request.as_ref().map(|v| v.to_string()),
            patch,
            snapshot,
            meta.undo_to.map(|v| v as i64),
            meta.redo_to.map(|v| v as i64),
        ],
    )
    .map_err(fail)?;
    Ok(())
}
