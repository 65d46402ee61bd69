//! The render node (`omniwarp play`): each projector's warped, blended picture put on its
//! output — a borderless window on a monitor, a window rectangle, or (headless) a file — and
//! kept current as the daemon's rig, tile screens and shows change.
//!
//! Pictures are made on the CPU, by the renderer that is the accuracy reference (on the
//! software adapters of machines without a GPU it is also the fast path: the daemon's warm
//! 1080p preview takes 32 ms there against 224–273 ms through the GPU warp), and the GPU only
//! uploads and presents them ([`crate::gpu::show`]), so every output shows the CPU renderer's
//! frame bit for bit. Where they come from is the caller's: pictures made once from a rig file,
//! or [`follow`]ing a daemon, which fetches each channel's `output.png` — its content, a test
//! card or a structured-light frame, as the daemon's `show` says — whenever the change feed
//! says it changed, and reports what is on screen. A picture that fails to arrive or to decode
//! never replaces the one shown: the wall stays lit while the daemon restarts.
//!
//! [`windows`] drives real outputs (winit and a wgpu surface per window); [`headless`] draws
//! the same frames off screen and writes them as files, for tests and for recording.

pub mod follow;
pub mod headless;
pub mod windows;

use crate::error::{Error, Result};
use crate::raster::Raster;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex};

/// Where an output goes.
#[derive(Debug, Clone, PartialEq)]
pub enum Place {
    /// A borderless fullscreen window on the monitor of this name.
    Monitor(String),
    /// A borderless window at `x, y`, `w × h` pixels (for testing, and windowed use).
    Window {
        /// Left edge, pixels.
        x: i32,
        /// Top edge, pixels.
        y: i32,
        /// Width, pixels.
        w: u32,
        /// Height, pixels.
        h: u32,
    },
}

/// One output of the node: a rig channel and where its picture goes.
#[derive(Debug, Clone, PartialEq)]
pub struct Output {
    /// The rig channel it shows.
    pub channel: String,
    /// Where (unused headless, where each output is a file named after its channel).
    pub place: Option<Place>,
}

impl Output {
    /// Parses `CHANNEL`, `CHANNEL=MONITOR` or `CHANNEL=X,Y,W,H`; errors name `--output`.
    pub fn parse(spec: &str) -> Result<Output> {
        let bad = |why: String| Error::invalid("output", format!("`{spec}`: {why}"));
        let (channel, place) = match spec.split_once('=') {
            None => (spec, None),
            Some((c, p)) => (c, Some(p)),
        };
        let plain = |c: char| c.is_ascii_alphanumeric() || "-_.".contains(c);
        if channel.is_empty() || channel.len() > 64 || !channel.chars().all(plain) {
            return Err(bad(
                "starts with a channel id (1–64 letters, digits, '-', '_' or '.'), then \
                 =MONITOR or =X,Y,W,H"
                    .into(),
            ));
        }
        let place = match place {
            None => None,
            Some("") => return Err(bad("an empty place after `=`".into())),
            Some(p) if p.contains(',') => {
                let parts: Vec<&str> = p.split(',').collect();
                let n = |s: &str| s.trim().parse::<i64>().ok();
                let nums: Vec<i64> = parts.iter().filter_map(|s| n(s)).collect();
                if parts.len() != 4 || nums.len() != 4 {
                    return Err(bad("a window is four integers X,Y,W,H".into()));
                }
                let side = |v: i64| (1..=i64::from(crate::limits::CHANNEL_SIDE)).contains(&v);
                let at = |v: i64| (-65536..=65536).contains(&v);
                if !side(nums[2]) || !side(nums[3]) || !at(nums[0]) || !at(nums[1]) {
                    return Err(bad(format!(
                        "a window is 1–{} pixels each way, at ±65536",
                        crate::limits::CHANNEL_SIDE
                    )));
                }
                Some(Place::Window {
                    x: nums[0] as i32,
                    y: nums[1] as i32,
                    w: nums[2] as u32,
                    h: nums[3] as u32,
                })
            }
            Some(m) => Some(Place::Monitor(m.to_string())),
        };
        Ok(Output {
            channel: channel.to_string(),
            place,
        })
    }
}

/// A picture for one output, with the tag that names it (the daemon's ETag, or a name).
pub struct Picture {
    /// Which output, by its index in the node's list.
    pub output: usize,
    /// The picture, at the channel's resolution.
    pub image: Raster<[u8; 4]>,
    /// What it is, as reported back.
    pub tag: String,
}

/// What the node tells the presenting loop.
pub enum Update {
    /// A new picture for an output.
    Picture(Picture),
    /// Something went wrong getting pictures; the ones shown stay.
    Error(String),
}

/// Somewhere to send updates: the window loop's proxy, or the headless loop's channel.
pub trait Deliver: Send + 'static {
    /// Sends `u`; false once the loop has gone.
    fn deliver(&self, u: Update) -> bool;
}

impl Deliver for std::sync::mpsc::Sender<Update> {
    fn deliver(&self, u: Update) -> bool {
        self.send(u).is_ok()
    }
}

/// What is on the outputs now, shared between the presenting loop and the reporter.
#[derive(Default)]
pub struct Status {
    state: Mutex<State>,
    changed: Condvar,
}

/// The state behind [`Status`].
#[derive(Default, Clone)]
pub struct State {
    /// Per output: the channel, the tag of the picture on screen and frames presented.
    pub outputs: Vec<(String, Option<String>, u64)>,
    /// Frames presented per second, lately.
    pub fps: f64,
    /// Frames late.
    pub dropped: u64,
    /// Whether the outputs are muted to black.
    pub black: bool,
    /// The last error.
    pub error: Option<String>,
    /// Bumped on every change worth reporting at once.
    pub version: u64,
}

impl Status {
    /// A status for `outputs`, nothing shown yet.
    pub fn new(outputs: &[Output]) -> Arc<Status> {
        let s = Status::default();
        s.state.lock().expect("status lock").outputs = outputs
            .iter()
            .map(|o| (o.channel.clone(), None, 0))
            .collect();
        Arc::new(s)
    }

    /// A copy of the state.
    pub fn get(&self) -> State {
        self.state.lock().expect("status lock").clone()
    }

    /// Changes the state with `f`; `urgent` wakes the reporter at once.
    pub fn update(&self, urgent: bool, f: impl FnOnce(&mut State)) {
        let mut s = self.state.lock().expect("status lock");
        f(&mut s);
        if urgent {
            s.version += 1;
            self.changed.notify_all();
        }
    }

    /// Waits until the version passes `seen` or `timeout` elapses; the state then.
    pub fn wait(&self, seen: u64, timeout: std::time::Duration) -> State {
        let s = self.state.lock().expect("status lock");
        let (s, _) = self
            .changed
            .wait_timeout_while(s, timeout, |s| s.version == seen)
            .expect("status lock");
        s.clone()
    }

    /// Wakes every waiter (at shutdown).
    pub fn wake(&self) {
        self.update(true, |_| {});
    }
}

/// Frames per second over a sliding second, and the frames late against the expected period.
#[derive(Default)]
pub struct Rate {
    times: std::collections::VecDeque<std::time::Instant>,
}

impl Rate {
    /// Counts a frame presented at `now`; the rate over the last second.
    pub fn tick(&mut self, now: std::time::Instant) -> f64 {
        self.times.push_back(now);
        while self
            .times
            .front()
            .is_some_and(|t| now.duration_since(*t).as_secs_f64() > 1.0)
        {
            self.times.pop_front();
        }
        self.times.len() as f64
    }
}

/// The operator's overlay on an output (`o` in a window, `--overlay`): the picture darkened
/// behind a box in its middle, the output's channel id large in it — which beam is which — and
/// `lines` (what it shows, its rates, the time) beneath.
pub fn overlay(img: &Raster<[u8; 4]>, channel: &str, lines: &[String]) -> Raster<[u8; 4]> {
    use crate::content::testcard::text_in;
    let (w, h) = (img.width, img.height);
    let mut out = img.clone();
    let (x0, x1, y0, y1) = (w / 8, w - w / 8, h / 4, h - h / 4);
    for y in y0..y1 {
        for p in &mut out.data[y * w + x0..y * w + x1] {
            *p = [p[0] / 4, p[1] / 4, p[2] / 4, 255];
        }
    }
    let white = [255, 255, 255, 255];
    let fit = |height: usize, chars: usize| (height / 8).min((x1 - x0) / (8 * chars + 8)).max(1);
    let big = fit(h / 6, channel.chars().count().max(1));
    text_in(&mut out, channel, w / 2, h * 2 / 5, big, white);
    let longest = lines.iter().map(|l| l.chars().count()).max().unwrap_or(1);
    let small = fit(h / 30, longest);
    for (k, line) in lines.iter().enumerate() {
        let y = h * 11 / 20 + k * small * 12;
        text_in(&mut out, line, w / 2, y, small, white);
    }
    out
}

/// The overlay's lines for output `i` as `status` has it: the picture's tag, its frames and the
/// node's rates, and the time of day (UTC), which a camera filming several walls can be lined
/// up by.
pub fn overlay_lines(state: &State, i: usize) -> Vec<String> {
    let (_, tag, frames) = &state.outputs[i];
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_millis())
        .unwrap_or(0);
    let t = secs / 1000 % 86_400;
    let clock = format!(
        "{:02}:{:02}:{:02}.{:03} UTC",
        t / 3600,
        t / 60 % 60,
        t % 60,
        secs % 1000
    );
    let mut lines = vec![
        format!("showing {}", tag.as_deref().unwrap_or("nothing yet")),
        format!(
            "{frames} frames, {:.0} fps, {} dropped",
            state.fps, state.dropped
        ),
        clock,
    ];
    if let Some(e) = &state.error {
        lines.push(e.chars().take(80).collect());
    }
    lines
}

/// Set once the node is asked to stop (SIGTERM, Ctrl-C, the window closed).
pub type Stop = Arc<AtomicBool>;

/// Whether `stop` is set.
pub fn stopping(stop: &Stop) -> bool {
    stop.load(Ordering::Relaxed)
}

/// Each output's channel, checked against the channels there are (`ids`).
pub fn check_channels(outputs: &[Output], ids: &[String]) -> Result<()> {
    if outputs.is_empty() {
        return Err(Error::invalid("output", "give at least one --output"));
    }
    if outputs.len() > crate::limits::NODE_OUTPUTS {
        return Err(Error::invalid(
            "output",
            format!(
                "at most {} outputs on one node, got {}",
                crate::limits::NODE_OUTPUTS,
                outputs.len()
            ),
        ));
    }
    for o in outputs {
        if !ids.contains(&o.channel) {
            return Err(Error::invalid(
                "output",
                format!(
                    "no channel `{}` in the rig; it has {}",
                    o.channel,
                    ids.join(", ")
                ),
            ));
        }
    }
    Ok(())
}
