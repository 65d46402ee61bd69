//! What every request passes before a route sees it, and what every answer passes on its way
//! out.
//!
//! Loopback is not a boundary against web pages: a page the technician opens can send requests
//! to `127.0.0.1` (a cross-site form post), or rebind its own host name to `127.0.0.1` and then
//! read the answers (DNS rebinding). So a request must name this server in `Host` (loopback
//! names and addresses, the address the server is bound to, `--allow-host` names); a request a
//! browser sends from another origin carries `Origin`, which must be the daemon's own or an
//! `--allow-origin` one; a body must be declared `application/json` (a form cannot send that
//! without a CORS preflight, which only allowed origins pass). A page's `<img>` or `<script>`
//! sends no `Origin`, but a browser marks it `Sec-Fetch-Site: cross-site`; those are refused
//! too, or any page could keep the workers busy with renders and exports.
//!
//! The token is checked on the headers, before a byte of the body is read: a client without it
//! must not get the daemon to buffer a 64 MiB upload first. Bodies are then read whole, within a
//! size limit and a deadline, so a client that sends slowly holds no route.

use super::state::{AppState, MAX_BODY};
use crate::server::ApiError;
use axum::body::{Body, Bytes};
use axum::extract::{Request, State};
use axum::http::{HeaderMap, HeaderName, HeaderValue, Method, StatusCode, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use std::net::IpAddr;
use std::sync::Arc;
use std::time::Duration;
use tokio_stream::StreamExt;

/// Time a client has to send a whole request body.
pub const BODY_TIMEOUT: Duration = Duration::from_secs(30);
/// Longest request target, bytes (414 beyond).
pub const MAX_URI: usize = 8 << 10;
/// Largest header block, bytes (431 beyond).
pub const MAX_HEADERS: usize = 32 << 10;

const ALLOW_METHODS: &str = "GET, PUT, POST, PATCH, DELETE";
const ALLOW_HEADERS: &str = "authorization, content-type, if-match";
const EXPOSE_HEADERS: &str = "etag, retry-after, x-omniwarp-grid, x-omniwarp-max-error";

fn forbidden(field: &str, reason: impl Into<String>) -> ApiError {
    ApiError::refused(StatusCode::FORBIDDEN, Some(field), reason)
}

/// The host part of a `Host` value (`name`, `name:port`, `[v6]:port`), lower-cased.
fn host_name(value: &str) -> Option<String> {
    let v = value.trim();
    let name = if let Some(rest) = v.strip_prefix('[') {
        let (inside, after) = rest.split_once(']')?;
        if !(after.is_empty() || after.strip_prefix(':').is_some_and(is_port)) {
            return None;
        }
        inside
    } else {
        match v.rsplit_once(':') {
            Some((n, port)) if is_port(port) => n,
            Some(_) => return None,
            None => v,
        }
    };
    (!name.is_empty()).then(|| name.to_ascii_lowercase())
}

fn is_port(p: &str) -> bool {
    !p.is_empty() && p.len() <= 5 && p.bytes().all(|b| b.is_ascii_digit())
}

/// Whether `Host: value` names this server.
pub fn host_allowed(s: &AppState, value: &str) -> bool {
    let Some(name) = host_name(value) else {
        return false;
    };
    if name == "localhost"
        || s.options
            .allow_hosts
            .iter()
            .any(|h| h.eq_ignore_ascii_case(&name))
    {
        return true;
    }
    let Ok(ip) = name.parse::<IpAddr>() else {
        return false;
    };
    // An address literal cannot be rebound; a server bound to all interfaces (which needs a
    // token) answers to any of its addresses.
    ip.is_loopback()
        || s.bound
            .get()
            .is_some_and(|b| b.ip() == ip || b.ip().is_unspecified())
}

/// Whether a browser on `origin` may call the daemon: its own origin (the `Host` it was
/// reached by) or one named with `--allow-origin`.
fn origin_allowed(s: &AppState, origin: &str, host: Option<&str>) -> bool {
    let origin = origin.trim().trim_end_matches('/');
    if s.options
        .allow_origins
        .iter()
        .any(|o| o.trim_end_matches('/').eq_ignore_ascii_case(origin))
    {
        return true;
    }
    host.is_some_and(|h| {
        ["http://", "https://"].iter().any(|scheme| {
            origin
                .strip_prefix(scheme)
                .is_some_and(|o| o.eq_ignore_ascii_case(h))
        })
    })
}

fn header_str(h: &HeaderMap, name: header::HeaderName) -> Result<Option<&str>, ApiError> {
    h.get(&name)
        .map(|v| {
            v.to_str().map_err(|_| ApiError::Invalid {
                field: name.as_str().to_string(),
                reason: "is not visible ASCII".into(),
            })
        })
        .transpose()
}

/// Whether `content-type` is JSON (`application/json`, parameters allowed).
fn is_json(ct: Option<&str>) -> bool {
    ct.and_then(|c| c.split(';').next())
        .is_some_and(|m| m.trim().eq_ignore_ascii_case("application/json"))
}

fn is_image(ct: Option<&str>) -> bool {
    ct.and_then(|c| c.split(';').next()).is_some_and(|m| {
        let m = m.trim();
        m.eq_ignore_ascii_case("image/png") || m.eq_ignore_ascii_case("image/jpeg")
    })
}

/// Host, Origin, content type, sizes and CORS; then the body, read whole.
pub async fn guard(
    State(s): State<Arc<AppState>>,
    req: Request,
    next: Next,
) -> Result<Response, ApiError> {
    if req.uri().to_string().len() > MAX_URI {
        return Err(ApiError::refused(
            StatusCode::URI_TOO_LONG,
            Some("uri"),
            format!("the request target is above {MAX_URI} bytes"),
        ));
    }
    let header_bytes: usize = req
        .headers()
        .iter()
        .map(|(k, v)| k.as_str().len() + v.len() + 4)
        .sum();
    if header_bytes > MAX_HEADERS {
        return Err(ApiError::refused(
            StatusCode::REQUEST_HEADER_FIELDS_TOO_LARGE,
            None,
            format!("the headers hold {header_bytes} bytes, above {MAX_HEADERS}"),
        ));
    }
    let h = req.headers();
    // HTTP/1.0 clients may leave Host out; a browser always sends it.
    let host = header_str(h, header::HOST)?;
    if let Some(v) = host
        && !host_allowed(&s, v)
    {
        return Err(forbidden(
            "Host",
            format!("`{v}` does not name this server; start it with --allow-host to add a name"),
        ));
    }
    let origin = header_str(h, header::ORIGIN)?.map(str::to_string);
    if let Some(o) = &origin
        && !origin_allowed(&s, o, host)
    {
        return Err(forbidden(
            "Origin",
            format!("pages from `{o}` may not call this server (see --allow-origin)"),
        ));
    }
    // A browser's request from another site that carries no Origin (an image, a script, a
    // link's prefetch): `same-site` counts, as any port on a loopback name is the same site.
    let fetch_site = header_str(h, HeaderName::from_static("sec-fetch-site"))?;
    if origin.is_none()
        && let Some(site) = fetch_site
        && !["same-origin", "none"].contains(&site.trim())
    {
        return Err(forbidden(
            "Sec-Fetch-Site",
            format!("a page from another site ({site}) may not load from this server"),
        ));
    }
    let cors = origin.and_then(|o| HeaderValue::from_str(&o).ok());
    if req.method() == Method::OPTIONS {
        return Ok(preflight(cors));
    }
    if !authorized(&s, &req) {
        return Err(ApiError::Unauthorized);
    }
    // Mesh uploads are OBJ text of their own size, camera captures images of theirs; every
    // other body is JSON.
    let path = req.uri().path();
    let is_mesh = path.starts_with("/v1/meshes/");
    let is_capture = req.method() == Method::PUT
        && path.starts_with("/v1/channels/")
        && path.rsplit('/').nth(1) == Some("captures");
    let limit = if is_mesh {
        crate::limits::MESH_BYTES as usize
    } else if is_capture {
        crate::limits::CAPTURE_BODY as usize
    } else {
        MAX_BODY
    };
    let declared = h
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok()?.parse::<u64>().ok());
    if declared.is_some_and(|n| n > limit as u64) {
        return Err(too_large(limit));
    }
    // A body of unknown length (chunked) counts as one; an empty one does not.
    let has_body = axum::body::HttpBody::size_hint(req.body()).exact() != Some(0);
    if has_body && is_capture && !is_image(header_str(h, header::CONTENT_TYPE)?) {
        return Err(ApiError::refused(
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            Some("Content-Type"),
            "a capture must be sent as image/png or image/jpeg",
        ));
    }
    if has_body && !is_mesh && !is_capture && !is_json(header_str(h, header::CONTENT_TYPE)?) {
        return Err(ApiError::refused(
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            Some("Content-Type"),
            "a request body must be sent as application/json",
        ));
    }
    let (parts, body) = req.into_parts();
    let bytes = if has_body {
        tokio::time::timeout(BODY_TIMEOUT, read_limited(body, limit))
            .await
            .map_err(|_| {
                ApiError::refused(
                    StatusCode::REQUEST_TIMEOUT,
                    None,
                    format!(
                        "the body did not arrive within {} s",
                        BODY_TIMEOUT.as_secs()
                    ),
                )
            })??
    } else {
        Bytes::new()
    };
    let mut resp = next
        .run(Request::from_parts(parts, Body::from(bytes)))
        .await;
    if let Some(o) = cors {
        let h = resp.headers_mut();
        h.insert(header::ACCESS_CONTROL_ALLOW_ORIGIN, o);
        h.insert(
            header::ACCESS_CONTROL_EXPOSE_HEADERS,
            HeaderValue::from_static(EXPOSE_HEADERS),
        );
        h.append(header::VARY, HeaderValue::from_static("origin"));
    }
    Ok(resp)
}

/// With a token configured, every request but the console's own files and `/v1/version`
/// must carry `Authorization: Bearer <token>`. The version answers without it since it is what
/// a client checks before sending the token: over TLS it carries the certificate's
/// fingerprint, which the console shows beside its token prompt.
fn authorized(s: &AppState, req: &Request) -> bool {
    let Some(token) = &s.options.token else {
        return true;
    };
    let public = req.method() == Method::GET && req.uri().path() == "/v1/version";
    if public || is_console_file(req.method(), req.uri().path()) {
        return true;
    }
    let given = req
        .headers()
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "));
    // Constant-time comparison: the token is a secret.
    given.is_some_and(|g| {
        g.len() == token.len()
            && g.bytes()
                .zip(token.bytes())
                .fold(0u8, |a, (x, y)| a | (x ^ y))
                == 0
    })
}

/// The console's own files load without a token: the page has to reach the browser before it
/// can ask for one.
fn is_console_file(method: &Method, path: &str) -> bool {
    (method == Method::GET || method == Method::HEAD)
        && (path == "/" || path == "/console" || path.starts_with("/console/"))
}

fn too_large(limit: usize) -> ApiError {
    ApiError::refused(
        StatusCode::PAYLOAD_TOO_LARGE,
        Some("body"),
        format!("the body is above the limit of {limit} bytes"),
    )
}

async fn read_limited(body: Body, limit: usize) -> Result<Bytes, ApiError> {
    let mut stream = body.into_data_stream();
    let mut out = Vec::new();
    while let Some(chunk) = stream.next().await {
        let chunk = chunk.map_err(|e| ApiError::Invalid {
            field: "body".into(),
            reason: format!("could not be read: {e}"),
        })?;
        if out.len() + chunk.len() > limit {
            return Err(too_large(limit));
        }
        out.extend_from_slice(&chunk);
    }
    Ok(out.into())
}

/// The answer to a CORS preflight from an allowed origin (others were refused above).
fn preflight(origin: Option<HeaderValue>) -> Response {
    let mut resp = StatusCode::NO_CONTENT.into_response();
    let h = resp.headers_mut();
    if let Some(o) = origin {
        h.insert(header::ACCESS_CONTROL_ALLOW_ORIGIN, o);
        h.insert(
            header::ACCESS_CONTROL_ALLOW_METHODS,
            HeaderValue::from_static(ALLOW_METHODS),
        );
        h.insert(
            header::ACCESS_CONTROL_ALLOW_HEADERS,
            HeaderValue::from_static(ALLOW_HEADERS),
        );
        h.insert(
            header::ACCESS_CONTROL_MAX_AGE,
            HeaderValue::from_static("600"),
        );
        h.insert(header::VARY, HeaderValue::from_static("origin"));
    }
    h.insert(header::ALLOW, HeaderValue::from_static(ALLOW_METHODS));
    resp
}

/// Every error answer in the one JSON shape: the framework's own refusals (a 405, a path or
/// query it could not parse) come as plain text or empty, and leave here as
/// `{"error": …}`.
pub async fn json_errors(req: Request, next: Next) -> Response {
    let resp = next.run(req).await;
    let status = resp.status();
    let json = resp
        .headers()
        .get(header::CONTENT_TYPE)
        .is_some_and(|v| v.as_bytes().starts_with(b"application/json"));
    if !(status.is_client_error() || status.is_server_error()) || json {
        return resp;
    }
    let (mut parts, body) = resp.into_parts();
    let text = match read_limited(body, 64 << 10).await {
        Ok(b) => String::from_utf8_lossy(&b).trim().to_string(),
        Err(_) => String::new(),
    };
    let reason = if text.is_empty() {
        status
            .canonical_reason()
            .unwrap_or("refused")
            .to_lowercase()
    } else {
        text
    };
    let body = serde_json::json!({"error": reason}).to_string();
    parts.headers.remove(header::CONTENT_LENGTH);
    parts.headers.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/json"),
    );
    Response::from_parts(parts, Body::from(body))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn host_values_are_split_from_their_ports() {
        assert_eq!(host_name("LocalHost:7878").as_deref(), Some("localhost"));
        assert_eq!(host_name("[::1]:80").as_deref(), Some("::1"));
        assert_eq!(host_name("127.0.0.1").as_deref(), Some("127.0.0.1"));
        assert_eq!(host_name("evil.example:x"), None);
        assert_eq!(host_name("[::1]x"), None);
        assert_eq!(host_name(":80"), None);
    }
}
