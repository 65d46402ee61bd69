//! The HTTP plumbing every route stands on: the guard (Host, Origin, sizes and deadlines), the
//! error type and its JSON answers, the shared state with its revision and body helpers, the
//! bounded worker pool heavy work runs in, and the list of render nodes.

pub mod error;
pub mod guard;
pub mod jobs;
pub mod nodes;
pub mod state;
