//! The node without windows (`play --headless --out DIR`): every picture an output would show
//! is drawn through the same GPU pass off screen, read back and written to `DIR/<channel>.png`
//! (atomically, so a reader never sees half a frame), for tests and for recording what a wall
//! showed. Without any adapter the pictures are written as they came, which is what the pass
//! (`shaders/show.wgsl`) would have put out: it copies pixels unchanged (tested).

use super::{Output, State, Status, Stop, Update, overlay, overlay_lines, stopping};
use crate::error::{Error, Result};
use crate::gpu::Gpu;
use crate::gpu::show::ShowPass;
use crate::image_io::write_png;
use std::path::Path;
use std::sync::Arc;
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

/// How the headless node runs.
pub struct Options<'a> {
    /// Stop once every output has been written once.
    pub once: bool,
    /// Draw the operator's overlay into the pictures.
    pub overlay: bool,
    /// The GPU adapter to use, by a part of its name or backend.
    pub adapter: Option<&'a str>,
}

/// Writes each output's pictures as they arrive on `updates` until `stop` is set, the senders
/// are gone, or — with `once` — every output has been written once.
pub fn run(
    outputs: &[Output],
    dir: &Path,
    updates: Receiver<Update>,
    status: Arc<Status>,
    stop: Stop,
    options: Options,
) -> Result<()> {
    let Options {
        once,
        overlay: overlaid,
        adapter,
    } = options;
    let mut seen = std::collections::HashSet::new();
    for o in outputs {
        if !seen.insert(&o.channel) {
            return Err(Error::invalid(
                "output",
                format!(
                    "`{}` twice: headless outputs are files named after their channel",
                    o.channel
                ),
            ));
        }
    }
    crate::image_io::create_dir_durably(dir)?;
    let gpu = Gpu::new(adapter)?;
    let mut pass = gpu.as_ref().map(ShowPass::new);
    match &gpu {
        Some(g) => eprintln!("drawing through {}", g.describe()),
        None => eprintln!("no GPU adapter: writing the pictures as the pass would show them"),
    }
    let mut shown = vec![false; outputs.len()];
    let mut rate = super::Rate::default();
    loop {
        if stopping(&stop) || (once && shown.iter().all(|s| *s)) {
            return Ok(());
        }
        let update = match updates.recv_timeout(Duration::from_millis(100)) {
            Ok(u) => u,
            Err(RecvTimeoutError::Timeout) => continue,
            Err(RecvTimeoutError::Disconnected) => return Ok(()),
        };
        let p = match update {
            Update::Picture(p) => p,
            Update::Error(e) => {
                eprintln!("{e}");
                status.update(true, |s: &mut State| s.error = Some(e));
                continue;
            }
        };
        let Some(output) = outputs.get(p.output) else {
            continue;
        };
        let image = match overlaid {
            true => {
                let mut state = status.get();
                state.outputs[p.output].1 = Some(p.tag.clone());
                let lines = overlay_lines(&state, p.output);
                overlay(&p.image, &output.channel, &lines)
            }
            false => p.image,
        };
        let drawn = match (&gpu, &mut pass) {
            (Some(g), Some(pass)) => {
                let size = (image.width as u32, image.height as u32);
                pass.upload(g, &image)
                    .and_then(|picture| pass.render(g, &picture, false, size))
            }
            _ => Ok(image),
        };
        // A picture this adapter cannot take replaces nothing; the node goes on.
        let image = match drawn {
            Ok(image) => image,
            Err(e) => {
                let e = format!("{}: {e}; the picture shown stays", output.channel);
                eprintln!("{e}");
                status.update(true, |s| s.error = Some(e));
                continue;
            }
        };
        write_png(&dir.join(format!("{}.png", output.channel)), &image)?;
        shown[p.output] = true;
        let fps = rate.tick(Instant::now());
        status.update(true, |s| {
            let o = &mut s.outputs[p.output];
            o.1 = Some(p.tag.clone());
            o.2 += 1;
            s.fps = fps;
        });
        println!("showing {} {}", output.channel, p.tag);
    }
}
