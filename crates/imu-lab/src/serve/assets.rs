//! The page's files, embedded in the binary: the HTML, its script and style, and uPlot (the
//! plotting library, vendored from npm: web/package.json pins its version, its licence is beside
//! it in assets/vendor). Only these names are served; any other path is a 404.
use axum::extract::Path;
use axum::http::{header, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};

use super::error;

/// (name, content type, bytes) of every embedded file but the page itself.
pub const ASSETS: &[(&str, &str, &[u8])] = &[
    (
        "app.js",
        "text/javascript; charset=utf-8",
        include_bytes!("../../assets/app.js"),
    ),
    (
        "style.css",
        "text/css; charset=utf-8",
        include_bytes!("../../assets/style.css"),
    ),
    (
        "uPlot.iife.min.js",
        "text/javascript; charset=utf-8",
        include_bytes!("../../assets/vendor/uPlot.iife.min.js"),
    ),
    (
        "uPlot.min.css",
        "text/css; charset=utf-8",
        include_bytes!("../../assets/vendor/uPlot.min.css"),
    ),
];

/// The page.
pub const INDEX: &str = include_str!("../../assets/index.html");

/// Everything from this server only: no inline script, nothing from elsewhere.
const CSP: &str = "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data:; \
                   connect-src 'self'; frame-ancestors 'none'; base-uri 'none'; form-action 'none'";

fn with_type(body: Response, ty: &'static str) -> Response {
    let mut r = body;
    let h = r.headers_mut();
    h.insert(header::CONTENT_TYPE, HeaderValue::from_static(ty));
    h.insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static(CSP),
    );
    r
}

pub async fn index() -> Response {
    with_type(INDEX.into_response(), "text/html; charset=utf-8")
}

pub async fn asset(Path(name): Path<String>) -> Response {
    match ASSETS.iter().find(|(n, _, _)| *n == name) {
        Some((_, ty, bytes)) => {
            let mut r = with_type(bytes.into_response(), ty);
            r.headers_mut().insert(
                header::CACHE_CONTROL,
                HeaderValue::from_static("max-age=3600"),
            );
            r
        }
        None => error(StatusCode::NOT_FOUND, "no such file"),
    }
}

/// The browser asks for an icon; there is none (204, not a 404 in the page's console).
pub async fn no_icon() -> Response {
    StatusCode::NO_CONTENT.into_response()
}
