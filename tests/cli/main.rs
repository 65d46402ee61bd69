//! The `omniwarp` command end to end, the README's and the guides' command blocks run as written,
//! and the house rules read off the tree.

#[path = "../common/mod.rs"]
mod common;

mod cli;
mod house;
mod movie;
mod photometry;
mod readme;
mod rig;
