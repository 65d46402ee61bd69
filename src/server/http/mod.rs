//! The HTTP plumbing every route stands on: the guard (Host, Origin, sizes and deadlines), the
//! error type and its JSON answers, the shared state with its revision and body helpers, and the
//! bounded worker pool heavy work runs in.

pub mod error;
pub mod guard;
pub mod jobs;
pub mod state;
