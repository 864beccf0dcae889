//! `pheromone view` end to end: real field and view, HTTP by hand, the page in headless Chromium.

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;

use crate::harness::*;

mod limits;
mod states;

/// The browser the page test drives: Debian's `chromium` package.
const CHROMIUM: &str = "/usr/bin/chromium";

/// A TCP port free a moment ago (the view binds it next).
fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// `(status, content type, body)` of `METHOD path` (HTTP/1.0: the answer ends at close).
fn request(port: u16, method: &str, path: &str) -> std::io::Result<(u16, String, Vec<u8>)> {
    let mut s = TcpStream::connect(("127.0.0.1", port))?;
    s.set_read_timeout(Some(Duration::from_secs(10)))?;
    write!(
        s,
        "{method} {path} HTTP/1.0\r\nHost: 127.0.0.1:{port}\r\n\r\n"
    )?;
    let mut raw = Vec::new();
    s.read_to_end(&mut raw)?;
    // A connection closed before a whole head (the view closed it) is an error of this request.
    let split = raw
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .ok_or_else(|| {
            std::io::Error::new(
                std::io::ErrorKind::UnexpectedEof,
                format!(
                    "closed after {} bytes, before a whole response head",
                    raw.len()
                ),
            )
        })?;
    let head = String::from_utf8_lossy(&raw[..split]).into_owned();
    let status = head
        .split(' ')
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("status line: {head}"));
    let content_type = head
        .lines()
        .find_map(|l| {
            let (k, v) = l.split_once(':')?;
            k.eq_ignore_ascii_case("content-type")
                .then(|| v.trim().to_string())
        })
        .unwrap_or_default();
    Ok((status, content_type, raw[split + 4..].to_vec()))
}

fn get(port: u16, path: &str) -> (u16, String, Vec<u8>) {
    request(port, "GET", path).unwrap_or_else(|e| panic!("GET {path}: {e}"))
}

fn get_json(port: u16, path: &str) -> Value {
    let (status, ctype, body) = get(port, path);
    assert_eq!(
        status,
        200,
        "GET {path}: {}",
        String::from_utf8_lossy(&body)
    );
    assert_eq!(ctype, "application/json", "GET {path}");
    serde_json::from_slice(&body).unwrap_or_else(|e| panic!("GET {path}: {e}"))
}

fn get_text(port: u16, path: &str) -> (u16, String) {
    let (status, _, body) = get(port, path);
    (status, String::from_utf8_lossy(&body).into_owned())
}

/// A 200×100 field of 0.1 m cells that keeps what it gets (model none), and a view of it.
fn field_and_view(tag: &str, view_args: &[&str]) -> (String, Proc, Proc, u16) {
    let name = unique(tag);
    let field = Proc::spawn(
        &Cmd::field(&name)
            .grid(200, 100)
            .cell_size(0.1)
            .model("none")
            .tick_hz(50)
            .argv(),
    );
    let (view, port) = view_on(&name, view_args);
    (name, field, view, port)
}

/// A view of field `name` on a free port, once it has attached to the field; it and its port.
///
/// `free_port` releases the port before the view binds it, so a test running beside this one can
/// take it meanwhile: the view then exits, and another port is tried.
fn view_on(name: &str, view_args: &[&str]) -> (Proc, u16) {
    for _ in 0..5 {
        let port = free_port();
        let listen = format!("127.0.0.1:{port}");
        let mut args = vec!["view", "--field", name, "--listen", &listen];
        args.extend_from_slice(view_args);
        let mut view = Proc::spawn(&args);
        let seen = eventually(
            Duration::from_secs(60),
            "the view to see the field (or to exit)",
            || {
                if !view.is_running() {
                    return Some(false);
                }
                let (status, _, body) = request(port, "GET", "/api/stats").ok()?;
                let stats: Value = serde_json::from_slice(&body).ok()?;
                (status == 200 && stats["attached"] == true).then_some(true)
            },
        );
        if seen && view.is_running() {
            return (view, port);
        }
        let out = view.wait_exit(Duration::from_secs(10));
        eprintln!("the view on port {port} exited: {}", stderr(&out));
    }
    panic!("the view exited on 5 ports in a row");
}

/// Deposits a blob at (x, y) and waits until the view's frame has it; returns that frame.
fn deposit_and_wait(name: &str, port: u16, x: f32, y: f32, query: &str) -> Value {
    let (xs, ys) = (x.to_string(), y.to_string());
    let out = run(&[
        "deposit", "--field", name, "--x", &xs, "--y", &ys, "--amount", "1",
    ]);
    assert!(out.status.success(), "deposit: {}", stderr(&out));
    eventually(Duration::from_secs(20), "the blob in /api/frame", || {
        let f = get_json(port, &format!("/api/frame?{query}"));
        (f["max"].as_f64()? > 0.0).then_some(f)
    })
}

/// The value `pheromone probe` reads at (x, y), once it is positive.
fn probe(name: &str, x: f32, y: f32) -> f64 {
    let (xs, ys) = (x.to_string(), y.to_string());
    let out = run(&[
        "probe", "--field", name, "--x", &xs, "--y", &ys, "--above", "0", "--json",
    ]);
    assert!(out.status.success(), "probe: {}", stderr(&out));
    json(&out)["value"].as_f64().unwrap()
}

#[test]
fn the_view_serves_the_fields_frame_downsampled_with_its_stats() {
    let (name, field, view, port) = field_and_view("view-http", &["--max-side", "50"]);
    // The centre of cell (123, 45).
    let (x, y) = (12.35f32, 4.55f32);
    let f = deposit_and_wait(&name, port, x, y, "");
    let value = probe(&name, x, y);

    // Default max_side 50: 200×100 pooled by 4 into 50×25 cells of 0.4 m.
    assert_eq!(
        (f["width"].as_u64(), f["height"].as_u64()),
        (Some(50), Some(25))
    );
    assert_eq!(f["factor"], 4);
    assert!(
        (f["cell_size_m"].as_f64().unwrap() - 0.4).abs() < 1e-6,
        "{}",
        f["cell_size_m"]
    );
    assert_eq!(
        (f["source_width"].as_u64(), f["source_height"].as_u64()),
        (Some(200), Some(100))
    );
    assert_eq!(
        (f["origin_x_m"].as_f64(), f["origin_y_m"].as_f64()),
        (Some(0.0), Some(0.0))
    );
    // The hottest cell is the deposit's, with the value the field holds there.
    let max = f["max"].as_f64().unwrap();
    assert!(
        (max - value).abs() <= 1e-6 * value,
        "view max {max}, probe {value}"
    );
    assert_eq!(
        (f["hottest"]["col"].as_u64(), f["hottest"]["row"].as_u64()),
        (Some(123), Some(45))
    );
    assert!((f["hottest"]["x_m"].as_f64().unwrap() - x as f64).abs() < 1e-4);
    assert!((f["hottest"]["y_m"].as_f64().unwrap() - y as f64).abs() < 1e-4);
    // In the pooled cells the maximum sits in the block holding (123, 45): (30, 11).
    let cells: Vec<f64> = f["cells"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert_eq!(cells.len(), 50 * 25);
    let argmax = (0..cells.len())
        .max_by(|&a, &b| cells[a].total_cmp(&cells[b]))
        .unwrap();
    assert_eq!((argmax % 50, argmax / 50), (30, 11));
    assert_eq!(cells[argmax], max);
    assert!(cells.iter().all(|v| v.is_finite() && *v >= 0.0));

    // Full resolution on request: the same cell, unpooled.
    let full = get_json(port, "/api/frame?channel=0&max_side=4096");
    assert_eq!(
        (full["width"].as_u64(), full["factor"].as_u64()),
        (Some(200), Some(1))
    );
    assert_eq!(full["cells"][45 * 200 + 123].as_f64(), Some(max));

    // Stats: the header's counters and a tick rate measured from the frames.
    let s = get_json(port, "/api/stats");
    assert_eq!(s["field"], name.as_str());
    assert_eq!(s["deposits_applied"], 1, "{s}");
    assert_eq!(s["deposits_rejected_total"], 0, "{s}");
    assert_eq!(s["deposits_rejected"].as_object().unwrap().len(), 7, "{s}");
    // The rate comes from the frames' stamps over a 2 s window. On a loaded machine a 50 Hz
    // field can tick late, and a few frames say little: once the view has seen a second of
    // frames, only a rate of the right order is asserted (the arithmetic is unit-tested).
    let settled = eventually(Duration::from_secs(20), "a second of frames", || {
        let s = get_json(port, "/api/stats");
        (s["frames_seen"].as_u64().unwrap_or(0) >= 50).then_some(s)
    });
    let hz = settled["tick_hz"].as_f64().unwrap();
    assert!(
        (10.0..250.0).contains(&hz),
        "tick rate of a 50 Hz field: {hz}: {settled}"
    );
    assert!(s["readers"].as_u64().unwrap() >= 1, "{s}");
    assert!(s["sequence"].as_u64().unwrap() >= f["sequence"].as_u64().unwrap());
    assert!(s["longest_tick_gap_ms"].as_f64().unwrap() > 0.0, "{s}");
    assert!(s["tick_compute_ms"].as_f64().unwrap() >= 0.0);

    // No --world: no robots.
    let r = get_json(port, "/api/robots");
    assert_eq!(r, serde_json::json!({"world": null, "robots": []}));

    // The page and its script and style, embedded.
    let (status, ctype, body) = get(port, "/");
    let html = String::from_utf8_lossy(&body);
    assert_eq!((status, ctype.as_str()), (200, "text/html; charset=utf-8"));
    assert!(
        html.contains("<canvas id=\"heat\"") && html.contains("/view.js"),
        "{html}"
    );
    let (status, js) = get_text(port, "/view.js");
    assert!(status == 200 && js.contains("/api/frame"), "{status}");
    assert_eq!(get(port, "/view.css").0, 200);

    view.interrupt();
    let out = view.wait_exit(Duration::from_secs(30));
    assert!(out.status.success(), "view: {}", stderr(&out));
    assert!(
        stderr(&out).contains(&format!("view: http://127.0.0.1:{port}/")),
        "{}",
        stderr(&out)
    );
    drop(field);
}

#[test]
fn bad_parameters_get_a_400_naming_them_and_unknown_paths_a_404() {
    let (_name, _field, _view, port) = field_and_view("view-bad", &[]);
    for (path, status, message) in [
        (
            "/api/frame?channel=x",
            400,
            "channel=x: not a non-negative integer",
        ),
        (
            "/api/frame?channel=-1",
            400,
            "channel=-1: not a non-negative integer",
        ),
        (
            "/api/frame?channel=1",
            400,
            "channel=1: the field has 1 channel(s), 0..1",
        ),
        (
            "/api/frame?max_side=0",
            400,
            "max_side=0: must be between 1 and 4096",
        ),
        (
            "/api/frame?max_side=4097",
            400,
            "max_side=4097: must be between 1 and 4096",
        ),
        (
            "/api/frame?max_side=abc",
            400,
            "max_side=abc: not a non-negative integer",
        ),
        ("/api/frame?zoom=3", 400, "zoom=3: unknown parameter"),
        (
            "/api/frame?channel=0&channel=0",
            400,
            "channel=0: given twice",
        ),
        ("/api/stats?x=1", 400, "x=1: unknown parameter"),
        ("/api/robots?world=w", 400, "world=w: unknown parameter"),
        ("/api/nothing", 404, "not found: /api/nothing"),
        ("/index.htm", 404, "not found: /index.htm"),
    ] {
        let (got, ctype, body) = get(port, path);
        assert_eq!(
            (got, String::from_utf8_lossy(&body).as_ref()),
            (status, message),
            "{path}"
        );
        assert_eq!(ctype, "text/plain; charset=utf-8", "{path}");
    }
    let (status, _, body) = request(port, "POST", "/api/frame").unwrap();
    assert_eq!(status, 405, "{}", String::from_utf8_lossy(&body));
    // The good parameters still work.
    assert_eq!(get(port, "/api/frame?channel=0&max_side=7").0, 200);
    // Bad flags: exit status 2 with a message naming the flag or the address.
    let o = run(&["view", "--max-side", "0"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("--max-side 0: must be between 1 and 4096"),
        "{}",
        stderr(&o)
    );
    let taken = format!("127.0.0.1:{port}");
    let o = run(&["view", "--listen", &taken]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains(&format!("cannot listen on {taken}")),
        "{}",
        stderr(&o)
    );
    let o = run(&["view", "--scenario", "no-such-scenario"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("no-such-scenario"), "{}", stderr(&o));
}

#[test]
fn the_view_shows_robot_poses_and_their_recent_paths() {
    use pheromone_field::process::link::Sender;
    use pheromone_field::wire::{ready_service, RobotServices, ROBOT_LINK};
    use pheromone_messages::PoseMsg;

    let world = unique("view-w");
    let (_name, _field, _view, port) = field_and_view("view-robots", &["--world", &world]);
    let node = pheromone_field::shm::create_node(&unique("view-test-poses")).unwrap();
    let pose = RobotServices::new(&world, 2).pose;
    let sender =
        Sender::<PoseMsg>::create(&node, &pose, &ready_service(&pose), ROBOT_LINK).unwrap();
    let mut k = 0u64;
    let robots = eventually(Duration::from_secs(60), "robot r2 with a path", || {
        k += 1;
        sender
            .send(PoseMsg {
                robot_id: 2,
                step: k,
                x_m: 1.0 + 0.1 * k as f64,
                y_m: 2.0,
                theta_rad: 0.5,
                ..Default::default()
            })
            .unwrap();
        std::thread::park_timeout(Duration::from_millis(50));
        let r = get_json(port, "/api/robots");
        (r["robots"][0]["path"].as_array()?.len() >= 3).then_some(r)
    });
    assert_eq!(robots["world"], world.as_str());
    let r2 = &robots["robots"][0];
    assert_eq!(robots["robots"].as_array().unwrap().len(), 1, "{robots}");
    assert_eq!(r2["id"], 2);
    assert_eq!(r2["theta_rad"], 0.5);
    let path = r2["path"].as_array().unwrap();
    assert_eq!(path.last().unwrap()[0], r2["x_m"]);
    assert!(path.iter().all(|p| p[1] == 2.0), "{path:?}");
}

/// Runs Chromium on `url` with `--dump-dom` and returns the DOM once the page has polled for
/// `budget_ms` of virtual time.
fn dump_dom(url: &str, budget_ms: u32) -> String {
    assert!(
        Path::new(CHROMIUM).exists(),
        "{CHROMIUM} is missing: the browser test needs Debian's chromium package \
         (apt-get install -y --no-install-recommends chromium; .ci/run installs it)"
    );
    let profile = std::env::temp_dir().join(unique("view-chromium"));
    std::fs::create_dir_all(&profile).unwrap();
    let mut child = Command::new(CHROMIUM)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--no-first-run",
            &format!("--user-data-dir={}", profile.display()),
            &format!("--virtual-time-budget={budget_ms}"),
            "--dump-dom",
            url,
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("start chromium");
    let mut stdout = child.stdout.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut dom = String::new();
        stdout.read_to_string(&mut dom).map(|_| dom)
    });
    let deadline = Instant::now() + Duration::from_secs(90);
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!("chromium did not finish within 90 s");
        }
        std::thread::park_timeout(Duration::from_millis(50));
    };
    let dom = reader.join().unwrap().expect("chromium's output");
    let _ = std::fs::remove_dir_all(&profile);
    assert!(status.success(), "chromium: {status}");
    dom
}

/// The text of `<output id="ID">…</output>` in a dumped DOM.
fn output(dom: &str, id: &str) -> String {
    let open = format!("<output id=\"{id}\">");
    let start = dom
        .find(&open)
        .unwrap_or_else(|| panic!("no output #{id} in the DOM:\n{dom}"))
        + open.len();
    let end = dom[start..].find("</output>").unwrap() + start;
    dom[start..end].to_string()
}

/// The value of attribute `name` of the element opened by `tag` (e.g. `<canvas id="heat"`).
fn attribute(dom: &str, tag: &str, name: &str) -> String {
    let start = dom
        .find(tag)
        .unwrap_or_else(|| panic!("no {tag} in the DOM"));
    let element = &dom[start..start + dom[start..].find('>').unwrap()];
    let key = format!(" {name}=\"");
    let at = element
        .find(&key)
        .unwrap_or_else(|| panic!("no {name} in {element}"))
        + key.len();
    element[at..at + element[at..].find('"').unwrap()].to_string()
}

#[test]
fn headless_chromium_shows_the_deposited_blob_on_the_page() {
    // With the walls of `trail` (two 12 m × 0.1 m rectangles, 8 segments, inside this 20 m ×
    // 10 m field).
    let (name, _field, _view, port) = field_and_view("view-browser", &["--scenario", "trail"]);
    let walls = get_json(port, "/api/walls");
    let segments = walls["walls"].as_array().unwrap();
    assert_eq!(segments.len(), 8, "{walls}");
    // The lower edge of the upper wall, as the scenario gives it (metres).
    assert!(
        segments.iter().any(|w| w[1] == 4.9 && w[3] == 4.9),
        "{walls}"
    );
    let (x, y) = (6.05f32, 8.25f32);
    deposit_and_wait(&name, port, x, y, "");
    let value = probe(&name, x, y);

    let dom = dump_dom(&format!("http://127.0.0.1:{port}/"), 5000);
    let number = |id: &str| -> f64 {
        output(&dom, id)
            .parse()
            .unwrap_or_else(|e| panic!("#{id} = {:?}: {e}", output(&dom, id)))
    };
    assert!(number("frames-drawn") >= 1.0, "the page drew a frame");
    assert!(number("frame-seq") > 0.0);
    // What the page drew: the blob's value (to the 4 digits shown) at its place in metres.
    let shown = number("frame-max");
    assert!(
        (shown - value).abs() <= 1e-3 * value,
        "page max {shown}, field {value}"
    );
    assert!((number("hot-value") - value).abs() <= 1e-3 * value);
    assert!(
        (number("hot-x") - x as f64).abs() < 0.05,
        "hot-x {}",
        output(&dom, "hot-x")
    );
    assert!(
        (number("hot-y") - y as f64).abs() < 0.05,
        "hot-y {}",
        output(&dom, "hot-y")
    );
    // The canvas: full-precision values on its data- attributes, and the pixel under the blob
    // read back from it is the top colour of the automatic scale.
    let heat = "<canvas id=\"heat\"";
    let data_max: f64 = attribute(&dom, heat, "data-max").parse().unwrap();
    assert!(
        (data_max - value).abs() <= 1e-6 * value,
        "data-max {data_max}, field {value}"
    );
    let hot_x: f64 = attribute(&dom, heat, "data-hot-x-m").parse().unwrap();
    assert!((hot_x - x as f64).abs() < 1e-4);
    assert_eq!(attribute(&dom, heat, "data-hot-pixel"), "rgb(253, 231, 37)");
    assert_eq!(output(&dom, "hot-pixel"), "rgb(253, 231, 37)");
    // Live stats reached the page too.
    assert_eq!(output(&dom, "stat-applied"), "1");
    let hz = number("stat-tick-hz");
    assert!((35.0..65.0).contains(&hz), "page tick rate {hz}");
    assert_eq!(attribute(&dom, "<span id=\"status\"", "data-state"), "live");
    // The walls on the overlay, in the pictures' wall colour, and the colour bar's unit.
    let overlay = "<canvas id=\"overlay\"";
    assert_eq!(attribute(&dom, overlay, "data-walls"), "8");
    assert_eq!(
        attribute(&dom, overlay, "data-wall-pixel"),
        "rgb(215, 215, 215)"
    );
    assert!(
        dom.contains("<span id=\"bar-unit\">level (pheromone units)</span>"),
        "no unit on the colour bar"
    );
}

#[test]
fn sim_view_serves_the_runs_field_and_robots_while_it_runs() {
    let port = free_port();
    let listen = format!("127.0.0.1:{port}");
    let sim = Proc::spawn(&[
        "sim",
        "blind-leader",
        "--realtime",
        "--duration",
        "8",
        "--no-out",
        "--view",
        &listen,
    ]);
    let robots = eventually(
        Duration::from_secs(30),
        "the run's robots in the view",
        || {
            let (status, _, body) = request(port, "GET", "/api/robots").ok()?;
            let r: Value = serde_json::from_slice(&body).ok()?;
            let moving = r["robots"]
                .as_array()?
                .iter()
                .all(|t| t["path"].as_array().is_some_and(|p| p.len() >= 2));
            (status == 200 && r["robots"].as_array()?.len() == 2 && moving).then_some(r)
        },
    );
    let world = robots["world"].as_str().unwrap().to_string();
    let stats = eventually(
        Duration::from_secs(30),
        "the leader's deposits in the view",
        || {
            let s = get_json(port, "/api/stats");
            (s["deposits_applied"].as_u64()? > 0).then_some(s)
        },
    );
    // The view reads the run's field: named like its world, ticking once per 0.1 s step.
    assert_eq!(stats["field"].as_str(), Some(world.as_str()), "{stats}");
    let f = get_json(port, "/api/frame");
    assert!(f["max"].as_f64().unwrap() > 0.0, "the trail: {}", f["max"]);
    let out = sim.wait_exit(Duration::from_secs(60));
    assert!(out.status.success(), "sim: {}", stderr(&out));
    // The view stops with the run.
    assert!(
        request(port, "GET", "/api/stats").is_err(),
        "the view outlived the run"
    );
}
