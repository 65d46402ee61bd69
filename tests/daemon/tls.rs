//! TLS beyond loopback: the real daemon on all interfaces serves HTTPS with a certificate it
//! made and kept, a client pinning its fingerprint edits the rig while the token never crosses
//! the socket in clear, and a client with another fingerprint or plain HTTP is refused; plain
//! HTTP beyond loopback only when asked for by name.

use omniwarp::server::client::Client;
use omniwarp::server::tls::parse_fingerprint;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};

const TOKEN: &str = "tls-test-token-0123456789";

/// Kills the daemon when the test ends, however it ends.
struct Daemon(Child);

impl Drop for Daemon {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts `serve` with `args`; returns the daemon, the URL it printed and the fingerprint line
/// (if it printed one).
fn serve(args: &[&str]) -> (Daemon, String, Option<String>) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_omniwarp"))
        .arg("serve")
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut out = BufReader::new(child.stdout.take().unwrap());
    let mut line = String::new();
    out.read_line(&mut line).unwrap();
    let url = line
        .trim()
        .strip_prefix("listening on ")
        .unwrap_or_else(|| panic!("unexpected first line {line:?}"))
        .to_string();
    let fingerprint = url.starts_with("https://").then(|| {
        let mut l = String::new();
        out.read_line(&mut l).unwrap();
        l.trim()
            .strip_prefix("certificate SHA-256 ")
            .unwrap_or_else(|| panic!("unexpected second line {l:?}"))
            .to_string()
    });
    (Daemon(child), url, fingerprint)
}

/// The loopback address of a daemon bound to all interfaces at `url`.
fn local(url: &str) -> SocketAddr {
    let port = url.rsplit(':').next().unwrap();
    format!("127.0.0.1:{port}").parse().unwrap()
}

fn token_file(dir: &Path) -> String {
    let path = dir.join("token");
    std::fs::write(&path, TOKEN).unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)).unwrap();
    path.to_str().unwrap().to_string()
}

/// A TCP relay to `to` that records every byte the client sends: what anyone on the venue's
/// network would see.
fn recording_relay(to: SocketAddr) -> (SocketAddr, Arc<Mutex<Vec<u8>>>) {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    let seen = Arc::new(Mutex::new(Vec::new()));
    let kept = seen.clone();
    std::thread::spawn(move || {
        for client in listener.incoming().flatten() {
            let Ok(server) = TcpStream::connect(to) else {
                continue;
            };
            let (mut c_read, mut s_write) =
                (client.try_clone().unwrap(), server.try_clone().unwrap());
            let (mut s_read, mut c_write) = (server, client);
            let kept = kept.clone();
            std::thread::spawn(move || {
                let mut buf = [0u8; 16384];
                while let Ok(n) = c_read.read(&mut buf) {
                    if n == 0 || s_write.write_all(&buf[..n]).is_err() {
                        break;
                    }
                    kept.lock().unwrap().extend_from_slice(&buf[..n]);
                }
                let _ = s_write.shutdown(std::net::Shutdown::Write);
            });
            std::thread::spawn(move || {
                let _ = std::io::copy(&mut s_read, &mut c_write);
                let _ = c_write.shutdown(std::net::Shutdown::Write);
            });
        }
    });
    (addr, seen)
}

fn contains(hay: &[u8], needle: &[u8]) -> bool {
    hay.windows(needle.len()).any(|w| w == needle)
}

#[test]
fn beyond_loopback_a_client_pinning_the_fingerprint_edits_the_rig_and_the_token_never_shows() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("state");
    let token = token_file(dir.path());
    let args = [
        "--bind",
        "0.0.0.0:0",
        "--demo",
        "--data",
        data.to_str().unwrap(),
        "--token-file",
        &token,
    ];
    let (daemon, url, fingerprint) = serve(&args);
    assert!(url.starts_with("https://"), "{url}");
    let fingerprint = fingerprint.unwrap();
    let pin = parse_fingerprint(&fingerprint).unwrap();
    let addr = local(&url);

    // Through a relay that records what crosses the network.
    let (relay, seen) = recording_relay(addr);
    let mut c = Client::pinned(relay, Some(TOKEN.into()), pin);
    let version = c.get("/v1/version").unwrap();
    assert_eq!(version.json()["tls_sha256"], fingerprint.as_str());
    let r = c.get("/v1/rig").unwrap();
    assert_eq!(r.status, 200);
    let mut doc = r.json()["rig"].clone();
    doc["eye"][1] = serde_json::json!(0.25);
    let tag = r.header("etag").unwrap().to_string();
    let put = c
        .send(
            "PUT",
            "/v1/rig",
            &[("If-Match", &tag)],
            doc.to_string().as_bytes(),
        )
        .unwrap();
    assert_eq!(put.status, 200, "{}", String::from_utf8_lossy(&put.body));
    assert_eq!(c.get("/v1/rig").unwrap().json()["rig"]["eye"][1], 0.25);
    drop(c);
    let wire = seen.lock().unwrap().clone();
    assert!(wire.len() > 1000, "the relay saw {} bytes", wire.len());
    for clear in [TOKEN.as_bytes(), b"Authorization", b"/v1/rig", b"If-Match"] {
        assert!(
            !contains(&wire, clear),
            "{} crossed in clear",
            String::from_utf8_lossy(clear)
        );
    }

    // Another fingerprint: refused in the handshake, before the token is sent.
    let mut other = pin;
    other[0] ^= 1;
    let before = seen.lock().unwrap().len();
    let err = Client::pinned(relay, Some(TOKEN.into()), other)
        .get("/v1/rig")
        .unwrap_err();
    assert!(err.to_string().contains("fingerprint"), "{err}");
    assert!(!contains(&seen.lock().unwrap()[before..], TOKEN.as_bytes()));
    // Plain HTTP to the TLS port gets no HTTP answer.
    assert!(
        Client::new(addr, Some(TOKEN.into()))
            .get("/v1/health")
            .is_err()
    );

    // The certificate is kept, private, and the same after a restart.
    use std::os::unix::fs::PermissionsExt;
    let key = data.join("tls/key.pem");
    let mode = std::fs::metadata(&key).unwrap().permissions().mode() & 0o777;
    assert_eq!(mode, 0o600);
    drop(daemon);
    let (_daemon, url, again) = serve(&args);
    assert_eq!(again.as_deref(), Some(fingerprint.as_str()));
    let mut c = Client::pinned(local(&url), Some(TOKEN.into()), pin);
    assert_eq!(c.get("/v1/rig").unwrap().json()["rig"]["eye"][1], 0.25);

    // A certificate the operator gives is served as given (here the one kept above, on
    // loopback with --tls).
    let other_data = dir.path().join("other");
    let cert = data.join("tls/cert.pem");
    let (_given, url, given) = serve(&[
        "--bind",
        "127.0.0.1:0",
        "--demo",
        "--data",
        other_data.to_str().unwrap(),
        "--tls-cert",
        cert.to_str().unwrap(),
        "--tls-key",
        key.to_str().unwrap(),
    ]);
    assert!(url.starts_with("https://127.0.0.1:"), "{url}");
    assert_eq!(given.as_deref(), Some(fingerprint.as_str()));
    let mut c = Client::pinned(url[8..].parse().unwrap(), None, pin);
    assert_eq!(c.get("/v1/health").unwrap().status, 200);
}

#[test]
fn plain_http_beyond_loopback_only_when_asked_for_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let token = token_file(dir.path());
    let (_daemon, url, fingerprint) = serve(&[
        "--bind",
        "0.0.0.0:0",
        "--demo",
        "--token-file",
        &token,
        "--plain-http",
    ]);
    assert!(url.starts_with("http://"), "{url}");
    assert_eq!(fingerprint, None);
    let mut c = Client::new(local(&url), Some(TOKEN.into()));
    assert_eq!(c.get("/v1/health").unwrap().status, 200);
    // Asking for both is a contradiction, refused before anything starts.
    let out = Command::new(env!("CARGO_BIN_EXE_omniwarp"))
        .args(["serve", "--demo", "--tls", "--plain-http"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--plain-http"));
}
