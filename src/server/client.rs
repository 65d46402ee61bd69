//! A small blocking HTTP/1.1 client with keep-alive, enough to drive the daemon from tests,
//! benchmarks, scripts and the render node (`omniwarp play`) without pulling in a client stack:
//! requests with a body and headers, responses with `Content-Length` (all the daemon's
//! non-streaming responses have one), and the change feed read event by event. Over
//! TLS it trusts the one certificate whose fingerprint it is given ([`Client::pinned`]).

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::sync::Arc;
use std::time::Duration;

/// A connection to a daemon at one address, kept alive between requests, sending the bearer
/// token when it has one.
pub struct Client {
    addr: SocketAddr,
    token: Option<String>,
    tls: Option<Arc<rustls::ClientConfig>>,
    conn: Option<BufReader<Box<dyn Stream>>>,
    /// The socket under `conn`, to change its timeout once TLS wraps it.
    tcp: Option<TcpStream>,
}

/// A connection, plain or TLS.
trait Stream: Read + Write + Send {}
impl<T: Read + Write + Send> Stream for T {}

/// A response, read whole.
#[derive(Debug, Clone)]
pub struct Reply {
    /// The HTTP status code.
    pub status: u16,
    /// Header names and values as received.
    pub headers: Vec<(String, String)>,
    /// The body, `Content-Length` bytes.
    pub body: Vec<u8>,
}

impl Reply {
    /// The value of header `name` (case-insensitive), if sent.
    pub fn header(&self, name: &str) -> Option<&str> {
        header(&self.headers, name)
    }

    /// The body as JSON; `Null` when it is not JSON.
    pub fn json(&self) -> serde_json::Value {
        serde_json::from_slice(&self.body).unwrap_or(serde_json::Value::Null)
    }

    /// The revision in the ETag (`"7"` → 7; `"3.7"` → 7, the part after the dot).
    pub fn revision(&self) -> Option<u64> {
        let tag = self.header("etag")?.trim_matches('"');
        tag.rsplit('.').next()?.parse().ok()
    }
}

impl Client {
    /// A client of the daemon at `addr`; `token` is sent as `Authorization: Bearer …`. It
    /// connects on the first request.
    pub fn new(addr: SocketAddr, token: Option<String>) -> Self {
        Client {
            addr,
            token,
            tls: None,
            conn: None,
            tcp: None,
        }
    }

    /// A client of a daemon serving TLS at `addr` that accepts only the certificate whose
    /// SHA-256 fingerprint is `pin` (see [`super::tls::parse_fingerprint`]); any other
    /// certificate, or a daemon speaking plain HTTP, fails the request before the token is sent.
    pub fn pinned(addr: SocketAddr, token: Option<String>, pin: [u8; 32]) -> Self {
        let provider = super::tls::provider();
        let verifier = Arc::new(super::tls::Pinned {
            pin,
            provider: provider.clone(),
        });
        let config = rustls::ClientConfig::builder_with_provider(provider)
            .with_safe_default_protocol_versions()
            .expect("the ring provider supports the default versions")
            .dangerous()
            .with_custom_certificate_verifier(verifier)
            .with_no_client_auth();
        Client {
            tls: Some(Arc::new(config)),
            ..Client::new(addr, token)
        }
    }

    /// Sends one request; reconnects once if a kept-alive connection was closed (an error on a
    /// fresh connection is the answer).
    pub fn send(
        &mut self,
        method: &str,
        path: &str,
        headers: &[(&str, &str)],
        body: &[u8],
    ) -> std::io::Result<Reply> {
        let reused = self.conn.is_some();
        match self.try_send(method, path, headers, body) {
            Ok(r) => Ok(r),
            Err(_) if reused => {
                self.conn = None;
                self.try_send(method, path, headers, body)
            }
            Err(e) => {
                self.conn = None;
                Err(e)
            }
        }
    }

    fn try_send(
        &mut self,
        method: &str,
        path: &str,
        headers: &[(&str, &str)],
        body: &[u8],
    ) -> std::io::Result<Reply> {
        let (status, headers) = self.head(method, path, headers, body)?;
        let conn = self.conn.as_mut().expect("connected by head");
        let len: usize = header(&headers, "content-length")
            .and_then(|v| v.parse().ok())
            .ok_or_else(|| bad("no Content-Length"))?;
        if len > MAX_BODY {
            return Err(bad("a body over 1 GiB"));
        }
        let mut body = vec![0; len];
        conn.read_exact(&mut body)?;
        if header(&headers, "connection").is_some_and(|v| v.eq_ignore_ascii_case("close")) {
            self.conn = None;
        }
        Ok(Reply {
            status,
            headers,
            body,
        })
    }

    /// Sends a request (connecting first if need be) and reads the status line and headers.
    fn head(
        &mut self,
        method: &str,
        path: &str,
        headers: &[(&str, &str)],
        body: &[u8],
    ) -> std::io::Result<(u16, Vec<(String, String)>)> {
        if self.conn.is_none() {
            let s = TcpStream::connect_timeout(&self.addr, Duration::from_secs(5))?;
            s.set_read_timeout(Some(Duration::from_secs(120)))?;
            s.set_nodelay(true)?;
            let tcp = s.try_clone()?;
            let stream: Box<dyn Stream> = match &self.tls {
                None => Box::new(s),
                Some(config) => {
                    // The pin names the certificate, so the name asked for matters not.
                    let name = rustls::pki_types::ServerName::IpAddress(self.addr.ip().into());
                    let conn = rustls::ClientConnection::new(config.clone(), name)
                        .map_err(std::io::Error::other)?;
                    let mut tls = rustls::StreamOwned::new(conn, s);
                    // The handshake now, so a wrong certificate fails before anything is sent.
                    while tls.conn.is_handshaking() {
                        tls.conn.complete_io(&mut tls.sock)?;
                    }
                    Box::new(tls)
                }
            };
            self.tcp = Some(tcp);
            self.conn = Some(BufReader::new(stream));
        }
        let conn = self.conn.as_mut().expect("connected above");
        let mut req = format!(
            "{method} {path} HTTP/1.1\r\nHost: {}\r\nContent-Length: {}\r\n",
            self.addr,
            body.len()
        );
        if let Some(t) = &self.token {
            req += &format!("Authorization: Bearer {t}\r\n");
        }
        for (k, v) in headers {
            req += &format!("{k}: {v}\r\n");
        }
        // The daemon takes JSON bodies only (a browser cannot send that cross-site without
        // asking first); say so unless the caller named another type.
        let typed = headers
            .iter()
            .any(|(k, _)| k.eq_ignore_ascii_case("content-type"));
        if !body.is_empty() && !typed {
            req += "Content-Type: application/json\r\n";
        }
        req += "\r\n";
        let stream = conn.get_mut();
        stream.write_all(req.as_bytes())?;
        stream.write_all(body)?;
        stream.flush()?;
        let mut line = String::new();
        if read_line(conn, &mut line, MAX_LINE)? == 0 {
            return Err(bad("connection closed"));
        }
        let status: u16 = line
            .split_whitespace()
            .nth(1)
            .and_then(|s| s.parse().ok())
            .ok_or_else(|| bad("no status line"))?;
        let mut headers = Vec::new();
        loop {
            line.clear();
            read_line(conn, &mut line, MAX_LINE)?;
            let l = line.trim_end();
            if l.is_empty() {
                break;
            }
            if headers.len() >= 100 {
                return Err(bad("over 100 headers"));
            }
            if let Some((k, v)) = l.split_once(':') {
                headers.push((k.trim().to_string(), v.trim().to_string()));
            }
        }
        Ok((status, headers))
    }

    /// `GET path` of a stream that does not end — the change feed — on a connection of its
    /// own: the status, and the body to read event by event when it is 200. Each read waits at
    /// most `patience` (the feed sends a keep-alive every 15 s, so a longer silence means the
    /// daemon is gone).
    pub fn feed(&mut self, path: &str, patience: Duration) -> std::io::Result<(u16, Feed)> {
        self.conn = None;
        let (status, headers) = self.head("GET", path, &[("Accept", "text/event-stream")], b"")?;
        let conn = self.conn.take().expect("connected by head");
        if let Some(tcp) = self.tcp.take() {
            tcp.set_read_timeout(Some(patience))?;
        }
        let chunked = header(&headers, "transfer-encoding")
            .is_some_and(|v| v.eq_ignore_ascii_case("chunked"));
        let body = Dechunk {
            conn,
            chunked,
            left: 0,
            done: false,
        };
        Ok((
            status,
            Feed {
                body: BufReader::new(body),
            },
        ))
    }

    /// `GET path`.
    pub fn get(&mut self, path: &str) -> std::io::Result<Reply> {
        self.send("GET", path, &[], b"")
    }
}

/// The longest body, status or header line, and event line the client reads: a daemon's
/// answers are far within them, and a peer that is not one cannot make it hold more.
const MAX_BODY: usize = 1 << 30;
const MAX_LINE: u64 = 64 << 10;
const MAX_EVENT: u64 = 1 << 20;

/// `read_line` of at most `max` bytes; a longer line is an error, not a growing buffer.
fn read_line(r: &mut impl BufRead, line: &mut String, max: u64) -> std::io::Result<usize> {
    let n = r.take(max).read_line(line)?;
    if n as u64 == max && !line.ends_with('\n') {
        return Err(bad("a line too long"));
    }
    Ok(n)
}

fn bad(why: &str) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::InvalidData, why.to_string())
}

fn header<'a>(headers: &'a [(String, String)], name: &str) -> Option<&'a str> {
    headers
        .iter()
        .find(|(k, _)| k.eq_ignore_ascii_case(name))
        .map(|(_, v)| v.as_str())
}

/// A response body of unknown length: HTTP/1.1 chunks decoded, or the bytes until the
/// connection closes.
struct Dechunk {
    conn: BufReader<Box<dyn Stream>>,
    chunked: bool,
    /// Bytes left in the current chunk.
    left: usize,
    done: bool,
}

impl Read for Dechunk {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        if self.done || buf.is_empty() {
            return Ok(0);
        }
        if !self.chunked {
            return self.conn.read(buf);
        }
        if self.left == 0 {
            let mut line = String::new();
            if read_line(&mut self.conn, &mut line, MAX_LINE)? == 0 {
                self.done = true;
                return Ok(0);
            }
            let size = line.trim_end().split(';').next().unwrap_or("");
            self.left =
                usize::from_str_radix(size.trim(), 16).map_err(|_| bad("bad chunk size"))?;
            if self.left == 0 {
                self.done = true;
                return Ok(0);
            }
        }
        let want = buf.len().min(self.left);
        let n = self.conn.read(&mut buf[..want])?;
        if n == 0 {
            return Err(bad("connection closed inside a chunk"));
        }
        self.left -= n;
        if self.left == 0 {
            let mut crlf = [0; 2];
            self.conn.read_exact(&mut crlf)?;
        }
        Ok(n)
    }
}

/// The change feed as it arrives ([`Client::feed`]).
pub struct Feed {
    body: BufReader<Dechunk>,
}

impl Feed {
    /// The next event's data (its `data:` lines joined); `None` when the stream ended.
    /// Comments (the keep-alives) are skipped.
    pub fn event(&mut self) -> std::io::Result<Option<String>> {
        let mut data = String::new();
        let mut line = String::new();
        loop {
            line.clear();
            if read_line(&mut self.body, &mut line, MAX_EVENT)? == 0 {
                return Ok(None);
            }
            let l = line.trim_end_matches(['\r', '\n']);
            if l.is_empty() {
                if !data.is_empty() {
                    return Ok(Some(data));
                }
                continue;
            }
            if let Some(d) = l.strip_prefix("data:") {
                if !data.is_empty() {
                    data.push('\n');
                }
                data.push_str(d.strip_prefix(' ').unwrap_or(d));
            }
            // A line this long is not the daemon's feed; stop rather than grow without end.
            if data.len() > 1 << 20 {
                return Err(bad("an event over 1 MiB"));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Client;
    use std::io::{Read, Write};
    use std::time::Duration;

    /// A server that answers the first request on its port with `answer`.
    fn answering(answer: Vec<u8>) -> std::net::SocketAddr {
        let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = listener.local_addr().unwrap();
        std::thread::spawn(move || {
            let (mut conn, _) = listener.accept().unwrap();
            let mut request = [0; 1024];
            let _ = conn.read(&mut request);
            let _ = conn.write_all(&answer);
            std::thread::sleep(Duration::from_millis(200));
        });
        addr
    }

    #[test]
    fn a_peer_that_is_not_the_daemon_cannot_make_the_client_panic_or_grow() {
        let huge = b"HTTP/1.1 200 OK\r\nContent-Length: 18446744073709551615\r\n\r\n".to_vec();
        let e = Client::new(answering(huge), None).get("/").unwrap_err();
        assert!(e.to_string().contains("over 1 GiB"), "{e}");
        let mut endless = b"HTTP/1.1 200 OK\r\nX-Long: ".to_vec();
        endless.extend(std::iter::repeat_n(b'a', 100 << 10));
        let e = Client::new(answering(endless), None).get("/").unwrap_err();
        assert!(e.to_string().contains("too long"), "{e}");
        let mut event = b"HTTP/1.1 200 OK\r\nTransfer-Encoding: chunked\r\n\r\n".to_vec();
        let line = format!("data: {}", "x".repeat(2 << 20));
        event.extend(format!("{:x}\r\n{line}\r\n", line.len()).into_bytes());
        let (status, mut feed) = Client::new(answering(event), None)
            .feed("/v1/events", Duration::from_secs(5))
            .unwrap();
        assert_eq!(status, 200);
        let e = feed.event().unwrap_err();
        assert!(e.to_string().contains("too long"), "{e}");
    }
}
