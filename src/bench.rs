//! `omniwarp bench`: steady-state throughput of the CPU warp, and the machine's memory
//! bandwidth for comparison.

use anyhow::Result;
use clap::Args;

#[derive(Args)]
pub struct BenchArgs {}

pub fn run(_a: BenchArgs) -> Result<()> {
    anyhow::bail!("not yet")
}
