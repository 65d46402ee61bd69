//! The browser console (`console/` in the repository), served at `/` and `/console/`. Its files
//! are written as plain ES modules and served exactly as written — there is no build step whose
//! output could drift from the source — and they are compiled into the binary, so the daemon
//! serves the console with nothing installed beside it. A test checks that [`ASSETS`] lists
//! every file of `console/`.
//!
//! The files carry no secret, so they are served without the token; everything the console does
//! afterwards goes through `/v1` with the token the technician types in. They are refused to
//! frames of other sites and may load nothing from elsewhere (the Content-Security-Policy).

use crate::server::http::state::AppState;
use axum::Router;
use axum::extract::Path;
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Redirect, Response};
use axum::routing::get;
use std::sync::Arc;

macro_rules! assets {
    ($($name:literal => $mime:literal,)*) => {
        /// The console's files: name, media type, contents.
        pub const ASSETS: &[(&str, &str, &[u8])] = &[
            $(($name, $mime, include_bytes!(concat!("../../../console/", $name))),)*
        ];
    };
}

assets! {
    "index.html" => "text/html; charset=utf-8",
    "console.css" => "text/css; charset=utf-8",
    "app.js" => "text/javascript; charset=utf-8",
    "api.js" => "text/javascript; charset=utf-8",
    "rig3d.js" => "text/javascript; charset=utf-8",
    "tiles.js" => "text/javascript; charset=utf-8",
    "channel.js" => "text/javascript; charset=utf-8",
    "panels.js" => "text/javascript; charset=utf-8",
}

const POLICY: &str = "default-src 'self'; img-src 'self' blob: data:; connect-src 'self'; \
                      style-src 'self'; script-src 'self'; frame-ancestors 'none'; \
                      base-uri 'none'; form-action 'none'";

fn serve(name: &str) -> Response {
    let Some((_, mime, bytes)) = ASSETS.iter().find(|(n, _, _)| *n == name) else {
        return crate::server::ApiError::NotFound(format!("the console has no file `{name}`"))
            .into_response();
    };
    let mut resp = (StatusCode::OK, *bytes).into_response();
    let h = resp.headers_mut();
    for (k, v) in [
        (header::CONTENT_TYPE, *mime),
        // The files change with the binary; a browser asks again rather than keep a stale one.
        (header::CACHE_CONTROL, "no-cache"),
        (header::CONTENT_SECURITY_POLICY, POLICY),
        (header::X_FRAME_OPTIONS, "DENY"),
        (header::X_CONTENT_TYPE_OPTIONS, "nosniff"),
        (header::REFERRER_POLICY, "no-referrer"),
    ] {
        h.insert(k, HeaderValue::from_static(v));
    }
    resp
}

pub fn routes() -> Router<Arc<AppState>> {
    Router::new()
        .route("/", get(|| async { serve("index.html") }))
        .route(
            "/console",
            get(|| async { Redirect::permanent("/console/") }),
        )
        .route("/console/", get(|| async { serve("index.html") }))
        .route(
            "/console/{file}",
            get(|Path(file): Path<String>| async move { serve(&file) }),
        )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_file_of_the_console_is_embedded_as_it_is() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("console");
        let mut on_disk: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap())
            .filter(|e| e.file_type().unwrap().is_file())
            .map(|e| e.file_name().into_string().unwrap())
            .filter(|n| !n.starts_with('.') && n != "package.json" && n != "package-lock.json")
            .collect();
        on_disk.sort();
        let mut embedded: Vec<String> = ASSETS.iter().map(|(n, _, _)| n.to_string()).collect();
        embedded.sort();
        assert_eq!(on_disk, embedded, "console/ and ASSETS differ");
        for (name, _, bytes) in ASSETS {
            assert_eq!(std::fs::read(dir.join(name)).unwrap(), *bytes, "{name}");
        }
    }
}
