//! The routes, one file per resource: the rig and its channels, their documents (content canvas,
//! tile screens) and history, the outputs (warp maps, blends, previews, test cards, exports), the
//! camera calibration (patterns, captures, proposals), meshes, scenes, render jobs, the render
//! nodes that follow the daemon and the console's assets.

pub mod calib;
pub mod captures;
pub mod channels;
pub mod console;
pub mod exports;
pub mod geometry;
pub mod history;
pub mod meshes;
pub mod nodes;
pub mod outputs;
pub mod plan;
pub mod renders;
pub mod rig;
pub mod show;
