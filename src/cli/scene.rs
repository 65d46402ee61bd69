//! `omniwarp scene`: the procedural city as glTF, for other tools or for `render --scene`.

use anyhow::{Context, Result};
use clap::Args;
use omniwarp::scene::Scene;
use std::path::Path;

#[derive(Args)]
pub struct SceneExportArgs {
    /// The procedural city to write: small, medium or large.
    #[arg(long, default_value = "small")]
    city: String,
    /// Output: .gltf (with a .bin beside it) or .glb.
    #[arg(long)]
    out: std::path::PathBuf,
}

/// Writes a procedural city as glTF, for other tools or for `render --scene file.gltf`.
pub fn export(a: SceneExportArgs) -> Result<()> {
    let scene = Scene::load(&format!("city:{}", a.city))
        .map_err(|e| anyhow::anyhow!("--city: {}", e.reason()))?;
    let write = |path: &Path, bytes: &[u8]| {
        omniwarp::image_io::atomic_write(path, |f| {
            std::io::Write::write_all(f, bytes).map_err(|e| omniwarp::Error::file(path, e))
        })
    };
    match a.out.extension().and_then(|e| e.to_str()) {
        Some("glb") => {
            let (json, bin) = scene.to_gltf(None);
            write(&a.out, &omniwarp::scene::glb(&json, &bin))?;
        }
        Some("gltf") => {
            let bin_path = a.out.with_extension("bin");
            let name = bin_path
                .file_name()
                .and_then(|n| n.to_str())
                .context("--out: the file name is not UTF-8")?;
            let (json, bin) = scene.to_gltf(Some(name));
            write(&bin_path, &bin)?;
            write(&a.out, json.as_bytes())?;
        }
        _ => anyhow::bail!("--out: must end in .gltf or .glb"),
    }
    eprintln!(
        "city:{} ({} triangles) → {}",
        a.city,
        scene.triangles(),
        a.out.display()
    );
    Ok(())
}
