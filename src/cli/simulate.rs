//! `omniwarp simulate`: the virtual bench's captures written as a folder, as a real camera's
//! would be: a rehearsal of a capture, and input `omniwarp calibrate --captures` reads.

use super::args::{BenchConditions, named};
use anyhow::Result;
use clap::Args;
use omniwarp::image_io::{Precision, atomic_write, create_dir_durably, write_exr_rgba};
use omniwarp::raster::Raster;
use omniwarp::structured::read_images;
use omniwarp::structured::simulator::Simulator;
use std::io::Write;
use std::path::PathBuf;

#[derive(Args)]
pub struct SimulateArgs {
    #[command(flatten)]
    conditions: BenchConditions,
    /// The folder to write: the captures (000.png …, in the sequence's order), the camera
    /// (camera.json) and the truth (truth.exr: R, G the projector coordinate each camera
    /// pixel's centre sees, A = 1 where the projector lights it).
    #[arg(long)]
    out: PathBuf,
    /// Film these projector images instead of the sequence (every PNG or JPEG of the folder in
    /// name order, each of the projector's size): another structured-light code through the
    /// same bench, as `calibration/bench/opencv_graycode.py` does with OpenCV's.
    #[arg(long, value_name = "DIR")]
    patterns: Option<PathBuf>,
}

pub fn run(a: SimulateArgs) -> Result<()> {
    let (rig, projector, camera, opts) = a.conditions.setup()?;
    let bench = Simulator::new(&rig, &projector, &camera, opts)
        .map_err(|e| anyhow::anyhow!("{}", named(e)))?;
    create_dir_durably(&a.out)?;
    let write = |name: String, bytes: &[u8]| -> Result<()> {
        let path = a.out.join(name);
        atomic_write(&path, |f| {
            f.write_all(bytes)
                .map_err(|e| omniwarp::Error::file(&path, e))
        })?;
        Ok(())
    };
    let frames = match &a.patterns {
        None => {
            for n in 0..bench.patterns().len() {
                write(format!("{n:03}.png"), &bench.capture(n)?.png()?)?;
            }
            bench.patterns().len()
        }
        Some(dir) => {
            let images =
                read_images(dir, "patterns").map_err(|e| anyhow::anyhow!("{}", named(e)))?;
            for (n, image) in images.iter().enumerate() {
                if [image.width, image.height] != [projector.width, projector.height] {
                    anyhow::bail!(
                        "--patterns: image {n} in name order is {}×{}, `{}` shows {}×{}",
                        image.width,
                        image.height,
                        projector.id,
                        projector.width,
                        projector.height
                    );
                }
                let capture = bench.capture_image(image, n as u64)?;
                write(format!("{n:03}.png"), &capture.png()?)?;
            }
            images.len()
        }
    };
    write(
        "camera.json".into(),
        serde_json::to_string_pretty(&camera.doc())?.as_bytes(),
    )?;
    let truth = Raster::from_fn(
        camera.width as usize,
        camera.height as usize,
        |x, y| match bench.truth(x as u32, y as u32) {
            Some(q) => [q[0] as f32, q[1] as f32, 0.0, 1.0],
            None => [0.0; 4],
        },
    );
    write_exr_rgba(&a.out.join("truth.exr"), &truth, &[], Precision::Float)?;
    outln!(
        "{frames} captures of `{}` by a {}×{} {} camera in {}",
        projector.id,
        camera.width,
        camera.height,
        camera.lens.model(),
        a.out.display()
    );
    Ok(())
}
