//! `omniwarp serve`: the daemon.

use anyhow::{Context, Result, bail};
use clap::Args;
use omniwarp::rig::RigDoc;
use omniwarp::server::{AppState, Store, launch};
use std::net::SocketAddr;
use std::path::PathBuf;

#[derive(Args)]
pub struct ServeArgs {
    /// Where the rig is kept (rig.json, written atomically). Without it nothing is persisted.
    #[arg(long)]
    data: Option<PathBuf>,
    /// Address and port to listen on. Anything but loopback needs --token-file.
    #[arg(long, default_value = "127.0.0.1:7878")]
    bind: SocketAddr,
    /// Start with the built-in demo rig (270° cylinder, 3 projectors) when the data directory
    /// holds none.
    #[arg(long)]
    demo: bool,
    /// File holding the bearer token every request must carry (Authorization: Bearer …).
    #[arg(long)]
    token_file: Option<PathBuf>,
}

pub fn run(a: ServeArgs) -> Result<()> {
    // Logs on stderr; stdout carries only the "listening on" line scripts read.
    // Colour codes only for a person at a terminal, not in a log file.
    use std::io::IsTerminal;
    tracing_subscriber::fmt()
        .with_target(false)
        .with_ansi(std::io::stderr().is_terminal())
        .with_writer(std::io::stderr)
        .init();
    let token = match &a.token_file {
        Some(p) => {
            let t = std::fs::read_to_string(p)
                .with_context(|| format!("--token-file {}", p.display()))?
                .trim()
                .to_string();
            if t.len() < 16 {
                bail!("--token-file: the token must be at least 16 characters");
            }
            Some(t)
        }
        None => None,
    };
    if !a.bind.ip().is_loopback() && token.is_none() {
        bail!(
            "--bind: {} is reachable from other machines; give --token-file to require a token",
            a.bind
        );
    }
    let initial = if a.demo {
        Some(
            serde_json::from_str::<RigDoc>(omniwarp::rig::DEMO_RIG)
                .context("the built-in demo rig")?,
        )
    } else {
        None
    };
    let store = Store::open(a.data.clone(), initial).map_err(|e| anyhow::anyhow!("--data: {e}"))?;
    let state = AppState::new(store, token);
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()?;
    rt.block_on(async move {
        let listener = tokio::net::TcpListener::bind(a.bind)
            .await
            .with_context(|| format!("--bind {}", a.bind))?;
        let addr = listener.local_addr()?;
        tracing::info!(%addr, "omniwarp serving /v1");
        // On stdout too, so scripts and tests that bind port 0 learn the port.
        outln!("listening on http://{addr}");
        std::io::Write::flush(&mut std::io::stdout())?;
        launch(listener, state, shutdown_signal()).await?;
        tracing::info!("stopped");
        Ok(())
    })
}

/// SIGINT or SIGTERM.
async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let term = async {
        if let Ok(mut s) = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
        {
            s.recv().await;
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => {},
        _ = term => {},
    }
}
