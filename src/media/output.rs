//! Warped frames out: a movie encoded by an `ffmpeg` child under a temporary name, renamed when
//! complete, or an image sequence written here; a writer thread per output, two frames behind
//! the warp.

use super::input::{Reaped, drain};
use super::probe::Rate;
use super::yuv::Matrix;
use crate::image_io::{self, Precision};
use crate::raster::Raster;
use crate::{Error, Result};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{ChildStdin, Stdio};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::thread::JoinHandle;

/// How an output movie is encoded; `None` fields take the container's defaults.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Encoding {
    /// ffmpeg's encoder (`libx264`, `libx265`, `prores_ks`, `hap`, `ffv1`, …).
    pub encoder: Option<String>,
    /// Constant rate factor (libx264, libx265).
    pub crf: Option<u32>,
    /// Encoder preset (libx264, libx265: `ultrafast` … `veryslow`).
    pub preset: Option<String>,
    /// The stored pixel format (`yuv420p`, `yuv422p10le`, …).
    pub pix_fmt: Option<String>,
    /// Further encoder options, each `-name value` on ffmpeg's command line.
    pub options: Vec<(String, String)>,
    /// Sequences: EXR frames as 16-bit half floats instead of 32-bit.
    pub half: bool,
}

impl Encoding {
    fn encoder_for(&self, path: &Path) -> String {
        if let Some(e) = &self.encoder {
            return e.clone();
        }
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or("")
            .to_ascii_lowercase();
        match ext.as_str() {
            "mov" => "prores_ks",
            "nut" => "ffv1",
            _ => "libx264",
        }
        .to_string()
    }

    /// Checks the names before any work: ffmpeg's option syntax only, so that nothing here can
    /// become another argument.
    pub fn check(&self) -> Result<()> {
        let word = |s: &str| {
            !s.is_empty()
                && s.len() <= 64
                && s.bytes()
                    .all(|b| b.is_ascii_alphanumeric() || b"_-:.+".contains(&b))
        };
        for (field, v) in [
            ("encoder", &self.encoder),
            ("preset", &self.preset),
            ("pix-fmt", &self.pix_fmt),
        ] {
            if let Some(v) = v.as_deref().filter(|v| !word(v)) {
                return Err(Error::invalid(
                    field,
                    format!("`{v}` is not a name ffmpeg knows"),
                ));
            }
        }
        if let Some(c) = self.crf.filter(|&c| c > 63) {
            return Err(Error::invalid("crf", format!("must be 0–63, got {c}")));
        }
        for (k, v) in &self.options {
            if !word(k) || k.starts_with('-') || v.len() > 256 {
                return Err(Error::invalid(
                    "encoder-option",
                    format!("`{k}={v}` is not NAME=VALUE with a plain option name"),
                ));
            }
        }
        Ok(())
    }
}

/// One output: where it goes and how it is encoded.
#[derive(Debug, Clone, PartialEq)]
pub struct OutputSpec {
    /// A movie file (by its extension, see [`super::MOVIE_EXTENSIONS`]) or a sequence pattern
    /// (`out-%05d.png` or `.exr`).
    pub path: PathBuf,
    /// How a movie is encoded.
    pub encoding: Encoding,
}

/// What the writer thread is handed.
pub(super) enum Packet {
    Bytes(Vec<u8>),
    /// The last frame has been sent: the output is complete.
    End,
    U8(Raster<[u8; 4]>),
    F32(Raster<[f32; 4]>),
}

/// How frames cross the pipe to an encoder.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Pipe {
    Yuv420,
    Rgba,
    /// Not a pipe: sequence files written here, 8-bit PNG or float EXR.
    Png,
    Exr,
}

/// What the movie being written carries over from the content.
#[derive(Debug, Clone, Default)]
pub(super) struct Carry {
    pub audio_from: Option<PathBuf>,
    pub timecode: Option<String>,
    pub color: [Option<String>; 4],
}

/// An output being written.
pub(super) struct Sink {
    pub pipe: Pipe,
    tx: Option<SyncSender<Packet>>,
    /// Byte buffers the writer is done with, for the next frames (a 4K frame is 12 MB: a fresh
    /// one each frame costs its page faults).
    spare: Receiver<Vec<u8>>,
    thread: Option<JoinHandle<Result<()>>>,
    /// The movie's temporary file and its final name.
    movie: Option<(PathBuf, PathBuf)>,
}

fn temporary(path: &Path) -> PathBuf {
    let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("out");
    path.with_file_name(format!(
        ".{name}.partial-{}.{}",
        std::process::id(),
        ext(path)
    ))
}

fn ext(path: &Path) -> String {
    path.extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase()
}

impl Sink {
    /// Starts writing `spec` for frames of `size` at `rate`, numbering a sequence from `first`.
    pub fn start(
        spec: &OutputSpec,
        size: (u32, u32),
        rate: Rate,
        first: u64,
        matrix: Matrix,
        carry: &Carry,
    ) -> Result<Sink> {
        let path = &spec.path;
        if path.as_os_str() == super::NULL {
            return Ok(Self::null());
        }
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| Error::file(dir, e))?;
        }
        if super::Sequence::is_pattern(path) {
            let pipe = match ext(path).as_str() {
                "png" => Pipe::Png,
                "exr" => Pipe::Exr,
                _ => {
                    return Err(Error::invalid(
                        "out",
                        format!("{}: sequences are written as .png or .exr", path.display()),
                    ));
                }
            };
            return Ok(Self::sequence(
                path.clone(),
                pipe,
                first,
                spec.encoding.half,
            ));
        }
        if !super::is_movie(path) {
            return Err(Error::invalid(
                "out",
                format!(
                    "{}: a movie ({}) or a sequence pattern (frame-%05d.png)",
                    path.display(),
                    super::MOVIE_EXTENSIONS.join(", ")
                ),
            ));
        }
        spec.encoding.check()?;
        let e = &spec.encoding;
        let encoder = e.encoder_for(path);
        let stored = e.pix_fmt.clone().unwrap_or_else(|| {
            match encoder.as_str() {
                "prores_ks" | "prores" | "prores_aw" => "yuv422p10le",
                "ffv1" | "utvideo" => "bgr0",
                "hap" | "png" | "qtrle" | "rawvideo" => "rgba",
                "libx264rgb" => "bgr24",
                _ => "yuv420p",
            }
            .to_string()
        });
        // 8-bit 4:2:0 goes through the pipe as it is stored; anything else as RGBA, which
        // ffmpeg converts where the stored format is Y′CbCr.
        let pipe = if stored == "yuv420p" {
            Pipe::Yuv420
        } else {
            Pipe::Rgba
        };
        let rgb = ["rgb", "bgr", "gbr", "argb", "abgr", "rgba", "bgra"]
            .iter()
            .any(|k| stored.starts_with(k));
        let (w, h) = size;
        let tmp = temporary(path);
        let mut cmd = super::command("ffmpeg");
        cmd.args(["-hide_banner", "-nostdin", "-loglevel", "error", "-y"])
            .args(["-f", "rawvideo", "-pix_fmt"])
            .arg(if pipe == Pipe::Yuv420 {
                "yuv420p"
            } else {
                "rgba"
            })
            .args(["-s", &format!("{w}x{h}"), "-framerate", &rate.text()])
            .args(["-i", "pipe:0"]);
        if let Some(a) = &carry.audio_from {
            cmd.arg("-i")
                .arg(a)
                .args(["-map", "0:v:0", "-map", "1:a?", "-c:a", "copy"]);
        }
        cmd.args(["-c:v", &encoder]);
        if let Some(c) = e.crf {
            cmd.args(["-crf", &c.to_string()]);
        } else if matches!(encoder.as_str(), "libx264" | "libx265") {
            cmd.args(["-crf", "18"]);
        }
        if let Some(p) = &e.preset {
            cmd.args(["-preset", p]);
        }
        if encoder == "prores_ks" && !e.options.iter().any(|(k, _)| k.starts_with("profile")) {
            // ProRes 422 HQ, what media servers are usually fed.
            cmd.args(["-profile:v", "3"]);
        }
        for (k, v) in &e.options {
            cmd.arg(format!("-{k}")).arg(v);
        }
        if pipe == Pipe::Rgba && !rgb {
            // The encoder stores Y′CbCr: converted by ffmpeg with the content's matrix and
            // range, which its tags below name (ffmpeg's default would be BT.601 limited).
            let range = if matrix.full_range() { "pc" } else { "tv" };
            cmd.args([
                "-vf",
                &format!(
                    "scale=out_color_matrix={}:out_range={range}",
                    matrix.ffmpeg_name()
                ),
            ]);
        }
        cmd.args(["-pix_fmt", &stored]);
        if !rgb {
            // The matrix and range the Y′CbCr was made with, stated: the content's own tag when
            // it names a Y′CbCr matrix, else the one used (untagged HD is read as BT.709 by
            // most players, where the frames were made as BT.601).
            let space = match carry.color[0].as_deref() {
                Some(s) if !matches!(s, "gbr" | "rgb" | "ycgco") => s,
                _ => matrix.tag(),
            };
            let range = if matrix.full_range() { "pc" } else { "tv" };
            cmd.args(["-colorspace", space, "-color_range", range]);
        }
        for (flag, tag) in ["-color_primaries", "-color_trc"]
            .iter()
            .zip(&carry.color[1..3])
        {
            if let Some(t) = tag {
                cmd.args([*flag, t.as_str()]);
            }
        }
        if let Some(tc) = &carry.timecode {
            cmd.args(["-timecode", tc]);
        }
        let mut child = cmd
            .arg(&tmp)
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| super::not_started("ffmpeg", e))?;
        let stdin = child.stdin.take().expect("piped");
        let stderr = drain(child.stderr.take().expect("piped"));
        let (tx, rx) = sync_channel::<Packet>(2);
        let (back, spare) = sync_channel::<Vec<u8>>(4);
        let out = path.clone();
        let thread = std::thread::spawn(move || {
            let child = Reaped(child);
            encode(rx, &back, stdin, child, stderr, &out)
        });
        Ok(Sink {
            pipe,
            tx: Some(tx),
            spare,
            thread: Some(thread),
            movie: Some((tmp, path.clone())),
        })
    }

    /// Frames packed as for a 4:2:0 movie, then dropped: what the warp alone sustains.
    fn null() -> Sink {
        let (tx, rx) = sync_channel::<Packet>(2);
        let (back, spare) = sync_channel::<Vec<u8>>(4);
        let thread = std::thread::spawn(move || {
            for p in rx {
                match p {
                    Packet::End => return Ok(()),
                    Packet::Bytes(b) => {
                        let _ = back.try_send(b);
                    }
                    _ => {}
                }
            }
            Err(Error::Cancelled)
        });
        Sink {
            pipe: Pipe::Yuv420,
            tx: Some(tx),
            spare,
            thread: Some(thread),
            movie: None,
        }
    }

    fn sequence(pattern: PathBuf, pipe: Pipe, first: u64, half: bool) -> Sink {
        let (tx, rx) = sync_channel::<Packet>(2);
        let thread = std::thread::spawn(move || write_sequence(rx, &pattern, first, half));
        Sink {
            pipe,
            tx: Some(tx),
            spare: sync_channel(0).1,
            thread: Some(thread),
            movie: None,
        }
    }

    /// A byte buffer for the next frame: one the writer is done with, or a new one.
    pub fn buffer(&self) -> Vec<u8> {
        self.spare.try_recv().unwrap_or_default()
    }

    /// Hands a frame to the writer; an error if the writer has stopped (its reason).
    pub fn send(&mut self, p: Packet) -> Result<()> {
        let sent = self.tx.as_ref().is_some_and(|tx| tx.send(p).is_ok());
        if sent {
            return Ok(());
        }
        self.tx = None;
        Err(self
            .join()
            .err()
            .unwrap_or_else(|| Error::invalid("out", "the writer stopped before the last frame")))
    }

    fn join(&mut self) -> Result<()> {
        self.tx = None;
        match self.thread.take() {
            Some(t) => t
                .join()
                .unwrap_or_else(|_| Err(Error::invalid("out", "the writer failed"))),
            None => Ok(()),
        }
    }

    /// Waits for the writer to finish and puts a movie in place.
    /// Tells the writer the last frame has been sent and waits for it to finish writing; a
    /// movie stays under its temporary name until [`Sink::place`].
    pub fn complete(&mut self) -> Result<()> {
        if let Some(tx) = &self.tx {
            let _ = tx.send(Packet::End);
        }
        self.join()
    }

    /// Puts a completed movie in place: synced, renamed over its name, the folder synced. A
    /// movie that cannot be put in place is removed.
    pub fn place(mut self) -> Result<()> {
        if let Some((tmp, path)) = self.movie.take() {
            let moved = std::fs::File::open(&tmp)
                .and_then(|f| f.sync_all())
                .and_then(|()| std::fs::rename(&tmp, &path));
            if let Err(e) = moved {
                let _ = std::fs::remove_file(&tmp);
                return Err(Error::file(&path, e));
            }
            let dir = path.parent().filter(|d| !d.as_os_str().is_empty());
            if let Ok(d) = std::fs::File::open(dir.unwrap_or(Path::new("."))) {
                let _ = d.sync_all();
            }
        }
        Ok(())
    }
}

impl Drop for Sink {
    /// Not finished: the writer is stopped and what it wrote removed.
    fn drop(&mut self) {
        let _ = self.join();
        if let Some((tmp, _)) = self.movie.take() {
            let _ = std::fs::remove_file(tmp);
        }
    }
}

fn encode(
    rx: Receiver<Packet>,
    back: &SyncSender<Vec<u8>>,
    mut stdin: ChildStdin,
    mut child: Reaped,
    stderr: JoinHandle<Vec<u8>>,
    out: &Path,
) -> Result<()> {
    let (mut failed, mut complete) = (None, false);
    for p in rx {
        let bytes = match p {
            Packet::Bytes(b) => b,
            Packet::End => {
                complete = true;
                break;
            }
            _ => unreachable!("movies are fed bytes"),
        };
        if let Err(e) = stdin.write_all(&bytes) {
            failed = Some(e);
            break;
        }
        let _ = back.try_send(bytes);
    }
    drop(stdin);
    if !complete && failed.is_none() {
        // Stopped: the temporary file is removed; no need to wait for the encoder to finish.
        return Err(Error::Cancelled);
    }
    let status = child.0.wait().map_err(|e| Error::file(out, e))?;
    let errors = stderr.join().unwrap_or_default();
    if !status.success() || failed.is_some() {
        let detail = super::tail(&errors);
        let why = if detail.is_empty() {
            failed.map_or(format!("ffmpeg ended with {status}"), |e| e.to_string())
        } else {
            detail
        };
        return Err(Error::file(out, format!("encoding failed: {why}")));
    }
    Ok(())
}

/// The files of a sequence being written; removed again unless the sequence completes.
struct Written(Vec<PathBuf>, bool);

impl Drop for Written {
    fn drop(&mut self) {
        if !self.1 {
            for f in &self.0 {
                let _ = std::fs::remove_file(f);
            }
        }
    }
}

fn write_sequence(rx: Receiver<Packet>, pattern: &Path, first: u64, half: bool) -> Result<()> {
    let name = pattern.file_name().and_then(|n| n.to_str()).unwrap_or("");
    let (prefix, width, suffix) =
        super::input::split_pattern(name).expect("checked to be a pattern");
    let mut written = Written(Vec::new(), false);
    let precision = if half {
        Precision::Half
    } else {
        Precision::Float
    };
    for (k, p) in rx.into_iter().enumerate() {
        let path = pattern.with_file_name(format!("{prefix}{:0width$}{suffix}", first + k as u64));
        match p {
            Packet::U8(r) => {
                written.0.push(path.clone());
                image_io::write_png(&path, &r)?
            }
            Packet::F32(r) => {
                written.0.push(path.clone());
                image_io::write_exr_rgba(&path, &r, &[], precision)?
            }
            Packet::End => {
                written.1 = true;
                return Ok(());
            }
            Packet::Bytes(_) => unreachable!("sequences are fed images"),
        }
    }
    Err(Error::Cancelled)
}
