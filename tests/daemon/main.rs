//! The daemon: routes through `oneshot`, the real binary under load and SIGKILL, durability,
//! history, hostile clients, the console's side and the render nodes that follow it.

#[path = "../common/mod.rs"]
mod common;

mod canvas;
mod console;
mod daemon;
mod disconnect;
mod durability;
mod history;
mod hostile;
mod jobs;
mod play;
mod pressure;
mod server;
mod server_edit;
mod tls;
