//! What the daemon keeps: the store (the rig and each channel's documents, written durably with
//! their history), the SQLite database under it and the migration from the file store of 0.1.0,
//! the computed warps kept on disk by the keeper, and what is kept computed in memory.

pub(crate) mod cache;
pub mod db;
pub(crate) mod keep;
pub(crate) mod store;
