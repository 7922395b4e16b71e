//! The route table (the single list of what is served, read by the OpenAPI test)
//! and [`app`], which builds the whole service from a state.

use super::problem::{Problem, kind};
use super::state::AppState;
use super::{auth, handlers, jobs_api, request};
use axum::Router;
use axum::handler::Handler;
use axum::http::{HeaderName, HeaderValue, Method, Request, StatusCode, header};
use axum::response::IntoResponse;
use axum::routing::{MethodFilter, MethodRouter, on};
use std::time::Duration;
use tower_http::compression::CompressionLayer;
use tower_http::cors::{AllowOrigin, CorsLayer};
use tower_http::request_id::{MakeRequestUuid, PropagateRequestIdLayer, SetRequestIdLayer};
use tower_http::services::ServeDir;
use tower_http::trace::TraceLayer;

/// Who may call a route.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Access {
    /// Always open (health checks).
    Public,
    /// Needs the bearer token when the server has one.
    Api,
}

pub struct Route {
    pub method: Method,
    pub path: &'static str,
    pub access: Access,
    /// The query parameters the route reads (its handler checks their values); any
    /// other is a 400 naming it. `None`: the query is ignored (the health check, so a
    /// probe's cache-busting parameter does no harm).
    pub query: Option<&'static [&'static str]>,
    router: MethodRouter<AppState>,
}

fn route<H, T>(
    method: Method,
    path: &'static str,
    access: Access,
    query: Option<&'static [&'static str]>,
    handler: H,
) -> Route
where
    H: Handler<T, AppState>,
    T: 'static,
{
    let filter = MethodFilter::try_from(method.clone()).expect("a routable method");
    let mut router = on(filter, handler);
    if query == Some(&[]) {
        router = router.layer(axum::middleware::from_fn(refuse_query));
    }
    Route {
        method,
        path,
        access,
        query,
        router,
    }
}

/// A route that reads no query parameter refuses every one (400, naming each).
async fn refuse_query(
    req: Request<axum::body::Body>,
    next: axum::middleware::Next,
) -> axum::response::Response {
    match request::no_query(req.uri().query().map(str::to_string)) {
        Ok(()) => next.run(req).await,
        Err(problem) => problem.into_response(),
    }
}

/// Every API route. The OpenAPI test compares this with `openapi.yaml`.
pub fn table() -> Vec<Route> {
    use Access::*;
    use Method as M;
    const NONE: Option<&[&str]> = Some(&[]);
    const PAGE: Option<&[&str]> = Some(&["limit", "cursor"]);
    vec![
        route(M::GET, "/healthz", Public, None, handlers::health),
        route(M::GET, "/v1/limits", Api, NONE, handlers::limits),
        route(M::GET, "/v1/presets", Api, NONE, handlers::list_presets),
        route(
            M::GET,
            "/v1/presets/{name}",
            Api,
            NONE,
            handlers::get_preset,
        ),
        route(
            M::GET,
            "/v1/presets/{name}/synthesis",
            Api,
            NONE,
            handlers::get_preset_synthesis,
        ),
        route(M::POST, "/v1/models", Api, NONE, handlers::create_model),
        route(M::GET, "/v1/models", Api, PAGE, handlers::list_models),
        route(M::GET, "/v1/models/{id}", Api, NONE, handlers::get_model),
        route(
            M::DELETE,
            "/v1/models/{id}",
            Api,
            NONE,
            handlers::delete_model,
        ),
        route(M::POST, "/v1/analyze", Api, NONE, handlers::analyze),
        route(M::POST, "/v1/jobs", Api, NONE, jobs_api::submit),
        route(
            M::GET,
            "/v1/jobs",
            Api,
            Some(&["status", "limit", "cursor"]),
            jobs_api::list,
        ),
        route(M::GET, "/v1/jobs/{id}", Api, NONE, jobs_api::get),
        route(
            M::DELETE,
            "/v1/jobs/{id}",
            Api,
            Some(&["purge"]),
            jobs_api::cancel,
        ),
        route(
            M::GET,
            "/v1/jobs/{id}/request",
            Api,
            NONE,
            jobs_api::request,
        ),
        route(M::GET, "/v1/jobs/{id}/result", Api, NONE, jobs_api::result),
        route(
            M::GET,
            "/v1/jobs/{id}/traces.csv",
            Api,
            NONE,
            jobs_api::traces,
        ),
        route(M::GET, "/v1/jobs/{id}/events", Api, NONE, jobs_api::events),
    ]
}

/// (method, path, query parameters read) of every route, e.g. `("GET",
/// "/v1/jobs/{id}", [])`; the query is empty where it is ignored (the health check)
/// or refused.
pub fn route_queries() -> Vec<(String, String, Vec<String>)> {
    table()
        .into_iter()
        .map(|r| {
            let q = r.query.unwrap_or_default();
            let q = q.iter().map(|p| p.to_string()).collect();
            (r.method.to_string(), r.path.to_string(), q)
        })
        .collect()
}

async fn not_found() -> Problem {
    Problem::new(StatusCode::NOT_FOUND, kind::NOT_FOUND, "no such resource")
        .detail("see openapi.yaml for the routes this server serves")
}

async fn method_not_allowed() -> Problem {
    Problem::new(
        StatusCode::METHOD_NOT_ALLOWED,
        kind::METHOD,
        "method not allowed on this resource",
    )
    .detail("see openapi.yaml for the methods of each route")
}

/// The whole service: API routes, auth, static UI, and the tower layers.
pub fn app(state: AppState) -> Router {
    let mut public = Router::new();
    let mut api = Router::new();
    for r in table() {
        match r.access {
            Access::Public => public = public.route(r.path, r.router),
            Access::Api => api = api.route(r.path, r.router),
        }
    }
    let api = api.route_layer(axum::middleware::from_fn_with_state(
        state.clone(),
        auth::require_token,
    ));
    let mut router = public
        .merge(api)
        .method_not_allowed_fallback(method_not_allowed);
    router = match &state.config.web_dir {
        Some(dir) => router.fallback_service(
            ServeDir::new(dir).not_found_service(not_found.with_state(state.clone())),
        ),
        None => router.fallback(not_found),
    };
    if !state.config.cors_origins.is_empty() {
        let origins: Vec<HeaderValue> = state
            .config
            .cors_origins
            .iter()
            .filter_map(|o| HeaderValue::from_str(o).ok())
            .collect();
        router = router.layer(
            CorsLayer::new()
                .allow_origin(AllowOrigin::list(origins))
                .allow_methods([Method::GET, Method::POST, Method::DELETE])
                .allow_headers([header::AUTHORIZATION, header::CONTENT_TYPE])
                .expose_headers([header::LOCATION, HeaderName::from_static("x-request-id")])
                .max_age(Duration::from_secs(3600)),
        );
    }
    let request_id = HeaderName::from_static("x-request-id");
    router
        .layer(CompressionLayer::new())
        .layer(PropagateRequestIdLayer::new(request_id.clone()))
        .layer(
            TraceLayer::new_for_http().make_span_with(|req: &Request<_>| {
                let id = req
                    .headers()
                    .get("x-request-id")
                    .and_then(|v| v.to_str().ok())
                    .unwrap_or("-");
                tracing::info_span!("request", id, method = %req.method(), uri = %req.uri())
            }),
        )
        .layer(SetRequestIdLayer::new(request_id, MakeRequestUuid))
        .with_state(state)
}
