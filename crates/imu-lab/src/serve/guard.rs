//! The server's rules for every request, checked before any handler runs:
//!
//! * **Host** must name the address the server listens on (`127.0.0.1:PORT`, or `localhost:PORT`
//!   when that address is a loopback one): a page on another site that rebinds its DNS name to
//!   127.0.0.1 sends its own name and is refused (403).
//! * **Writes** (every method but GET and HEAD) must come from the page itself: an `Origin`
//!   other than the server's own, or a browser's `Sec-Fetch-Site: cross-site`, is refused (403);
//!   and every write carries the token the page obtained from `/api/info` in
//!   `X-Imu-Lab-Token` (403 without it). Another site's script can neither read that token
//!   (no CORS headers are ever sent) nor send the header without a preflight nobody answers.
//! * GET and HEAD change nothing.
use std::collections::hash_map::RandomState;
use std::hash::{BuildHasher, Hasher};

use axum::extract::{Request, State};
use axum::http::{header, Method, StatusCode};
use axum::middleware::Next;
use axum::response::Response;

use super::{error, Shared};

/// The header that carries the write token.
pub const TOKEN_HEADER: &str = "x-imu-lab-token";

/// A fresh unguessable token: 128 bits from two SipHash keys std draws from the operating
/// system's random source.
pub fn new_token() -> String {
    let word = |salt: u64| {
        let mut h = RandomState::new().build_hasher();
        h.write_u64(salt);
        h.finish()
    };
    format!("{:016x}{:016x}", word(1), word(2))
}

/// The `Host` values the server answers: its address, and `localhost:PORT` for a loopback one.
fn hosts(s: &Shared) -> Vec<String> {
    let mut v = vec![s.listen.to_string()];
    if s.listen.ip().is_loopback() {
        v.push(format!("localhost:{}", s.listen.port()));
    }
    v
}

pub async fn check(State(s): State<Shared>, req: Request, next: Next) -> Response {
    let h = req.headers();
    let hosts = hosts(&s);
    // exactly one Host, naming this server
    let host = h.get(header::HOST).and_then(|v| v.to_str().ok());
    let single = h.get_all(header::HOST).iter().count() == 1;
    if !(single && host.is_some_and(|v| hosts.iter().any(|a| a.eq_ignore_ascii_case(v)))) {
        return error(
            StatusCode::FORBIDDEN,
            &format!(
                "Host {:?} is not the address this server listens on ({})",
                host.unwrap_or(""),
                hosts.join(" or ")
            ),
        );
    }
    if req.method() != Method::GET && req.method() != Method::HEAD {
        // every Origin given (a request may carry several) must be this server
        for origin in h.get_all(header::ORIGIN) {
            let ok = origin.to_str().is_ok_and(|o| {
                hosts
                    .iter()
                    .any(|a| o.eq_ignore_ascii_case(&format!("http://{a}")))
            });
            if !ok {
                return error(
                    StatusCode::FORBIDDEN,
                    "a write from another origin: refused",
                );
            }
        }
        if h.get("sec-fetch-site")
            .is_some_and(|v| v.as_bytes().eq_ignore_ascii_case(b"cross-site"))
        {
            return error(StatusCode::FORBIDDEN, "a cross-site write: refused");
        }
        // exactly one token, the page's (with two, which one counted depended on their order)
        let mut tokens = h.get_all(TOKEN_HEADER).iter();
        let token = tokens.next().map(|v| v.as_bytes());
        if token != Some(s.token.as_bytes()) || tokens.next().is_some() {
            return error(
                StatusCode::FORBIDDEN,
                "a write without the page's token (X-Imu-Lab-Token, from /api/info): refused",
            );
        }
    }
    let mut resp = next.run(req).await;
    let rh = resp.headers_mut();
    // the page is never framed by another site, and what it serves is never sniffed
    rh.insert(
        header::X_FRAME_OPTIONS,
        header::HeaderValue::from_static("DENY"),
    );
    rh.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        header::HeaderValue::from_static("nosniff"),
    );
    resp
}
