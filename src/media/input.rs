//! Content frames in: a movie decoded by an `ffmpeg` child, or an image sequence read here,
//! on a thread of their own, two frames ahead of the warp.

use super::probe::{Info, Rate};
use super::yuv;
use crate::image_io::{self, Loaded};
use crate::raster::Raster;
use crate::{Error, Result};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::thread::JoinHandle;

/// One decoded content frame, as it came through the pipe or off the disk.
#[derive(Debug)]
pub enum Frame {
    /// 8-bit 4:2:0 planes ([`yuv::frame_len`] bytes).
    Yuv420(Vec<u8>),
    /// 8-bit RGBA.
    Rgba8(Raster<[u8; 4]>),
    /// Float RGBA (16-bit and float sources; 0–1 is black to white).
    RgbaF32(Raster<[f32; 4]>),
}

/// An image sequence: files named by a pattern with one `%d` or `%0Nd`, numbered without gaps.
#[derive(Debug, Clone)]
pub struct Sequence {
    /// The files in frame order.
    pub files: Vec<PathBuf>,
    /// The number of the first.
    pub first: u64,
    /// Frame size of the first file, pixels.
    pub size: (usize, usize),
    /// Whether the files hold more than 8 bits (EXR, 16-bit PNG or TIFF): read as float.
    pub deep: bool,
}

/// Where the content frames come from.
#[derive(Debug, Clone)]
pub enum Input {
    /// A movie, as ffprobe describes it.
    Movie {
        /// The movie file.
        path: PathBuf,
        /// What it holds.
        info: Info,
    },
    /// An image sequence, played at `rate`.
    Sequence(Sequence, Rate),
}

/// The pattern's name split at its `%d`/`%0Nd`: prefix, digits (0 for any), suffix.
pub(super) fn split_pattern(name: &str) -> Option<(&str, usize, &str)> {
    let at = name.find('%')?;
    let rest = &name[at + 1..];
    let d = rest.find('d')?;
    let spec = &rest[..d];
    let width = if spec.is_empty() {
        0
    } else if spec.starts_with('0') && spec.len() <= 2 {
        spec.parse().ok()?
    } else {
        return None;
    };
    let suffix = &rest[d + 1..];
    (!suffix.contains('%')).then_some((&name[..at], width, suffix))
}

impl Sequence {
    /// Whether the file name of `path` is a `%d`/`%0Nd` pattern.
    pub fn is_pattern(path: &Path) -> bool {
        path.file_name()
            .and_then(|n| n.to_str())
            .is_some_and(|n| split_pattern(n).is_some())
    }

    /// The files `pattern` names, checked: at least one, numbered without a gap (a missing
    /// frame is named), at most [`crate::limits::SEQUENCE_FRAMES`], all of the first one's size
    /// and depth (checked as they are read).
    pub fn find(pattern: &Path) -> Result<Sequence> {
        Self::find_within(pattern, None)
    }

    /// [`Sequence::find`], every frame checked to be a file inside `root` (symbolic links
    /// followed) before any is read, when given: the daemon's media folder.
    pub fn find_within(pattern: &Path, root: Option<&Path>) -> Result<Sequence> {
        let name = pattern.file_name().and_then(|n| n.to_str()).unwrap_or("");
        let (prefix, width, suffix) = split_pattern(name).ok_or_else(|| {
            Error::invalid(
                "content",
                format!("`{name}` has no frame number pattern (%d or %05d)"),
            )
        })?;
        let dir = match pattern.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let entries = std::fs::read_dir(&dir).map_err(|e| Error::file(&dir, e))?;
        let mut numbers = Vec::new();
        for e in entries {
            let e = e.map_err(|e| Error::file(&dir, e))?;
            let n = e.file_name();
            let Some(n) = n.to_str() else { continue };
            let Some(digits) = n.strip_prefix(prefix).and_then(|r| r.strip_suffix(suffix)) else {
                continue;
            };
            if digits.is_empty()
                || !digits.bytes().all(|b| b.is_ascii_digit())
                || (width > 0 && digits.len() != width)
                // `%d` writes numbers unpadded: `0007` is not one of its names.
                || (width == 0 && digits.len() > 1 && digits.starts_with('0'))
            {
                continue;
            }
            if let Ok(v) = digits.parse::<u64>() {
                numbers.push(v);
            }
            if numbers.len() > crate::limits::SEQUENCE_FRAMES {
                return Err(Error::invalid(
                    "content",
                    format!(
                        "`{name}` names more than {} frames",
                        crate::limits::SEQUENCE_FRAMES
                    ),
                ));
            }
        }
        numbers.sort_unstable();
        let file = |v: u64| dir.join(format!("{prefix}{v:0width$}{suffix}"));
        let (&first, &last) = match (numbers.first(), numbers.last()) {
            (Some(f), Some(l)) => (f, l),
            _ => return Err(Error::file(pattern, "no file matches this frame pattern")),
        };
        if let Some(w) = numbers.windows(2).find(|w| w[1] != w[0] + 1) {
            let missing = file(w[0] + 1);
            return Err(Error::file(
                &missing,
                format!("missing: the sequence runs from {first} to {last} with a gap here"),
            ));
        }
        let files: Vec<PathBuf> = (first..=last).map(file).collect();
        if let Some(root) = root {
            for f in &files {
                let inside = f
                    .canonicalize()
                    .is_ok_and(|real| real.starts_with(root) && real.is_file());
                if !inside {
                    return Err(Error::invalid(
                        "content",
                        format!(
                            "frame {} leads out of the media folder, or is not a file",
                            f.file_name().unwrap_or_default().to_string_lossy()
                        ),
                    ));
                }
            }
        }
        let (size, deep) = match image_io::read_image(&files[0])? {
            Loaded::U8(r) => ((r.width, r.height), false),
            Loaded::F32(r) => ((r.width, r.height), true),
        };
        check_side(&files[0], size)?;
        Ok(Sequence {
            files,
            first,
            size,
            deep,
        })
    }
}

fn check_side(path: &Path, (w, h): (usize, usize)) -> Result<()> {
    let max = crate::limits::MEDIA_SIDE as usize;
    if w < 2 || h < 2 || w > max || h > max {
        return Err(Error::file(
            path,
            format!("a frame must be 2–{max} pixels each way, got {w}×{h}"),
        ));
    }
    Ok(())
}

impl Input {
    /// The content at `path`: an image sequence when its name has a frame number pattern
    /// (played at `rate`, default 30 frames a second), else a movie, probed.
    pub fn open(path: &Path, rate: Option<Rate>) -> Result<Input> {
        Self::open_within(path, rate, None)
    }

    /// [`Input::open`], a sequence's every frame checked to lie inside `root` before any is
    /// read (see [`Sequence::find_within`]).
    pub fn open_within(path: &Path, rate: Option<Rate>, root: Option<&Path>) -> Result<Input> {
        if Sequence::is_pattern(path) {
            let rate = rate.unwrap_or(Rate { num: 30, den: 1 });
            return Ok(Input::Sequence(Sequence::find_within(path, root)?, rate));
        }
        if rate.is_some() {
            return Err(Error::invalid(
                "frame-rate",
                "a movie plays at its own rate; the rate is for image sequences",
            ));
        }
        let info = Info::probe(path)?;
        Ok(Input::Movie {
            path: path.to_path_buf(),
            info,
        })
    }

    /// Frame size, pixels.
    pub fn size(&self) -> (usize, usize) {
        match self {
            Input::Movie { info, .. } => info.size,
            Input::Sequence(s, _) => s.size,
        }
    }

    /// Frame rate.
    pub fn rate(&self) -> Rate {
        match self {
            Input::Movie { info, .. } => info.rate,
            Input::Sequence(_, r) => *r,
        }
    }

    /// The number of frames, when known before decoding.
    pub fn frames(&self) -> Option<u64> {
        match self {
            Input::Movie { info, .. } => info.frames,
            Input::Sequence(s, _) => Some(s.files.len() as u64),
        }
    }

    /// Whether frames carry more than 8 bits, so the warp runs in float.
    pub fn deep(&self) -> bool {
        match self {
            Input::Movie { info, .. } => info.deep(),
            Input::Sequence(s, _) => s.deep,
        }
    }

    /// The movie's description, if this is a movie.
    pub fn info(&self) -> Option<&Info> {
        match self {
            Input::Movie { info, .. } => Some(info),
            Input::Sequence(..) => None,
        }
    }

    /// Starts decoding: frames arrive in order from a thread of their own.
    pub fn decode(&self) -> Result<Frames> {
        let (tx, rx) = sync_channel::<Result<Frame>>(2);
        match self {
            Input::Sequence(s, _) => {
                let s = s.clone();
                let thread = std::thread::spawn(move || {
                    for path in &s.files {
                        let frame = read_frame(path, s.size, s.deep);
                        let failed = frame.is_err();
                        if tx.send(frame).is_err() || failed {
                            return;
                        }
                    }
                });
                Ok(Frames {
                    rx,
                    thread: Some(thread),
                    back: None,
                })
            }
            Input::Movie { path, info } => {
                let (pix_fmt, len) = pipe_format(info);
                let mut child = super::command("ffmpeg")
                    .args(["-hide_banner", "-nostdin", "-loglevel", "error", "-xerror"])
                    // Frames as stored: the probed size holds (a rotation tag would turn them).
                    .arg("-noautorotate")
                    .arg("-i")
                    .arg(path)
                    .args(["-map", &format!("0:{}", info.stream)])
                    .args(["-f", "rawvideo", "-pix_fmt", pix_fmt, "pipe:1"])
                    .stdin(Stdio::null())
                    .stdout(Stdio::piped())
                    .stderr(Stdio::piped())
                    .spawn()
                    .map_err(|e| super::not_started("ffmpeg", e))?;
                let mut stdout = child.stdout.take().expect("piped");
                let stderr = drain(child.stderr.take().expect("piped"));
                let (path, info) = (path.clone(), info.clone());
                let (back, spare) = sync_channel::<Vec<u8>>(3);
                let thread = std::thread::spawn(move || {
                    let mut child = Reaped(child);
                    let mut count = 0u64;
                    loop {
                        let mut buf = spare
                            .try_recv()
                            .ok()
                            .filter(|b| b.len() == len)
                            .unwrap_or_else(|| vec![0u8; len]);
                        match read_full(&mut stdout, &mut buf) {
                            Ok(n) if n == len => {
                                count += 1;
                                if tx.send(Ok(movie_frame(buf, pix_fmt, &info))).is_err() {
                                    return;
                                }
                            }
                            Ok(0) => break,
                            Ok(n) => {
                                let _ = tx.send(Err(Error::file(
                                    &path,
                                    format!(
                                        "frame {} ends after {n} of its {len} bytes",
                                        count + 1
                                    ),
                                )));
                                return;
                            }
                            Err(e) => {
                                let _ = tx.send(Err(Error::file(&path, e)));
                                return;
                            }
                        }
                    }
                    let errors = stderr.join().unwrap_or_default();
                    let ok = child.0.wait().is_ok_and(|s| s.success());
                    // A frame count from the duration may be one over.
                    let short = info.frames.filter(|&n| count + 1 < n);
                    if !ok || short.is_some() || count == 0 {
                        let why = match short {
                            Some(n) => format!("it ends after {count} of its {n} frames"),
                            None if count == 0 => "it gave no frame".to_string(),
                            None => "ffmpeg could not decode it".to_string(),
                        };
                        let detail = super::tail(&errors);
                        let sep = if detail.is_empty() { "" } else { ": " };
                        let _ = tx.send(Err(Error::file(&path, format!("{why}{sep}{detail}"))));
                    }
                });
                Ok(Frames {
                    rx,
                    thread: Some(thread),
                    back: Some(back),
                })
            }
        }
    }
}

/// How a movie's frames cross the pipe, and the bytes of one: 4:2:0 as stored, else RGBA,
/// 16-bit RGBA for deep sources.
fn pipe_format(info: &Info) -> (&'static str, usize) {
    let (w, h) = info.size;
    if info.deep() {
        ("rgba64le", w * h * 8)
    } else if info.pix_fmt == "yuvj420p" {
        // Asked for as itself: asked for as yuv420p, some ffmpeg versions squeeze it to the
        // limited range, and the matrix (full range, from the name) would no longer hold.
        ("yuvj420p", yuv::frame_len(w, h))
    } else if info.pix_fmt == "yuv420p" {
        ("yuv420p", yuv::frame_len(w, h))
    } else {
        ("rgba", w * h * 4)
    }
}

fn movie_frame(buf: Vec<u8>, pix_fmt: &str, info: &Info) -> Frame {
    let (w, h) = info.size;
    match pix_fmt {
        "yuv420p" | "yuvj420p" => Frame::Yuv420(buf),
        "rgba" => Frame::Rgba8(Raster {
            width: w,
            height: h,
            data: buf
                .chunks_exact(4)
                .map(|p| [p[0], p[1], p[2], p[3]])
                .collect(),
        }),
        _ => Frame::RgbaF32(Raster {
            width: w,
            height: h,
            data: buf
                .chunks_exact(8)
                .map(|p| {
                    let c = |k: usize| f32::from(u16::from_le_bytes([p[k], p[k + 1]])) / 65535.0;
                    [c(0), c(2), c(4), c(6)]
                })
                .collect(),
        }),
    }
}

fn read_frame(path: &Path, size: (usize, usize), deep: bool) -> Result<Frame> {
    let frame = match image_io::read_image(path)? {
        Loaded::U8(r) if !deep => Frame::Rgba8(r),
        Loaded::F32(r) if deep => Frame::RgbaF32(r),
        _ => {
            return Err(Error::file(
                path,
                "its depth differs from the first frame's (8-bit and deeper files mixed)",
            ));
        }
    };
    let got = match &frame {
        Frame::Rgba8(r) => (r.width, r.height),
        Frame::RgbaF32(r) => (r.width, r.height),
        Frame::Yuv420(_) => unreachable!("sequences are read as RGBA"),
    };
    if got != size {
        return Err(Error::file(
            path,
            format!(
                "it is {}×{} pixels where the first frame is {}×{}",
                got.0, got.1, size.0, size.1
            ),
        ));
    }
    Ok(frame)
}

/// Reads until `buf` is full or the stream ends; the bytes read.
fn read_full(r: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match r.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(n)
}

/// Reads a child's standard error to the end on a thread, so a chatty child never blocks.
pub(super) fn drain(mut stderr: impl Read + Send + 'static) -> JoinHandle<Vec<u8>> {
    std::thread::spawn(move || {
        let mut all = Vec::new();
        let _ = stderr.read_to_end(&mut all);
        all
    })
}

/// A child process that is stopped and waited for when dropped, however its thread ends.
pub(super) struct Reaped(pub Child);

impl Drop for Reaped {
    fn drop(&mut self) {
        if matches!(self.0.try_wait(), Ok(None)) {
            let _ = self.0.kill();
        }
        let _ = self.0.wait();
    }
}

/// Decoded frames in order; dropping it stops the decoder.
pub struct Frames {
    rx: Receiver<Result<Frame>>,
    thread: Option<JoinHandle<()>>,
    /// Hands a used frame's bytes back to the decoder (a 4K frame is 11 MB).
    back: Option<SyncSender<Vec<u8>>>,
}

impl Frames {
    /// Gives a frame that has been laid into the atlas back, for its bytes to be reused.
    pub fn recycle(&self, frame: Frame) {
        if let (Some(back), Frame::Yuv420(b)) = (&self.back, frame) {
            let _ = back.try_send(b);
        }
    }
}

impl Iterator for Frames {
    type Item = Result<Frame>;

    fn next(&mut self) -> Option<Result<Frame>> {
        self.rx.recv().ok()
    }
}

impl Drop for Frames {
    fn drop(&mut self) {
        // A decoder waiting to send finds its receiver gone and ends, stopping its child.
        let (_, dead) = sync_channel(0);
        drop(std::mem::replace(&mut self.rx, dead));
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `%03d` takes three digits only; `%d` takes unpadded numbers only, as printf writes them;
    /// a gap is named.
    #[test]
    fn patterns_match_the_names_printf_writes() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let img = Raster::from_fn(4, 2, |x, _| [x as u8, 0, 0, 255]);
        for name in [
            "f-1.png",
            "f-2.png",
            "f-0003.png",
            "g-001.png",
            "g-002.png",
            "g-4.png",
        ] {
            image_io::write_png(&d.join(name), &img).unwrap();
        }
        let s = Sequence::find(&d.join("f-%d.png")).unwrap();
        assert_eq!((s.first, s.files.len(), s.size), (1, 2, (4, 2)));
        let s = Sequence::find(&d.join("g-%03d.png")).unwrap();
        assert_eq!((s.first, s.files.len()), (1, 2));
        image_io::write_png(&d.join("g-004.png"), &img).unwrap();
        let e = Sequence::find(&d.join("g-%03d.png"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("g-003.png"), "{e}");
        assert!(Sequence::is_pattern(Path::new("a/f-%05d.exr")));
        assert!(!Sequence::is_pattern(Path::new("f-%5d.png")));
    }
}
