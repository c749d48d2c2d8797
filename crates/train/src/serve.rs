//! `serve`: the detector over HTTP (axum on tokio), loaded once.
//!
//! ```text
//! POST /detect[?format=pcd|bin|nuscenes|npy][&render=1][&score_threshold=0.5]   body: one point cloud
//!      → 200 application/json FrameReport (or image/png with render=1)
//!      → 400 malformed cloud, bad query · 408 body not received in time · 413 body over
//!        --max-body-mb or cloud over --max-points · 415 format not recognised · 503 no room or
//!        no answer in time
//! GET  /health → 200 {"status": "ok", "model": …, "backend": …, …}
//! ```
//!
//! What clients can take is bounded: each body at most `--max-body-mb`, each cloud at most
//! `--max-points` (checked from its header before it is decoded), all requests together at most
//! `--memory-budget-mb` (a request reserves [`RESERVE_PER_BODY_BYTE`](crate::serve::RESERVE_PER_BODY_BYTE) times its announced body
//! before reading it and holds that until it is answered; others wait for room), and each request
//! ends within `--timeout-s`. SIGTERM or Ctrl-C stops accepting, lets the requests in flight
//! finish, and exits 0.
//!
//! The body's format comes from the body where it carries a signature (PCD's header, NPY's magic),
//! else from `format=`, else from the content type (`application/x-pcd`, `application/x-npy`,
//! `application/x-kitti-bin`). Requests are parsed concurrently on tokio's workers; the model runs
//! on one thread of its own that takes them from a bounded queue in arrival order, because one
//! inference already uses every core the CPU backend has (more models would only contend for
//! them). Each request is logged on stderr in one line: method, path, status, milliseconds.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use axum::Router;
use axum::body::Bytes;
use axum::extract::{DefaultBodyLimit, Query, Request, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use data_jrdb::{CloudFormat, ErrorKind, FormatInfo, ReadLimits, parse_cloud_within};
use serde::Deserialize;
use serde_json::json;
use tokio::sync::{Semaphore, mpsc, oneshot};

use crate::backend::BackendKind;
use crate::checkpoint::Slot;
use crate::detect::{BoxRecord, FrameReport, find_people, format_name, panic_message};
use crate::detector::RunDetector;
use crate::render::render_bev_png;
use crate::sensor_pose::{FrameSpec, Placement};
use crate::validate::FrameResult;

/// How to serve.
#[derive(Debug, Clone)]
pub struct ServeOptions {
    /// The run folder whose model is served.
    pub run: PathBuf,
    /// Keys of its config overridden for this service (`--set`).
    pub overrides: Vec<String>,
    /// Its checkpoint.
    pub checkpoint: Slot,
    /// Backend override.
    pub backend: Option<BackendKind>,
    /// Address to listen on.
    pub addr: SocketAddr,
    /// Bodies larger than this get 413.
    pub max_body_bytes: usize,
    /// Default score threshold (a request's `score_threshold` overrides it).
    pub score_threshold: f64,
    /// The clients' sensor pose in the base frame, or the ground to find in each cloud.
    pub frame: FrameSpec,
    /// Requests waiting for the model beyond this many wait for room (back-pressure).
    pub queue: usize,
    /// Clouds of more points than this get 413, refused from their header before decoding.
    pub max_points: usize,
    /// Bytes all requests in flight may reserve together (see [`RESERVE_PER_BODY_BYTE`]).
    pub memory_budget_bytes: usize,
    /// Longest a request may take from its arrival to its answer.
    pub timeout: Duration,
    /// Longest a client may take to send its body (counted from its arrival).
    pub read_timeout: Duration,
}

/// One inference for the model thread.
struct Job {
    /// In the client's frame; `find_people` moves them and the boxes with the service's pose.
    points: Vec<[f32; 3]>,
    frame: FrameSpec,
    score_threshold: f64,
    render: bool,
    reply: oneshot::Sender<Result<Answer, String>>,
}

/// Set once a request's body has been read: a time-out before then is the client's (408),
/// after it the service's (503).
#[derive(Clone, Default)]
struct BodyRead(Arc<AtomicBool>);

enum Answer {
    /// The boxes, the points dropped outside the working volume, and how the cloud was placed.
    Boxes(Vec<BoxRecord>, usize, Placement),
    Png(Vec<u8>),
}

#[derive(Clone)]
struct AppState {
    jobs: mpsc::Sender<Job>,
    health: serde_json::Value,
    score_threshold: f64,
    frame: FrameSpec,
    limits: ReadLimits,
    max_body_bytes: usize,
    /// The memory budget, one permit per KiB.
    budget: Arc<Semaphore>,
    budget_kib: usize,
    timeout: Duration,
    read_timeout: Duration,
}

/// What a request reserves of the memory budget per byte of body, until it is answered: the body
/// itself, and the cloud parsed from it, whose points take at most four times their bytes (a
/// compressed PCD may decode to no more than a body may hold).
pub const RESERVE_PER_BODY_BYTE: usize = 5;

/// Loads the model, binds `opts.addr`, prints `listening on http://ADDR` on stdout (the port
/// chosen when it is 0) and serves until SIGTERM or Ctrl-C, after which the requests in flight
/// are answered before it returns.
pub fn serve(opts: &ServeOptions) -> Result<()> {
    let (jobs, rx) = mpsc::channel::<Job>(opts.queue.max(1));
    let health = start_model_thread(opts, rx)?;
    let runtime = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().context("starting the tokio runtime")?;
    runtime.block_on(async move {
        let state = AppState {
            jobs,
            health,
            score_threshold: opts.score_threshold,
            frame: opts.frame,
            // A compressed body may decode to no more than a body may hold.
            limits: ReadLimits { max_points: opts.max_points, max_data_bytes: opts.max_body_bytes },
            max_body_bytes: opts.max_body_bytes,
            budget: Arc::new(Semaphore::new(opts.memory_budget_bytes.div_ceil(1024).min(Semaphore::MAX_PERMITS))),
            budget_kib: opts.memory_budget_bytes.div_ceil(1024),
            timeout: opts.timeout,
            read_timeout: opts.read_timeout.min(opts.timeout),
        };
        let app = Router::new()
            .route("/detect", post(detect_handler).layer(middleware::from_fn_with_state(state.clone(), admit)))
            .route("/health", get(health_handler))
            .layer(DefaultBodyLimit::max(opts.max_body_bytes))
            .layer(middleware::from_fn(log_request))
            .with_state(state);
        let listener = tokio::net::TcpListener::bind(opts.addr).await.with_context(|| format!("binding {}", opts.addr))?;
        let addr = listener.local_addr()?;
        println!("listening on http://{addr}");
        eprintln!("POST http://{addr}/detect with a point cloud ({}); GET http://{addr}/health; SIGTERM or Ctrl-C stops", FormatInfo::titles());
        axum::serve(listener, app).with_graceful_shutdown(shutdown_signal()).await.context("serving")?;
        eprintln!("stopped: every request in flight was answered");
        Ok(())
    })
}

/// SIGTERM (what service managers and container runtimes send) or Ctrl-C.
async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => {},
        _ = term => {},
    }
    eprintln!("stopping: no new connections; finishing the requests in flight");
}

/// Admits a `/detect` request: reserves its share of the memory budget before its body is read
/// (by its Content-Length, else the largest body), holds it until the answer, answers 408 to a
/// client whose body has not arrived by `--read-timeout-s`, and ends the request at `--timeout-s`
/// whatever it is waiting for.
async fn admit(State(state): State<AppState>, mut req: Request, next: Next) -> Response {
    let arrived = tokio::time::Instant::now();
    let (deadline, read_deadline) = (arrived + state.timeout, arrived + state.read_timeout);
    let secs = state.timeout.as_secs_f64();
    let announced = req.headers().get(header::CONTENT_LENGTH).and_then(|v| v.to_str().ok()).and_then(|v| v.trim().parse::<u64>().ok());
    if let Some(n) = announced.filter(|&n| n > state.max_body_bytes as u64) {
        return error(StatusCode::PAYLOAD_TOO_LARGE, format!("a body of {n} bytes is over the service's --max-body-mb ({} bytes)", state.max_body_bytes));
    }
    let body = announced.map_or(state.max_body_bytes, |n| n as usize);
    let kib = (body.saturating_mul(RESERVE_PER_BODY_BYTE).div_ceil(1024)).clamp(1, state.budget_kib) as u32;
    let Ok(Ok(_reserved)) = tokio::time::timeout_at(deadline, state.budget.clone().acquire_many_owned(kib)).await else {
        return error(StatusCode::SERVICE_UNAVAILABLE, format!("busy: no room for this request within {secs} s; try again later"));
    };
    let body_read = BodyRead::default();
    req.extensions_mut().insert(body_read.clone());
    let mut answer = std::pin::pin!(next.run(req));
    if let Ok(res) = tokio::time::timeout_at(read_deadline, &mut answer).await {
        return res;
    }
    if !body_read.0.load(Ordering::Acquire) {
        let read_secs = state.read_timeout.as_secs_f64();
        return error(StatusCode::REQUEST_TIMEOUT, format!("the body was not received within {read_secs} s"));
    }
    match tokio::time::timeout_at(deadline, answer).await {
        Ok(res) => res,
        Err(_) => error(StatusCode::SERVICE_UNAVAILABLE, format!("no answer within {secs} s: the model is busy; try again later")),
    }
}

/// Loads the detector on its own thread (Burn's CPU backends and the model stay there) and
/// answers with the health document once it is ready.
fn start_model_thread(opts: &ServeOptions, mut rx: mpsc::Receiver<Job>) -> Result<serde_json::Value> {
    let (ready_tx, ready_rx) = std::sync::mpsc::channel();
    let (run, overrides, slot, backend) = (opts.run.clone(), opts.overrides.clone(), opts.checkpoint, opts.backend);
    std::thread::Builder::new()
        .name("model".into())
        .spawn(move || {
            let detector = match RunDetector::load_with(&run, &overrides, slot, backend) {
                Ok(d) => d,
                Err(e) => {
                    let _ = ready_tx.send(Err(e));
                    return;
                }
            };
            let cfg = detector.config();
            let health = json!({
                "status": "ok",
                "model": cfg.model.kind(),
                "backend": cfg.backend.name(),
                "run": run.display().to_string(),
                "checkpoint": detector.checkpoint().file_name().map(|n| n.to_string_lossy().into_owned()),
                "overrides": overrides,
            });
            let range = cfg.eval.max_range.unwrap_or(25.0);
            let _ = ready_tx.send(Ok(health));
            while let Some(job) = rx.blocking_recv() {
                let Job { points, frame, score_threshold, render, reply } = job;
                if reply.is_closed() {
                    // Its client has gone or its time ran out while it waited.
                    continue;
                }
                // A panic inside the model answers 500 for this request; the service goes on.
                let answer = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                    let placement = frame.place(&points);
                    let found = find_people(&detector, &points, &placement.pose, score_threshold);
                    if render {
                        let frame = FrameResult { sequence: String::new(), name: "request".into(), gt: vec![], num_points: vec![], ignored: vec![], detections: found.base };
                        render_bev_png(&found.base_points, &frame, range).map(Answer::Png).map_err(|e| format!("{e:#}"))
                    } else {
                        Ok(Answer::Boxes(found.input.iter().map(|d| BoxRecord::new(&d.bbox, d.score)).collect(), found.dropped_out_of_volume, placement))
                    }
                }))
                .unwrap_or_else(|payload| Err(format!("the model failed on this cloud: {}", panic_message(&*payload))));
                let _ = reply.send(answer);
            }
        })
        .context("starting the model thread")?;
    ready_rx.recv().context("the model thread stopped while loading")?
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct DetectQuery {
    format: Option<String>,
    render: Option<String>,
    score_threshold: Option<f64>,
}

fn json_response(status: StatusCode, value: &serde_json::Value) -> Response {
    (status, [(header::CONTENT_TYPE, "application/json")], value.to_string()).into_response()
}

fn error(status: StatusCode, message: impl Into<String>) -> Response {
    json_response(status, &json!({ "error": message.into() }))
}

/// A `/detect` request's options, from its query string.
#[derive(Debug, Clone, PartialEq)]
pub struct DetectParams {
    /// `format=`: the body's format where the body carries no signature.
    pub format: Option<String>,
    /// `render=1`: answer a PNG.
    pub render: bool,
    /// `score_threshold=`, in [0, 1].
    pub score_threshold: f64,
}

impl DetectParams {
    /// Parses a query string (without the `?`); `Err` is the message a 400 carries.
    pub fn from_query(query: Option<&str>, default_threshold: f64) -> Result<Self, String> {
        let uri: axum::http::Uri = match query {
            None => axum::http::Uri::from_static("/detect"),
            Some(text) => format!("/detect?{text}").parse().map_err(|_| format!("query `{text}` is not a valid URI query"))?,
        };
        Self::from_uri(&uri, default_threshold)
    }

    /// The options of a request's URI, as [`from_query`](Self::from_query).
    pub fn from_uri(uri: &axum::http::Uri, default_threshold: f64) -> Result<Self, String> {
        let q: DetectQuery = if uri.query().is_none() {
            DetectQuery { format: None, render: None, score_threshold: None }
        } else {
            Query::<DetectQuery>::try_from_uri(uri).map_err(|e| format!("query: {}", e.body_text()))?.0
        };
        let render = match q.render.as_deref() {
            None | Some("0") | Some("false") => false,
            Some("1") | Some("true") | Some("") => true,
            Some(v) => return Err(format!("render={v}: use 1 or 0")),
        };
        let score_threshold = q.score_threshold.unwrap_or(default_threshold);
        if !(0.0..=1.0).contains(&score_threshold) {
            return Err(format!("score_threshold={score_threshold}: must lie in [0, 1]"));
        }
        Ok(Self { format: q.format, render, score_threshold })
    }
}

async fn detect_handler(State(state): State<AppState>, uri: axum::http::Uri, headers: HeaderMap, body_read: Option<axum::Extension<BodyRead>>, body: Bytes) -> Response {
    if let Some(axum::Extension(flag)) = body_read {
        flag.0.store(true, Ordering::Release);
    }
    let DetectParams { format, render, score_threshold } = match DetectParams::from_uri(&uri, state.score_threshold) {
        Ok(p) => p,
        Err(message) => return error(StatusCode::BAD_REQUEST, message),
    };
    if body.is_empty() {
        return error(StatusCode::BAD_REQUEST, format!("empty body: POST a point cloud ({})", FormatInfo::titles()));
    }
    let format = match body_format(&body, format.as_deref(), &headers) {
        Ok(f) => f,
        Err(r) => return r,
    };
    let started = Instant::now();
    let limits = state.limits;
    let cloud = match tokio::task::spawn_blocking(move || parse_cloud_within(&body, format, &limits)).await {
        Ok(Ok(c)) => c,
        Ok(Err(kind @ ErrorKind::OverLimit(_))) => {
            return error(StatusCode::PAYLOAD_TOO_LARGE, format!("{} cloud {kind} (the service's --max-points or --max-body-mb)", format_name(format)));
        }
        Ok(Err(kind)) => return error(StatusCode::BAD_REQUEST, format!("not a valid {} cloud: {kind}", format_name(format))),
        Err(e) => return error(StatusCode::INTERNAL_SERVER_ERROR, format!("reading the cloud failed: {}", if e.is_panic() { panic_message(&*e.into_panic()) } else { e.to_string() })),
    };
    let (n_points, dropped_non_finite) = (cloud.points.len(), cloud.dropped_non_finite);
    let (tx, rx) = oneshot::channel();
    if state.jobs.send(Job { points: cloud.points, frame: state.frame, score_threshold, render, reply: tx }).await.is_err() {
        return error(StatusCode::SERVICE_UNAVAILABLE, "the model is not running");
    }
    match rx.await {
        Ok(Ok(Answer::Png(png))) => ([(header::CONTENT_TYPE, "image/png")], png).into_response(),
        Ok(Ok(Answer::Boxes(detections, dropped_out_of_volume, placement))) => {
            let report = FrameReport {
                source: "request body".into(),
                format: format_name(format).into(),
                points: n_points,
                dropped_non_finite,
                dropped_out_of_volume,
                pose: placement.pose.to_string(),
                frame: placement.how,
                detections,
                score_threshold,
                message: None,
            };
            let mut value = serde_json::to_value(&report).unwrap_or_default();
            value["ms"] = json!(started.elapsed().as_secs_f64() * 1e3);
            json_response(StatusCode::OK, &value)
        }
        Ok(Err(message)) => error(StatusCode::INTERNAL_SERVER_ERROR, message),
        Err(_) => error(StatusCode::INTERNAL_SERVER_ERROR, "the model thread dropped the request"),
    }
}

/// The body's format: its signature, else `format=`, else the content type; else 415.
fn body_format(body: &[u8], query: Option<&str>, headers: &HeaderMap) -> Result<CloudFormat, Response> {
    if let Some(f) = CloudFormat::sniff(body) {
        return Ok(f);
    }
    if let Some(q) = query {
        return CloudFormat::from_name(q).ok_or_else(|| error(StatusCode::BAD_REQUEST, format!("format={q}: use {}", FormatInfo::names().replace('|', ", "))));
    }
    let content_type = headers.get(header::CONTENT_TYPE).and_then(|v| v.to_str().ok()).unwrap_or("");
    CloudFormat::from_media_type(content_type).ok_or_else(|| {
        let said = if content_type.is_empty() { "no content type".to_string() } else { format!("content type `{content_type}`") };
        error(
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            format!(
                "unrecognised point-cloud format: the body has no {} and {said} names none; send ?format={} or Content-Type {}",
                FormatInfo::signatures(),
                FormatInfo::names(),
                FormatInfo::media_types()
            ),
        )
    })
}

async fn health_handler(State(state): State<AppState>) -> Response {
    json_response(StatusCode::OK, &state.health)
}

async fn log_request(req: Request, next: Next) -> Response {
    let (method, path) = (req.method().clone(), req.uri().path().to_owned());
    let started = Instant::now();
    let res = next.run(req).await;
    eprintln!("{method} {path} {} {:.1} ms", res.status().as_u16(), started.elapsed().as_secs_f64() * 1e3);
    res
}
