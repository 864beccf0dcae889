//! The view's HTTP side: one loop that takes the field's newest frame, the robots' poses and
//! the page's requests in turn (synchronous; the requests' heads are read, with bounds, on
//! threads of `super::http`).
//!
//! | path | answer |
//! | --- | --- |
//! | `/` (`/view.js`, `/view.css`) | the page: static HTML, JS and CSS embedded in the binary |
//! | `/api/frame?channel=C&max_side=N` | [`super::FrameSnapshot`] as JSON |
//! | `/api/stats` | [`super::Stats`] as JSON |
//! | `/api/robots` | `{"world": W, "robots": [`[`super::RobotTrack`]`]}` (empty without `--world`) |
//! | `/api/walls` | `{"walls": [[x0, y0, x1, y1], …]}` in metres (empty without `--scenario`) |
//!
//! A bad parameter is a 400 with a plain-text message naming it and its value (each cut to 32
//! characters), a request target over 2048 bytes (or a request line over 4096 bytes, read no
//! further) a 414 that does not repeat it, a request head over 16 KiB a 431, an unknown path
//! a 404, another method than GET or HEAD a 405, and `/api/frame` before the first frame a 503
//! with `Retry-After: 1` and a JSON body `{"field", "state": "waiting", "status"}`.

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::time::{Duration, Instant};

use iceoryx2::node::Node;
use iceoryx2::prelude::*;
use pheromone_field::process::link::Receiver;
use pheromone_field::shm::{AttachError, FieldReader, ShmError, Svc};
use pheromone_field::wire::{ready_service, RobotServices, ROBOT_LINK};

use super::http::{Request, Server};

use super::{parse_frame_query, snapshot, QueryError, RobotPaths, StatsTracker};
use pheromone_messages::PoseMsg;

const PAGE_HTML: &str = include_str!("page/index.html");
const PAGE_JS: &str = include_str!("page/view.js");
const PAGE_CSS: &str = include_str!("page/view.css");

/// How long the loop waits for a request before it looks at the field, the robots and Ctrl-C.
/// Short enough to see nearly every frame of a 100 Hz field (for the tick statistics).
const REQUEST_SLICE: Duration = Duration::from_millis(5);
/// How often missing robots are looked for.
const RESCAN: Duration = Duration::from_secs(1);
/// How often a field not there yet is looked for.
const REATTACH: Duration = Duration::from_millis(200);
/// How often whether the field's process is still there is looked at.
const ALIVE_CHECK: Duration = Duration::from_millis(500);
/// The longest request target (path and query) answered; a longer one gets a 414.
pub const MAX_URL_BYTES: usize = 2048;

/// What `pheromone view` serves.
#[derive(Debug, Clone)]
pub struct ViewConfig {
    pub field: String,
    /// World whose robots' poses are shown (`pheromone/W/r<ID>/pose`), if any.
    pub world: Option<String>,
    /// Robots `r0..r<max_robots>` looked for.
    pub max_robots: u32,
    /// `max_side` of `/api/frame` when the request gives none.
    pub default_max_side: usize,
    /// The world's walls, `[x0, y0, x1, y1]` in metres (`pheromone view --scenario`): the
    /// field's frames carry no walls, the page draws these over the heat map (`/api/walls`).
    pub walls_m: Vec<[f64; 4]>,
}

#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    #[error("cannot listen on {address}: {source}")]
    Bind {
        address: String,
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    #[error(transparent)]
    Shm(#[from] ShmError),
}

/// Binds the HTTP server on `address` (e.g. `127.0.0.1:8080`; port 0 picks a free one) and
/// returns it with the address it listens on.
pub fn bind(address: &str) -> Result<(Server, SocketAddr), ViewError> {
    let server = Server::bind(address).map_err(|source| ViewError::Bind {
        address: address.to_string(),
        source: source.into(),
    })?;
    let local = server.local_addr();
    Ok((server, local))
}

/// An HTTP answer before it is sent.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Reply {
    pub status: u16,
    pub content_type: &'static str,
    pub body: Vec<u8>,
}

impl Reply {
    fn text(status: u16, body: impl Into<String>) -> Self {
        Self {
            status,
            content_type: "text/plain; charset=utf-8",
            body: body.into().into_bytes(),
        }
    }

    fn json(value: &impl serde::Serialize) -> Self {
        match serde_json::to_vec(value) {
            Ok(body) => Self {
                status: 200,
                content_type: "application/json",
                body,
            },
            Err(e) => Self::text(500, format!("cannot encode the answer: {e}")),
        }
    }

    fn bad(e: QueryError) -> Self {
        Self::text(400, e.to_string())
    }
}

/// The robots of one world: a pose receiver per robot whose pose service exists.
struct Robots {
    world: String,
    receivers: BTreeMap<u32, Receiver<PoseMsg>>,
    paths: RobotPaths,
}

impl Robots {
    /// Attaches to the pose services of `r0..r<max>` that exist now (never creates one).
    fn scan(&mut self, node: &Node<Svc>, max: u32) {
        for id in 0..max {
            if self.receivers.contains_key(&id) {
                continue;
            }
            let names = RobotServices::new(&self.world, id);
            let Ok(name) = ServiceName::new(&names.pose) else {
                continue;
            };
            let exists =
                ipc::Service::does_exist(&name, node.config(), MessagingPattern::PublishSubscribe)
                    .unwrap_or(false);
            if !exists {
                continue;
            }
            match Receiver::create(node, &names.pose, &ready_service(&names.pose), ROBOT_LINK) {
                Ok(r) => {
                    self.receivers.insert(id, r);
                }
                Err(e) => eprintln!("view: robot r{id}: {e}"),
            }
        }
    }

    fn drain(&mut self) {
        for (&id, r) in &self.receivers {
            while let Ok(Some(pose)) = r.try_recv() {
                self.paths.push(id, pose);
            }
        }
    }
}

/// The view's state between requests.
pub struct View {
    config: ViewConfig,
    reader: Option<FieldReader>,
    robots: Option<Robots>,
    stats: StatsTracker,
    next_scan: Instant,
    next_attach: Instant,
    /// When the view last saw a new frame.
    last_new_frame: Option<Instant>,
    /// Whether a process publishes the field's frames (looked at every `ALIVE_CHECK`).
    alive: bool,
    next_alive_check: Instant,
}

impl View {
    pub fn new(config: ViewConfig) -> Self {
        let robots = config.world.clone().map(|world| Robots {
            world,
            receivers: BTreeMap::new(),
            paths: RobotPaths::default(),
        });
        Self {
            config,
            reader: None,
            robots,
            stats: StatsTracker::default(),
            next_scan: Instant::now(),
            next_attach: Instant::now(),
            last_new_frame: None,
            alive: false,
            next_alive_check: Instant::now(),
        }
    }

    /// The field's state and what the page says about it: waiting, live, stalled, stopped.
    fn field_state(&self, s: &mut super::Stats) {
        let f = &self.config.field;
        let age = self.last_new_frame.map(|t| t.elapsed());
        s.last_frame_age_s = age.map(|a| a.as_secs_f64());
        let (state, status) = match age {
            _ if !s.attached => ("waiting", format!("waiting for field '{f}'")),
            None => ("waiting", format!("waiting for field '{f}'")),
            Some(age) if !self.alive => (
                "stopped",
                format!(
                    "field '{f}' stopped: no process publishes it; last frame {} ({:.1} s ago)",
                    s.sequence,
                    age.as_secs_f64()
                ),
            ),
            Some(age) if age > stall_after(s.tick_hz) => (
                "stalled",
                format!(
                    "field '{f}': no new frame for {:.1} s (its process is there); last frame {}",
                    age.as_secs_f64(),
                    s.sequence
                ),
            ),
            Some(_) => (
                "live",
                format!("field '{f}', frame {}, {:.1} Hz", s.sequence, s.tick_hz),
            ),
        };
        if state == "stopped" {
            // The rate of frames that no longer come.
            s.tick_hz = 0.0;
        }
        s.state = state;
        s.status = status;
    }

    /// Takes what arrived: the newest frame (attaching to the field when it appears) and the
    /// robots' poses.
    pub fn poll(&mut self, node: &Node<Svc>) -> Result<(), ShmError> {
        let now = Instant::now();
        let rescan = now >= self.next_scan;
        if rescan {
            self.next_scan = now + RESCAN;
        }
        if self.reader.is_none() && now >= self.next_attach {
            self.next_attach = now + REATTACH;
            match FieldReader::attach(node, &self.config.field) {
                Ok(r) => {
                    eprintln!("view: attached to field '{}'", self.config.field);
                    self.reader = Some(r);
                }
                Err(AttachError::NoField { .. }) => {}
                Err(e) => return Err(e.into()),
            }
        }
        if let Some(reader) = &mut self.reader {
            if reader.update()? {
                // A new frame: something publishes it.
                self.last_new_frame = Some(now);
                self.alive = true;
            }
            if let Some(f) = reader.frame() {
                self.stats.record(f.header);
            }
            // Only a field that sent nothing since the last look can have stopped (a field
            // starting may have its service before its publisher).
            if now >= self.next_alive_check {
                self.next_alive_check = now + ALIVE_CHECK;
                let quiet = self.last_new_frame.is_none_or(|t| now - t >= ALIVE_CHECK);
                self.alive = !quiet || reader.field_alive();
            }
        }
        if let Some(robots) = &mut self.robots {
            if rescan {
                robots.scan(node, self.config.max_robots);
            }
            robots.drain();
        }
        Ok(())
    }

    /// The answer to a GET of `url` (path and query).
    pub fn answer(&self, url: &str) -> Reply {
        if url.len() > MAX_URL_BYTES {
            // Not repeated: it could be anything, of any size.
            return Reply::text(
                414,
                format!(
                    "request target of {} bytes: at most {MAX_URL_BYTES}",
                    url.len()
                ),
            );
        }
        let (path, query) = match url.split_once('?') {
            Some((p, q)) => (p, Some(q)),
            None => (url, None),
        };
        let no_params = || match query.and_then(|q| q.split('&').find(|p| !p.is_empty())) {
            None => Ok(()),
            Some(p) => {
                let (k, v) = p.split_once('=').unwrap_or((p, ""));
                Err(Reply::bad(super::query_error(k, v, "unknown parameter")))
            }
        };
        let page = |content_type, body: &str| Reply {
            status: 200,
            content_type,
            body: body.as_bytes().to_vec(),
        };
        match path {
            "/" | "/index.html" => page("text/html; charset=utf-8", PAGE_HTML),
            "/view.js" => page("text/javascript; charset=utf-8", PAGE_JS),
            "/view.css" => page("text/css; charset=utf-8", PAGE_CSS),
            "/api/frame" => self.frame(query),
            "/api/stats" => no_params().map_or_else(
                |e| e,
                |()| {
                    let readers = self.reader.as_ref().map(|r| r.readers());
                    let mut stats = self.stats.stats(&self.config.field, readers);
                    self.field_state(&mut stats);
                    Reply::json(&stats)
                },
            ),
            "/api/robots" => no_params().map_or_else(|e| e, |()| self.robots()),
            "/api/walls" => no_params().map_or_else(
                |e| e,
                |()| Reply::json(&serde_json::json!({ "walls": self.config.walls_m })),
            ),
            _ => Reply::text(404, format!("not found: {}", super::shown(path))),
        }
    }

    fn frame(&self, query: Option<&str>) -> Reply {
        let q = match parse_frame_query(query, self.config.default_max_side) {
            Ok(q) => q,
            Err(e) => return Reply::bad(e),
        };
        let Some(sample) = self.reader.as_ref().and_then(|r| r.sample()) else {
            // Not an error of the request: the field has not started (yet).
            let f = &self.config.field;
            let mut reply = Reply::json(&serde_json::json!({
                "field": f,
                "state": "waiting",
                "status": format!("waiting for field '{f}'"),
            }));
            reply.status = 503;
            return reply;
        };
        let header = sample.user_header();
        if let Err(e) = q.check_channel(header.channels) {
            return Reply::bad(e);
        }
        Reply::json(&snapshot(header, sample.payload(), q.channel, q.max_side))
    }

    fn robots(&self) -> Reply {
        #[derive(serde::Serialize)]
        struct Answer<'a> {
            world: Option<&'a str>,
            robots: Vec<super::RobotTrack>,
        }
        Reply::json(&Answer {
            world: self.robots.as_ref().map(|r| r.world.as_str()),
            robots: self
                .robots
                .as_ref()
                .map(|r| r.paths.tracks())
                .unwrap_or_default(),
        })
    }

    fn respond(&mut self, node: &Node<Svc>, request: Request) -> Result<(), ShmError> {
        let reply = match request.method.as_str() {
            "GET" | "HEAD" => {
                // The newest frame, not the one of the last slice.
                self.poll(node)?;
                self.answer(&request.target)
            }
            m => {
                let m = super::shown(m);
                Reply::text(405, format!("method {m} not allowed: GET only"))
            }
        };
        let mut headers = vec![
            ("Content-Type", reply.content_type),
            ("Cache-Control", "no-store"),
        ];
        if reply.status == 503 {
            // A field not there yet: ask again in a second.
            headers.push(("Retry-After", "1"));
        }
        request.respond(reply.status, &headers, reply.body);
        Ok(())
    }
}

/// How long without a new frame a field whose process is there counts as stalled: five tick
/// periods at the rate measured, at least 1 s.
fn stall_after(tick_hz: f64) -> Duration {
    let periods = if tick_hz > 0.0 { 5.0 / tick_hz } else { 0.0 };
    Duration::from_secs_f64(periods.clamp(1.0, 3600.0))
}

/// Serves `view` on `server` until the node sees a termination request (Ctrl-C, SIGTERM).
pub fn serve(node: &Node<Svc>, server: &Server, view: &mut View) -> Result<(), ViewError> {
    while !pheromone_field::shm::should_stop(node) {
        view.poll(node)?;
        if let Some(request) = server.recv_timeout(REQUEST_SLICE) {
            view.respond(node, request)?;
        }
    }
    Ok(())
}
