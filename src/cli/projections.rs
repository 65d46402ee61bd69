//! `omniwarp projections`: the registry, as a user reads it.

use anyhow::Result;
use omniwarp::projection;

pub fn run() -> Result<()> {
    for e in projection::REGISTRY {
        let aliases = if e.aliases.is_empty() {
            String::new()
        } else {
            format!(" (also {})", e.aliases.join(", "))
        };
        outln!("{}{aliases}: {}", e.name, e.description);
        for (p, what) in e.params {
            outln!("    --{p:<7} {what} (degrees)");
        }
    }
    Ok(())
}
