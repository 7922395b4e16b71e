//! The optional bearer token: when the server has one, every `/v1` route needs
//! `Authorization: Bearer <token>`. Without one, a `/v1` request must be addressed to
//! this machine by its Host (DNS rebinding: see [`addressed_here`]).

use super::problem::{Problem, kind};
use super::state::AppState;
use axum::extract::{Request, State};
use axum::http::{StatusCode, header};
use axum::middleware::Next;
use axum::response::Response;

pub async fn require_token(
    State(state): State<AppState>,
    req: Request,
    next: Next,
) -> Result<Response, Problem> {
    let Some(token) = state.config.token.as_deref() else {
        if let Some(allowed) = &state.config.host_check {
            let host = req
                .headers()
                .get(header::HOST)
                .and_then(|v| v.to_str().ok())
                .or_else(|| req.uri().authority().map(|a| a.as_str()));
            if let Some(host) = host
                && !addressed_here(host, allowed)
            {
                return Err(elsewhere(host));
            }
        }
        return Ok(next.run(req).await);
    };
    let given = req
        .headers()
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| {
            let (scheme, rest) = v.split_once(' ')?;
            scheme.eq_ignore_ascii_case("bearer").then(|| rest.trim())
        });
    match given {
        Some(g) if constant_time_eq(g.as_bytes(), token.as_bytes()) => Ok(next.run(req).await),
        Some(_) => Err(unauthorized("the bearer token is wrong")),
        None => Err(unauthorized(
            "this server needs `Authorization: Bearer <token>` (its --token / KEA_TOKEN)",
        )),
    }
}

/// Whether a Host header (name or address, with or without a port) names this machine:
/// `localhost` or a name under it, an address in 127.0.0.0/8, `[::1]`, or one of the
/// `allowed` names (lower case). A request without a Host has not come from a browser.
pub fn addressed_here(host: &str, allowed: &[String]) -> bool {
    let host = host.trim().to_ascii_lowercase();
    // The port goes; an IPv6 literal keeps its brackets.
    let name = match host.rsplit_once(':') {
        Some((name, port))
            if !name.is_empty()
                && port.bytes().all(|b| b.is_ascii_digit())
                && !name.ends_with(':') =>
        {
            name
        }
        _ => host.as_str(),
    };
    let name = name.strip_suffix('.').unwrap_or(name);
    name == "localhost"
        || name.ends_with(".localhost")
        || name == "[::1]"
        || name
            .parse::<std::net::Ipv4Addr>()
            .is_ok_and(|ip| ip.is_loopback())
        || allowed.iter().any(|a| a == name)
}

fn elsewhere(host: &str) -> Problem {
    Problem::new(
        StatusCode::FORBIDDEN,
        kind::FORBIDDEN_HOST,
        "request addressed to another host",
    )
    .detail(format!(
        "this server has no token, so its API answers only requests addressed to this machine (Host localhost, 127.0.0.1 or [::1]), not to `{}`: a web page whose name is pointed at this machine (DNS rebinding) must not reach it. To call it by that name, start it with --allowed-host NAME, or give it a --token",
        host.chars().take(200).collect::<String>()
    ))
}

fn unauthorized(detail: &str) -> Problem {
    Problem::new(
        StatusCode::UNAUTHORIZED,
        kind::UNAUTHORIZED,
        "authentication required",
    )
    .detail(detail)
    .header(header::WWW_AUTHENTICATE, "Bearer realm=\"kea\"")
}

/// Compare without an early exit, so the time taken says nothing about the token.
fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    if a.len() != b.len() {
        return false;
    }
    a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_host_is_this_machine_by_its_loopback_names_or_an_allowed_one() {
        let allowed = ["kea.lab".to_string()];
        for here in [
            "localhost",
            "localhost:8080",
            "LOCALHOST.:8080",
            "app.localhost:3000",
            "127.0.0.1",
            "127.0.0.1:18111",
            "127.1.2.3:80",
            "[::1]:8080",
            "[::1]",
            "kea.lab",
            "Kea.Lab:443",
        ] {
            assert!(super::addressed_here(here, &allowed), "{here}");
        }
        for elsewhere in [
            "attacker.example",
            "attacker.example:18111",
            "localhost.attacker.example",
            "127.0.0.1.attacker.example",
            "10.0.0.1:8080",
            "[::2]:8080",
            "[::ffff:127.0.0.1]:8080",
            "kea.lab.evil",
            "",
            ":8080",
        ] {
            assert!(!super::addressed_here(elsewhere, &allowed), "{elsewhere}");
        }
    }

    #[test]
    fn constant_time_eq_compares() {
        assert!(super::constant_time_eq(b"abc", b"abc"));
        assert!(!super::constant_time_eq(b"abc", b"abd"));
        assert!(!super::constant_time_eq(b"abc", b"abcd"));
    }
}
