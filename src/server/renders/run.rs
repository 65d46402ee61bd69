//! A render job's own work, on the blocking pool: the blend masks, then the frame loop over
//! every channel, progress into the record, and the files made.

use super::{Blend, Channel, Entry, File, Work, announce};
use crate::media::{Input, OutputSpec, Progress, Sample, Target};
use crate::render::{Filter, Plan, Warp};
use crate::rig::Canvas;
use std::path::Path;
use std::sync::atomic::AtomicBool;

/// The job itself, on the blocking pool: the content decoded once, warped and blended for
/// every channel, each output encoded; the files it made.
pub(super) fn run(
    s: &crate::server::AppState,
    entry: &Entry,
    dir: &Path,
    work: Work,
    blend: Blend,
) -> crate::Result<Vec<File>> {
    std::fs::create_dir_all(dir).map_err(|e| crate::Error::file(dir, e))?;
    let ext = entry.record().container.clone();
    let name = |id: &str| format!("{id}.{ext}");
    let mut blends = Vec::new();
    let mut outputs = Vec::new();
    for c in &work.channels {
        let computed = &c.computed;
        let gains = crate::rig::signal_gains(&computed.geometry.weights, 2.2)?;
        let gains = match blend {
            Blend::Baked => Some(gains),
            Blend::Separate => {
                let mask =
                    crate::rig::gains_image(computed.map.width(), computed.map.height(), &gains);
                let file = format!("{}-blend.png", c.id);
                crate::image_io::write_png(&dir.join(&file), &mask)?;
                blends.push((file, c.id.clone()));
                None
            }
            Blend::None => None,
        };
        outputs.push((c, gains));
    }
    let mut last = std::time::Instant::now();
    let progress = |p: Progress| {
        let fps = p.frame as f64 / p.elapsed.as_secs_f64().max(1e-9);
        let mut r = entry.record();
        r.frame = p.frame;
        r.fps = Some((fps * 100.0).round() / 100.0);
        r.eta_seconds = p
            .frames
            .map(|n| (n.saturating_sub(p.frame) as f64 / fps.max(1e-9)).round());
        // The feed hears of progress twice a second, not every frame.
        if last.elapsed().as_millis() >= 500 {
            last = std::time::Instant::now();
            let snapshot = r.clone();
            drop(r);
            announce(s, &snapshot);
        }
    };
    let specs: Vec<OutputSpec> = work
        .channels
        .iter()
        .map(|c| OutputSpec {
            path: dir.join(name(&c.id)),
            encoding: work.encoding.clone(),
        })
        .collect();
    let canvas = work.canvas.clone();
    let filter = work.filter;
    let stop = &entry.stop;
    if work.input.deep() {
        go::<[f32; 4]>(&work.input, &canvas, outputs, specs, filter, progress, stop)?;
    } else {
        go::<[u8; 4]>(&work.input, &canvas, outputs, specs, filter, progress, stop)?;
    }
    let mut files = Vec::new();
    for c in &work.channels {
        let file = name(&c.id);
        files.push((file, c.id.clone()));
    }
    files.extend(blends);
    files
        .into_iter()
        .map(|(name, channel)| {
            let path = dir.join(&name);
            let bytes = std::fs::metadata(&path)
                .map_err(|e| crate::Error::file(&path, e))?
                .len();
            Ok(File {
                name,
                channel,
                bytes,
            })
        })
        .collect()
}

fn go<T: Sample>(
    input: &Input,
    canvas: &Canvas,
    outputs: Vec<(&Channel, Option<Vec<f32>>)>,
    specs: Vec<OutputSpec>,
    filter: Filter,
    progress: impl FnMut(Progress),
    stop: &AtomicBool,
) -> crate::Result<crate::media::Summary> {
    let setup = |first: &crate::raster::Raster<T>| {
        let content = canvas.content(first)?;
        let mut targets = Vec::new();
        for ((c, gains), out) in outputs.into_iter().zip(specs) {
            let map = &c.computed.map;
            let size = (map.width() as u32, map.height() as u32);
            let plan = Plan::new(
                Warp::Map(map),
                &content,
                content.atlas(),
                size.0,
                size.1,
                1,
                filter,
            )?;
            targets.push(Target {
                plan,
                size,
                gains,
                saturation: c.computed.f.clone(),
                out,
            });
        }
        Ok((content, targets))
    };
    crate::media::transcode(input, setup, progress, stop)
}
