//! What previews compute, apart from the routes that ask for them: the test pattern through a
//! channel's warp (kept pattern cubes and prepared plans) and 3D scenes through it, each with the
//! little it keeps between requests.

pub mod pattern;
pub mod scene;
