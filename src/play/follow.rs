//! Following a daemon: the change feed says when a channel's picture may have changed; the
//! node then asks for the channel's `output.png` with the ETag it shows (a 304 costs nothing),
//! decodes it on this thread and hands it to the presenting loop, which swaps it in between
//! two frames. A fetch that fails, an answer that is not a PNG (or one over 16384 pixels a
//! side), a daemon that is gone: each is reported and the picture shown stays. The feed is reopened
//! with a growing pause (a quarter second to five); it opens with a change of the rig, so every
//! output is asked for again then, and with the first change after ten quiet seconds, in case
//! a burst of changes overran the feed.
//!
//! A second thread reports to the daemon (`PUT /v1/nodes/{node}`) what each output shows,
//! at once when it changes and every second otherwise.

use super::{Deliver, Output, Picture, Status, Stop, Update, stopping};
use crate::raster::Raster;
use crate::server::client::Client;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// How to reach the daemon.
#[derive(Clone)]
pub struct Daemon {
    /// Its address.
    pub addr: SocketAddr,
    /// The bearer token, when it asks for one.
    pub token: Option<String>,
    /// The SHA-256 fingerprint of its certificate, when it serves TLS.
    pub pin: Option<[u8; 32]>,
    /// This node's id in the daemon's list.
    pub node: String,
}

impl Daemon {
    fn client(&self) -> Client {
        match self.pin {
            Some(pin) => Client::pinned(self.addr, self.token.clone(), pin),
            None => Client::new(self.addr, self.token.clone()),
        }
    }
}

/// Every so often each output is asked for again, in case an event was missed.
const REVALIDATE: Duration = Duration::from_secs(10);
/// A feed silent this long (it sends a keep-alive every 15 s) is taken for lost.
const PATIENCE: Duration = Duration::from_secs(40);

/// Starts the threads that follow `daemon` for `outputs` (sending pictures to `to`) and report
/// `status` to it; they run until `stop` is set.
pub fn start(
    daemon: Daemon,
    outputs: Vec<Output>,
    status: Arc<Status>,
    stop: Stop,
    to: impl Deliver,
) {
    let (d, st, s) = (daemon.clone(), status.clone(), stop.clone());
    std::thread::Builder::new()
        .name("report".into())
        .spawn(move || report(d, st, s))
        .expect("a thread");
    std::thread::Builder::new()
        .name("follow".into())
        .spawn(move || follow(daemon, outputs, status, stop, to))
        .expect("a thread");
}

/// Which outputs a change on the feed concerns: those of its channel, every one for a change
/// of the rig (or of a kind this node does not know), none for what changes no picture.
fn concerned(change: &str, outputs: &[Output]) -> Vec<usize> {
    let v: serde_json::Value = serde_json::from_str(change).unwrap_or_default();
    let all = (0..outputs.len()).collect();
    match v["kind"].as_str() {
        Some("node" | "job" | "proposal") => Vec::new(),
        Some("tiles" | "content" | "show") => match v["channel"].as_str() {
            Some(c) => (0..outputs.len())
                .filter(|&i| outputs[i].channel == c)
                .collect(),
            None => all,
        },
        _ => all,
    }
}

fn follow(daemon: Daemon, outputs: Vec<Output>, status: Arc<Status>, stop: Stop, to: impl Deliver) {
    let mut feed_client = daemon.client();
    let mut fetcher = daemon.client();
    let mut shown: Vec<Option<String>> = vec![None; outputs.len()];
    let mut pause = Duration::from_millis(250);
    let mut reported_down = false;
    while !stopping(&stop) {
        let error = match feed_client.feed("/v1/events", PATIENCE) {
            Ok((200, mut feed)) => {
                if reported_down {
                    eprintln!("following the daemon at {} again", daemon.addr);
                    reported_down = false;
                }
                status.update(true, |s| s.error = None);
                pause = Duration::from_millis(250);
                let mut checked = Instant::now();
                // The feed opens with a `rig` change, which fetches every output.
                loop {
                    let next = feed.event();
                    if stopping(&stop) {
                        return;
                    }
                    let wanted = match next {
                        Ok(Some(change)) => concerned(&change, &outputs),
                        Ok(None) => break "the daemon closed the change feed".to_string(),
                        Err(e) => break format!("the change feed broke off: {e}"),
                    };
                    let due = checked.elapsed() > REVALIDATE;
                    let list: Vec<usize> = if due {
                        checked = Instant::now();
                        (0..outputs.len()).collect()
                    } else {
                        wanted
                    };
                    for i in list {
                        if !fetch(&mut fetcher, &outputs, i, &mut shown, &to) {
                            return;
                        }
                    }
                }
            }
            Ok((code, _)) => format!("the daemon answered {code} for its change feed"),
            Err(e) => format!("cannot reach the daemon at {}: {e}", daemon.addr),
        };
        if !reported_down {
            reported_down = true;
            if !to.deliver(Update::Error(format!("{error}; the pictures shown stay"))) {
                return;
            }
        }
        let until = Instant::now() + pause;
        while Instant::now() < until && !stopping(&stop) {
            std::thread::sleep(Duration::from_millis(50));
        }
        pause = (pause * 2).min(Duration::from_secs(5));
    }
}

/// Asks for output `i`'s picture; sends it on when it is new and sound, an error when it is
/// not. False once the presenting loop has gone.
fn fetch(
    client: &mut Client,
    outputs: &[Output],
    i: usize,
    shown: &mut [Option<String>],
    to: &impl Deliver,
) -> bool {
    let channel = &outputs[i].channel;
    let path = format!("/v1/channels/{channel}/output.png");
    let mut headers = Vec::new();
    if let Some(tag) = &shown[i] {
        headers.push(("If-None-Match", tag.as_str()));
    }
    let got = client.send("GET", &path, &headers, b"");
    let picture = got.map_err(|e| e.to_string()).and_then(|r| match r.status {
        304 => Ok(None),
        200 => {
            let tag = r.header("etag").unwrap_or("").to_string();
            decode(&r.body).map(|img| Some((img, tag)))
        }
        code => Err(format!(
            "answered {code}: {}",
            String::from_utf8_lossy(&r.body[..r.body.len().min(200)])
        )),
    });
    match picture {
        Ok(None) => true,
        Ok(Some((image, tag))) => {
            shown[i] = Some(tag.clone());
            to.deliver(Update::Picture(Picture {
                output: i,
                image,
                tag,
            }))
        }
        Err(e) => to.deliver(Update::Error(format!(
            "{path}: {e}; the picture shown stays"
        ))),
    }
}

/// A PNG as RGBA8, refused beyond a channel's largest size.
fn decode(bytes: &[u8]) -> Result<Raster<[u8; 4]>, String> {
    let mut reader =
        image::ImageReader::with_format(std::io::Cursor::new(bytes), image::ImageFormat::Png);
    let mut limits = image::Limits::default();
    let side = crate::limits::CHANNEL_SIDE;
    limits.max_image_width = Some(side);
    limits.max_image_height = Some(side);
    // The largest picture, RGBA8, decoded once.
    limits.max_alloc = Some(u64::from(side) * u64::from(side) * 4);
    reader.limits(limits);
    let img = reader
        .decode()
        .map_err(|e| format!("not a picture ({e})"))?
        .into_rgba8();
    let (width, height) = (img.width() as usize, img.height() as usize);
    let data = img
        .as_raw()
        .chunks_exact(4)
        .map(|p| [p[0], p[1], p[2], p[3]])
        .collect();
    Ok(Raster {
        width,
        height,
        data,
    })
}

fn report(daemon: Daemon, status: Arc<Status>, stop: Stop) {
    let mut client = daemon.client();
    let path = format!("/v1/nodes/{}", daemon.node);
    let mut seen = 0;
    while !stopping(&stop) {
        let s = status.wait(seen, Duration::from_secs(1));
        seen = s.version;
        if stopping(&stop) {
            return;
        }
        let outputs: Vec<_> = s
            .outputs
            .iter()
            .map(|(channel, showing, frames)| {
                serde_json::json!({"channel": channel, "showing": showing, "frames": frames})
            })
            .collect();
        let mut body = serde_json::json!({
            "outputs": outputs,
            "fps": s.fps,
            "dropped": s.dropped,
            "black": s.black,
        });
        if let Some(e) = &s.error {
            body["error"] = e.chars().take(500).collect::<String>().into();
        }
        // A daemon that is away hears from the node when it is back; the follower says so.
        let _ = client.send("PUT", &path, &[], body.to_string().as_bytes());
    }
}
