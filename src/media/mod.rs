//! Movies and image sequences through the warp: content frames in, one warped (and blended)
//! movie or sequence out per output, every output fed from one decode.
//!
//! Movies are read and written by the `ffmpeg` and `ffprobe` programs as child processes (no
//! codec library is linked): frames cross the pipes as 8-bit 4:2:0 Y′CbCr where the movie is
//! stored that way (a quarter of RGBA's bytes; converted in [`yuv`] as the atlas is filled and
//! as the warped frame is packed), as RGBA otherwise, and as 16-bit RGBA from deeper sources.
//! Image sequences (`frame-%05d.png`, `.exr`, `.tif`, `.jpg`) are read and written here,
//! 8-bit or float, each file checked before the first frame is warped.
//!
//! Decoding, warping and encoding run as a pipeline of threads with queues two frames deep.
//! Outputs appear only when complete: a movie is written under a temporary name and renamed at
//! the end; a sequence's frames written so far are removed if the run fails or is stopped.

mod input;
mod output;
mod pack;
mod probe;
mod run;
pub mod yuv;

pub use input::{Frame, Input, Sequence};
pub use output::{Encoding, OutputSpec};
pub use pack::Sample;
pub use probe::{Info, Rate};
pub use run::{Progress, Summary, Target, transcode};

use crate::Error;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The output that discards its frames after packing them as for a 4:2:0 movie: what the
/// decode and the warp alone sustain (as ffmpeg's `-f null -`).
pub const NULL: &str = "null:";

/// Extensions read as movies.
pub const MOVIE_EXTENSIONS: [&str; 10] = [
    "mp4", "mov", "mkv", "avi", "mxf", "webm", "m4v", "nut", "mpg", "ts",
];

/// Whether `path` names a movie (by its extension) or an image sequence (a `%d`-style
/// pattern): content for [`transcode`] rather than a still image.
pub fn is_media(path: &Path) -> bool {
    Sequence::is_pattern(path) || is_movie(path) || path.as_os_str() == NULL
}

/// Whether `path` has a movie's extension.
pub fn is_movie(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| MOVIE_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
}

/// The program `name` (`ffmpeg` or `ffprobe`): `$OMNIWARP_FFMPEG_DIR/name` when that is set,
/// else the one on the PATH.
fn tool(name: &str) -> PathBuf {
    match std::env::var_os("OMNIWARP_FFMPEG_DIR") {
        Some(dir) => PathBuf::from(dir).join(name),
        None => PathBuf::from(name),
    }
}

/// Why `name` could not be started: a clear error naming the package when it is not installed.
fn not_started(name: &str, e: std::io::Error) -> Error {
    if e.kind() == std::io::ErrorKind::NotFound {
        Error::invalid(
            "content",
            format!(
                "movies are read and written with `{name}`, which is not installed: install the \
                 ffmpeg package (Debian: apt install ffmpeg)"
            ),
        )
    } else {
        Error::file(tool(name), e)
    }
}

/// `ffmpeg` or `ffprobe` ready to run, in a process group of its own: a terminal's Ctrl-C
/// reaches this process, which stops the run and its children itself and removes what they
/// were writing, instead of each child stopping on its own mid-file. (Whether it is installed
/// shows when it is started: asking it first would cost a start of its own, about 0.1 s.)
fn command(name: &str) -> Command {
    let mut c = Command::new(tool(name));
    #[cfg(unix)]
    std::os::unix::process::CommandExt::process_group(&mut c, 0);
    c
}

/// The last lines of a child's standard error, for an error message.
fn tail(stderr: &[u8]) -> String {
    let text = String::from_utf8_lossy(stderr);
    let lines: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    lines[lines.len().saturating_sub(3)..].join(" / ")
}
