//! `omniwarp play`: the render node. Each `--output` puts a rig channel's picture on a monitor
//! or a window; the pictures come from a daemon it follows (`--daemon`) or are made once from
//! a rig file (`--rig` with `--content` or `--show`). See `src/play/` and docs/player.md.

use crate::cli::args::{ContentArgs, flag_error};
use crate::cli::io::{AnyContent, channel, channel_blend, load_content, read_rig};
use anyhow::{Context, Result, bail};
use clap::Args;
use omniwarp::content::testcard::{self, Card, Label};
use omniwarp::play::follow::{self, Daemon};
use omniwarp::play::{self, Deliver, Output, Picture, Status, Update};
use omniwarp::render::{self, Filter, Warp};
use std::net::ToSocketAddrs;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

#[derive(Args)]
pub struct PlayArgs {
    /// An output: `CHANNEL=X,Y,W,H` (a borderless window there), `CHANNEL=MONITOR` (borderless
    /// fullscreen on that monitor) or `CHANNEL` (fullscreen on the first); repeat for each.
    #[arg(long = "output", value_parser = parse_output, required = true)]
    outputs: Vec<Output>,
    /// Follow the daemon at this address (`http://HOST:PORT`, or `https://…` with --pin): each
    /// output shows what the daemon's `show` says for its channel, and changes with it.
    #[arg(long, conflicts_with = "rig")]
    daemon: Option<String>,
    /// File holding the daemon's bearer token.
    #[arg(long, requires = "daemon")]
    token_file: Option<PathBuf>,
    /// The SHA-256 fingerprint of the daemon's certificate, as it prints it (with https).
    #[arg(long, requires = "daemon")]
    pin: Option<String>,
    /// This node's name in the daemon's list of nodes (default: the host name).
    #[arg(long, requires = "daemon")]
    node: Option<String>,
    /// Play from this rig file instead, with no daemon: each channel's warp and blend are
    /// computed here.
    #[arg(long)]
    rig: Option<PathBuf>,
    /// With --rig: what every output shows: `content` (--content through the warp, blended) or
    /// a test card (grid, crosshatch, bars, ids, edges; black and white through the blend and
    /// black lift).
    #[arg(long, default_value = "content", requires = "rig")]
    show: String,
    #[command(flatten)]
    content: ContentArgs,
    /// Projector gamma for the blend mask (with --rig).
    #[arg(long, default_value_t = 2.2)]
    gamma: f64,
    /// Draw off screen and write each output's pictures to `--out DIR/<channel>.png` instead of
    /// opening windows (with --rig: once, then exit).
    #[arg(long, requires = "out")]
    headless: bool,
    /// Where --headless writes.
    #[arg(long, requires = "headless")]
    out: Option<PathBuf>,
    /// Start with the operator's overlay on every output (the `o` key toggles it): the
    /// channel's id large, what it shows, its rates and the time.
    #[arg(long)]
    overlay: bool,
    /// Use the first GPU adapter whose name or backend contains this.
    #[arg(long)]
    adapter: Option<String>,
}

fn parse_output(s: &str) -> Result<Output, String> {
    Output::parse(s).map_err(|e| e.reason().to_string())
}

pub fn run(a: PlayArgs) -> Result<()> {
    let stop: play::Stop = Arc::new(AtomicBool::new(false));
    // SIGTERM or Ctrl-C ends the node between frames; a second one at once (exit 130).
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register_conditional_shutdown(signal, 130, stop.clone())
            .and_then(|_| signal_hook::flag::register(signal, stop.clone()))
            .context("installing a signal handler")?;
    }
    let status = Status::new(&a.outputs);
    let source = source(&a)?;
    let outputs = a.outputs.clone();
    if let Some(dir) = &a.out {
        let (tx, rx) = std::sync::mpsc::channel();
        let once = matches!(source, Source::Pictures(_));
        source.start(outputs.clone(), status.clone(), stop.clone(), tx);
        let options = play::headless::Options {
            once,
            overlay: a.overlay,
            adapter: a.adapter.as_deref(),
        };
        return play::headless::run(&outputs, dir, rx, status, stop, options).map_err(flag_error);
    }
    let (s, st) = (stop.clone(), status.clone());
    let options = play::windows::Options {
        adapter: a.adapter.clone(),
        overlay: a.overlay,
    };
    play::windows::run(outputs.clone(), status, stop, options, move |proxy| {
        source.start(outputs, st, s, proxy)
    })
    .map_err(flag_error)
}

/// Where the pictures come from.
enum Source {
    /// Made here, one per output.
    Pictures(Vec<Picture>),
    /// A daemon followed.
    Daemon(Daemon),
}

impl Source {
    fn start(self, outputs: Vec<Output>, status: Arc<Status>, stop: play::Stop, to: impl Deliver) {
        match self {
            Source::Pictures(pictures) => {
                for p in pictures {
                    to.deliver(Update::Picture(p));
                }
            }
            Source::Daemon(d) => follow::start(d, outputs, status, stop, to),
        }
    }
}

fn source(a: &PlayArgs) -> Result<Source> {
    match (&a.daemon, &a.rig) {
        (Some(url), _) => daemon(a, url).map(Source::Daemon),
        (None, Some(_)) => pictures(a).map(Source::Pictures),
        (None, None) => bail!("--daemon or --rig: say where the pictures come from"),
    }
}

fn daemon(a: &PlayArgs, url: &str) -> Result<Daemon> {
    // The channels are the daemon's to check; the count is the node's own limit.
    let most = omniwarp::limits::NODE_OUTPUTS;
    if a.outputs.len() > most {
        bail!(
            "--output: at most {most} outputs on one node, got {}",
            a.outputs.len()
        );
    }
    let (tls, rest) = match url.split_once("://") {
        Some(("http", r)) => (false, r),
        Some(("https", r)) => (true, r),
        _ => bail!("--daemon: `{url}` is not http://HOST:PORT or https://HOST:PORT"),
    };
    let host = rest.trim_end_matches('/');
    let addr = host
        .to_socket_addrs()
        .with_context(|| format!("--daemon: `{host}` is not a HOST:PORT this machine can resolve"))?
        .next()
        .with_context(|| format!("--daemon: `{host}` resolves to no address"))?;
    let pin = match (&a.pin, tls) {
        (Some(p), true) => Some(omniwarp::server::tls::parse_fingerprint(p).map_err(flag_error)?),
        (None, true) => bail!("--pin: needed with https (the fingerprint the daemon prints)"),
        (Some(_), false) => bail!("--pin: the daemon's address is http, which has no certificate"),
        (None, false) => None,
    };
    let token = match &a.token_file {
        Some(p) => Some(
            std::fs::read_to_string(p)
                .with_context(|| format!("--token-file {}", p.display()))?
                .trim()
                .to_string(),
        ),
        None => None,
    };
    let node = match &a.node {
        Some(n) => n.clone(),
        None => std::fs::read_to_string("/proc/sys/kernel/hostname")
            .map(|h| h.trim().to_string())
            .unwrap_or_default(),
    };
    let plain = |c: char| c.is_ascii_alphanumeric() || "._-".contains(c);
    if node.is_empty() || node.len() > 64 || !node.chars().all(plain) {
        bail!("--node: `{node}` must be 1–64 letters, digits, '.', '_' or '-'");
    }
    Ok(Daemon {
        addr,
        token,
        pin,
        node,
    })
}

/// What a rig file's outputs show.
enum What {
    Card(Card),
    Content(Box<omniwarp::content::Content<[u8; 4]>>),
}

/// Each output's picture from the rig file: its content through its warp and blend, or a card.
fn pictures(a: &PlayArgs) -> Result<Vec<Picture>> {
    let path = a.rig.as_ref().expect("checked by source");
    let rig = read_rig(path)?;
    let ids: Vec<String> = rig.channels.iter().map(|c| c.id.clone()).collect();
    play::check_channels(&a.outputs, &ids).map_err(flag_error)?;
    let what = match a.show.as_str() {
        "content" => {
            if a.content.content.is_none() {
                bail!("--content: needed to show content (or --show a test card)");
            }
            match load_content(&a.content, false)? {
                AnyContent::U8(c) => What::Content(Box::new(c)),
                AnyContent::F32(_) => bail!("--content: the player shows 8-bit content"),
            }
        }
        other => What::Card(
            Card::parse(other)
                .map_err(|e| anyhow::anyhow!("--show: {}; or content", e.reason()))?,
        ),
    };
    let mut out = Vec::new();
    for (i, o) in a.outputs.iter().enumerate() {
        let ch = channel(&rig, &o.channel)?;
        let index = ids.iter().position(|c| *c == o.channel).unwrap_or(0);
        let warp = rig.warp(ch);
        let blend = channel_blend(&rig, ch, &warp.points, a.gamma)?;
        let map = warp.map;
        let image = match &what {
            What::Card(card) => {
                let label = Label {
                    index,
                    id: &o.channel,
                };
                let mut img = testcard::draw(*card, &map, &label);
                if card.blended() {
                    blend.apply(&mut img).map_err(flag_error)?;
                }
                img
            }
            What::Content(c) => {
                let (w, h) = (ch.width, ch.height);
                let mut img = render::render(Warp::Map(&map), c, w, h, 1, Filter::Bilinear)
                    .map_err(flag_error)?;
                blend.apply(&mut img).map_err(flag_error)?;
                img
            }
        };
        out.push(Picture {
            output: i,
            image,
            tag: a.show.clone(),
        });
    }
    Ok(out)
}
