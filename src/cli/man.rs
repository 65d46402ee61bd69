//! `omniwarp man`: the manual pages, generated from the command's own definition, so that the
//! pages a package installs say what `--help` says.

use anyhow::{Context, Result};
use clap::Args;
use std::path::{Path, PathBuf};

#[derive(Args)]
pub struct ManArgs {
    /// The folder to write `omniwarp.1` and a page per subcommand (`omniwarp-rig-plan.1`, …)
    /// into; made if missing.
    #[arg(long)]
    out_dir: PathBuf,
}

/// Writes the pages of `cmd` (the whole command line, as parsed) under `a.out_dir`.
pub fn run(a: ManArgs, cmd: clap::Command) -> Result<()> {
    std::fs::create_dir_all(&a.out_dir)
        .with_context(|| format!("--out-dir {}", a.out_dir.display()))?;
    let mut cmd = cmd.disable_help_subcommand(true);
    cmd.build();
    let mut written = 0;
    pages(&cmd, &a.out_dir, &mut written)?;
    outln!("wrote {written} manual pages to {}", a.out_dir.display());
    Ok(())
}

/// The page of `cmd` and of each of its subcommands but the hidden ones, each written whole or
/// not at all.
fn pages(cmd: &clap::Command, dir: &Path, written: &mut usize) -> Result<()> {
    for sub in cmd.get_subcommands().filter(|s| !s.is_hide_set()) {
        pages(sub, dir, written)?;
    }
    let man = clap_mangen::Man::new(cmd.clone());
    let mut page = Vec::new();
    man.render(&mut page)?;
    let path = dir.join(man.get_filename());
    omniwarp::image_io::atomic_write(&path, |f| {
        std::io::Write::write_all(f, &page).map_err(|e| omniwarp::Error::file(&path, e))
    })?;
    *written += 1;
    Ok(())
}
