//! The view before its field starts, after it dies, and with oversized requests.
//!
//! `/api/stats` says `waiting` (and `/api/frame` is a 503 with a JSON body saying so) until the
//! field starts, `live` while it ticks, and `stopped` soon after the field is killed; a request
//! target over the limit gets a 414 that does not repeat it, a long bad value a 400 that repeats
//! at most 32 characters of it.

use std::time::{Duration, Instant};

use super::*;

/// Kilobytes of the process's resident memory: (now, peak).
fn rss_kb(pid: u32) -> (u64, u64) {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap_or_default();
    let kb = |key: &str| {
        status
            .lines()
            .find_map(|l| l.strip_prefix(key))
            .and_then(|v| v.split_whitespace().next()?.parse().ok())
            .unwrap_or(0)
    };
    (kb("VmRSS:"), kb("VmHWM:"))
}

#[test]
fn the_view_says_waiting_before_the_field_and_stopped_after_it_dies() {
    let name = unique("view-state");
    let port = free_port();
    let listen = format!("127.0.0.1:{port}");
    let _view = Proc::spawn(&["view", "--field", &name, "--listen", &listen]);
    let stats = eventually(Duration::from_secs(30), "the view to answer", || {
        let (status, _, body) = request(port, "GET", "/api/stats").ok()?;
        (status == 200).then(|| serde_json::from_slice::<Value>(&body).unwrap())
    });
    assert_eq!(stats["state"], "waiting", "{stats}");
    assert_eq!(
        stats["status"],
        format!("waiting for field '{name}'"),
        "{stats}"
    );
    let (status, ctype, body) = get(port, "/api/frame");
    assert_eq!((status, ctype.as_str()), (503, "application/json"));
    let body: Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(body["state"], "waiting", "{body}");
    // The page says so, in words, without an error.
    let url = format!("http://127.0.0.1:{port}/");
    let status_of = |dom: &str| {
        let state = attribute(dom, "<span id=\"status\"", "data-state");
        let at = dom.find("<span id=\"status\"").unwrap();
        let text = &dom[at..];
        let text = &text[text.find('>').unwrap() + 1..text.find("</span>").unwrap()];
        (state, text.to_string())
    };
    let dom = dump_dom(&url, 1500);
    assert_eq!(
        status_of(&dom),
        ("waiting".to_string(), format!("waiting for field '{name}'"))
    );

    let field = Proc::spawn(&Cmd::field(&name).grid(50, 50).tick_hz(20).argv());
    let live = eventually(Duration::from_secs(30), "the view to see the field", || {
        let s = get_json(port, "/api/stats");
        (s["state"] == "live").then_some(s)
    });
    assert!(live["status"].as_str().unwrap().contains("frame"), "{live}");
    // The field dies: within a few periods and the next look at its process, `stopped`.
    field.kill();
    let killed = Instant::now();
    let stopped = eventually(Duration::from_secs(10), "the view to say stopped", || {
        let s = get_json(port, "/api/stats");
        (s["state"] == "stopped").then_some(s)
    });
    println!(
        "view: field SIGKILLed, 'stopped' after {:.0} ms: {}",
        killed.elapsed().as_secs_f64() * 1e3,
        stopped["status"]
    );
    assert_eq!(stopped["tick_hz"], 0.0, "{stopped}");
    assert!(
        stopped["status"].as_str().unwrap().contains("stopped"),
        "{stopped}"
    );
    // Its last frame is still served, and the page says the field stopped.
    assert_eq!(get(port, "/api/frame").0, 200);
    let (state, text) = status_of(&dump_dom(&url, 1500));
    assert_eq!(state, "stopped", "{text}");
    assert!(text.contains("stopped"), "{text}");
}

#[test]
fn oversized_requests_get_414_or_400_without_being_repeated() {
    let (_name, _field, view, port) = field_and_view("view-long", &[]);
    let before = rss_kb(view.pid());
    let huge = format!("/api/frame?channel={}", "7".repeat(32 << 20));
    let (status, _, body) = get(port, &huge);
    let after = rss_kb(view.pid());
    let body = String::from_utf8_lossy(&body).into_owned();
    assert_eq!(status, 414, "{}", &body[..body.len().min(200)]);
    assert!(body.len() < 200 && !body.contains("777"), "{body}");
    println!(
        "view: a 32 MiB query: RSS {} → {} kB (peak {} → {} kB), answered {status} in {} bytes",
        before.0,
        after.0,
        before.1,
        after.1,
        body.len()
    );
    // Read no further than its first 4 KiB: the view's memory does not grow with it.
    assert!(
        after.1.saturating_sub(before.1) < 8 * 1024,
        "peak RSS {} → {} kB",
        before.1,
        after.1
    );
    let long_value = format!("/api/frame?channel={}", "x".repeat(1500));
    let (status, text) = get_text(port, &long_value);
    assert_eq!(status, 400);
    assert_eq!(
        text,
        format!("channel={}…: not a non-negative integer", "x".repeat(32))
    );
    // The view goes on serving.
    assert_eq!(get(port, "/api/frame?max_side=8").0, 200);
}
