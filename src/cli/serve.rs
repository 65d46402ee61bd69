//! `omniwarp serve`: the daemon.

use anyhow::{Context, Result, bail};
use clap::Args;
use omniwarp::rig::RigDoc;
use omniwarp::server::{AppState, OpenOptions, Options, Store, launch};
use std::net::SocketAddr;
use std::path::PathBuf;

#[derive(Args)]
pub struct ServeArgs {
    /// The directory that keeps the state: omniwarp.db (SQLite: the rig, every channel's
    /// content canvas and tile screen, calibration proposals, the history of every edit),
    /// meshes/ and the warp cache warps/. Without it nothing is persisted.
    #[arg(long)]
    data: Option<PathBuf>,
    /// Address and port to listen on. Anything but loopback needs --token-file.
    #[arg(long, default_value = "127.0.0.1:7878")]
    bind: SocketAddr,
    /// Start with the built-in demo rig (270° cylinder, 3 projectors) when the data directory
    /// holds none.
    #[arg(long, conflicts_with = "rig")]
    demo: bool,
    /// Serve this rig file: imported into a data directory that holds no rig; one holding
    /// another rig is refused unless --replace-rig. Its mesh screen is read from the data
    /// directory's meshes/ or --assets, as any rig the daemon serves.
    #[arg(long, value_name = "FILE")]
    rig: Option<PathBuf>,
    /// With --rig: make the file the data directory's next rig revision when it holds another
    /// (the one before stays in the history, for undo).
    #[arg(long, requires = "rig")]
    replace_rig: bool,
    /// File holding the bearer token every request must carry (Authorization: Bearer …).
    #[arg(long)]
    token_file: Option<PathBuf>,
    /// Serve HTTPS on loopback too. Beyond loopback HTTPS is the default: with --tls-cert and
    /// --tls-key, or a self-signed certificate made on first start and kept in the data
    /// directory's tls/, its SHA-256 fingerprint printed at start for clients to pin.
    #[arg(long)]
    tls: bool,
    /// The certificate chain (PEM) to serve HTTPS with, the daemon's own certificate first.
    #[arg(long, requires = "tls_key", value_name = "FILE")]
    tls_cert: Option<PathBuf>,
    /// The private key (PEM) of --tls-cert.
    #[arg(long, requires = "tls_cert", value_name = "FILE")]
    tls_key: Option<PathBuf>,
    /// Serve plain HTTP beyond loopback: the token and every edit cross the network in clear,
    /// so anyone on it who reads one request can drive the projectors. Only on a network that is
    /// itself trusted or encrypted.
    #[arg(long, conflicts_with_all = ["tls", "tls_cert"])]
    plain_http: bool,
    /// Bytes the warps of all channels may hold at once; a rig needing more is refused
    /// (e.g. 2GiB, 512MiB, or a number of bytes).
    #[arg(long, default_value = "2GiB", value_parser = parse_bytes)]
    memory_budget: u64,
    /// A host name clients may reach the daemon by, besides localhost, loopback addresses and
    /// the bound address (checked against the Host header; repeat for more).
    #[arg(long = "allow-host", value_name = "NAME")]
    allow_hosts: Vec<String>,
    /// An origin (scheme://host[:port]) whose web pages may call the daemon, e.g. a console
    /// served elsewhere (repeat for more).
    #[arg(long = "allow-origin", value_name = "ORIGIN")]
    allow_origins: Vec<String>,
    /// Connections open at once; beyond them a few more are answered for health only (and 503
    /// otherwise), the rest closed. Change feeds may take at most half (and at most 256).
    #[arg(long, default_value_t = omniwarp::server::CONNECTIONS as u16,
          value_parser = clap::value_parser!(u16).range(16..))]
    max_connections: u16,
    /// Revisions of each document (the rig, each channel's content and tiles) the history keeps;
    /// older rows are dropped, the oldest kept becoming a full snapshot.
    #[arg(long, default_value_t = 10_000, value_parser = clap::value_parser!(u64).range(1..))]
    history_revisions: u64,
    /// Days the history keeps a row (the current revision of each document always stays).
    #[arg(long, default_value_t = 365, value_parser = clap::value_parser!(u64).range(1..=36_500))]
    history_days: u64,
    /// Bytes of history kept per document, patches and snapshots (e.g. 256MiB).
    #[arg(long, default_value = "256MiB", value_parser = parse_bytes)]
    history_size: u64,
    /// The folder render jobs (POST /v1/jobs) read movies and image sequences from; each job
    /// writes its movies into its renders/<id>/ there. Without it, jobs are refused.
    #[arg(long, value_name = "DIR")]
    media: Option<PathBuf>,
    /// A directory mesh screens may be read from, besides the data directory's meshes/.
    #[arg(long)]
    assets: Option<PathBuf>,
    /// When the database is damaged, or no revision of a document in it passes validation,
    /// keep it aside as omniwarp.db.damaged and start again (from --demo for the rig) instead
    /// of refusing to start.
    #[arg(long)]
    reset: bool,
}

/// `2GiB`, `512MiB`, `64KiB` or a plain number of bytes.
fn parse_bytes(s: &str) -> Result<u64, String> {
    let s = s.trim();
    let (digits, unit) = s
        .find(|c: char| !c.is_ascii_digit())
        .map_or((s, ""), |i| s.split_at(i));
    let shift = match unit.trim() {
        "" | "B" => 0,
        "KiB" => 10,
        "MiB" => 20,
        "GiB" => 30,
        "TiB" => 40,
        other => return Err(format!("unknown unit `{other}`; use KiB, MiB, GiB or TiB")),
    };
    let n: u64 = digits
        .parse()
        .map_err(|_| format!("`{s}` is not a size such as 2GiB"))?;
    n.checked_mul(1 << shift)
        .filter(|&b| b > 0)
        .ok_or_else(|| format!("`{s}` must be positive and below 16 EiB"))
}

/// A token other local users can read is everyone's on this machine, and a data directory
/// they can read hands them the rig and its history. The daemon creates its own files
/// private; one made by hand, or by an older version, is the operator's to change.
fn warn_if_readable_by_others(path: &std::path::Path, what: &str, fix: &str) {
    use std::os::unix::fs::PermissionsExt;
    if let Ok(m) = std::fs::metadata(path)
        && m.permissions().mode() & 0o077 != 0
    {
        tracing::warn!(
            path = %path.display(),
            mode = format!("{:o}", m.permissions().mode() & 0o777),
            "{what} can be read by other users; {fix} it"
        );
    }
}

/// The TLS identity: the given certificate and key, or the self-made one of the data
/// directory, for the names clients may reach the daemon by.
fn tls_identity(a: &ServeArgs) -> Result<omniwarp::server::tls::Tls> {
    use omniwarp::server::tls::Tls;
    if let (Some(cert), Some(key)) = (&a.tls_cert, &a.tls_key) {
        return Tls::from_pem(cert, key).map_err(|e| anyhow::anyhow!("--tls-cert/--tls-key: {e}"));
    }
    let mut names: Vec<String> = ["localhost", "127.0.0.1", "::1"].map(String::from).into();
    let bound = (!a.bind.ip().is_unspecified()).then(|| a.bind.ip().to_string());
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname").ok();
    for name in bound
        .into_iter()
        .chain(host)
        .chain(a.allow_hosts.iter().cloned())
    {
        let name = name.trim().to_string();
        if !name.is_empty() && !names.contains(&name) {
            names.push(name);
        }
    }
    if a.data.is_none() {
        tracing::warn!("no --data: the self-signed certificate lasts this run only");
    }
    Tls::self_signed(a.data.as_deref(), &names).map_err(|e| anyhow::anyhow!("--tls: {e}"))
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
            warn_if_readable_by_others(p, "the token file", "chmod 600");
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
    let import = match &a.rig {
        Some(p) => {
            let text =
                std::fs::read_to_string(p).with_context(|| format!("--rig {}", p.display()))?;
            Some(RigDoc::parse(&text).with_context(|| format!("--rig {}", p.display()))?)
        }
        None => None,
    };
    if let Some(d) = &a.data {
        warn_if_readable_by_others(d, "the data directory", "chmod 700");
    }
    let store = Store::open_with(
        a.data.clone(),
        OpenOptions {
            initial,
            import,
            replace: a.replace_rig,
            reset: a.reset,
            memory_budget: a.memory_budget,
            assets: a.assets.clone(),
            retention: omniwarp::server::Retention {
                revisions: a.history_revisions,
                max_age: std::time::Duration::from_secs(a.history_days * 86_400),
                bytes: a.history_size,
            },
        },
    )
    .map_err(|e| anyhow::anyhow!("--data: {e}"))?;
    let media = a
        .media
        .as_ref()
        .map(|m| {
            let m = m
                .canonicalize()
                .with_context(|| format!("--media {}", m.display()))?;
            if !m.is_dir() {
                bail!("--media: {} is not a folder", m.display());
            }
            // Jobs write there: a folder they cannot write to is found now, not at the end of
            // the first job.
            let renders = m.join("renders");
            if std::fs::symlink_metadata(&renders).is_ok_and(|r| !r.is_dir()) {
                bail!(
                    "--media: {} is not a folder of its own (a link?); jobs write only there",
                    renders.display()
                );
            }
            std::fs::create_dir_all(&renders)
                .and_then(|()| tempfile::tempfile_in(&renders).map(drop))
                .with_context(|| format!("--media: cannot write to {}", renders.display()))?;
            Ok(m)
        })
        .transpose()?;
    // After the store, which makes the data directory the certificate is kept in.
    let tls = if a.tls || a.tls_cert.is_some() || (!a.bind.ip().is_loopback() && !a.plain_http) {
        Some(tls_identity(&a)?)
    } else {
        None
    };
    let state = AppState::with_options(
        store,
        Options {
            token,
            memory_budget: a.memory_budget,
            allow_hosts: a.allow_hosts,
            allow_origins: a.allow_origins,
            // The history names who changed what: with a token, the token file's name.
            user: a
                .token_file
                .as_ref()
                .and_then(|p| p.file_stem())
                .map_or("local".into(), |n| n.to_string_lossy().into_owned()),
            connections: usize::from(a.max_connections),
            tls: tls.clone(),
            media,
        },
    );
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()?;
    let served = rt.block_on(async move {
        let listener = tokio::net::TcpListener::bind(a.bind)
            .await
            .with_context(|| format!("--bind {}", a.bind))?;
        let addr = listener.local_addr()?;
        tracing::info!(%addr, "omniwarp serving /v1");
        // On stdout too, so scripts and tests that bind port 0 learn the port (and, over TLS,
        // the fingerprint to pin).
        match &tls {
            None => outln!("listening on http://{addr}"),
            Some(t) => {
                tracing::info!(fingerprint = t.fingerprint(), "TLS certificate (SHA-256)");
                outln!("listening on https://{addr}");
                outln!("certificate SHA-256 {}", t.fingerprint());
            }
        }
        std::io::Write::flush(&mut std::io::stdout())?;
        // Under systemd (Type=notify) the unit is started once the port takes connections;
        // elsewhere NOTIFY_SOCKET is unset and this does nothing.
        if let Err(e) = sd_notify::notify(&[sd_notify::NotifyState::Ready]) {
            tracing::warn!(error = %e, "could not tell the service manager we are ready");
        }
        launch(listener, state, shutdown_signal()).await?;
        let _ = sd_notify::notify(&[sd_notify::NotifyState::Stopping]);
        tracing::info!("stopped");
        Ok(())
    });
    // A render job whose encoder hangs must not hold the process after it was told to stop
    // (it was asked to stop, and given the drain time, in `launch`).
    rt.shutdown_timeout(std::time::Duration::from_secs(1));
    served
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
