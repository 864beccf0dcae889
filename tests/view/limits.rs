//! Slow clients against the view (issue 54, item 8): a flood of connections that send their
//! request head a byte at a time, or never read their answer, must not starve a client that
//! asks and reads at once; and the view stops on SIGTERM while they hang on.

use std::net::Shutdown;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;

use super::*;

/// More connections than the view keeps open at once (`pheromone_view::http::MAX_CONNECTIONS`).
const SLOW_CLIENTS: usize = 160;

/// Keeps `SLOW_CLIENTS` connections open that have sent only the start of a request line,
/// opening a new one whenever the view closes one (as a slowloris client does), until `stop`.
/// Counts the connections it opened.
fn slowloris(port: u16, stop: Arc<AtomicBool>, opened: Arc<AtomicUsize>) {
    let open = || -> Option<TcpStream> {
        let mut s = TcpStream::connect(("127.0.0.1", port)).ok()?;
        s.write_all(b"GET /api/stats HT").ok()?;
        s.set_nonblocking(true).ok()?;
        opened.fetch_add(1, Ordering::Relaxed);
        Some(s)
    };
    let mut conns: Vec<Option<TcpStream>> = (0..SLOW_CLIENTS).map(|_| open()).collect();
    let mut buf = [0u8; 512];
    while !stop.load(Ordering::Relaxed) {
        for c in conns.iter_mut() {
            let closed = match c {
                None => true,
                // Closed by the view (0 bytes, or a reset), or answered (which it must not be).
                Some(s) => {
                    !matches!(s.read(&mut buf), Err(e) if e.kind() == std::io::ErrorKind::WouldBlock)
                }
            };
            if closed {
                *c = open();
            }
        }
        std::thread::yield_now();
    }
}

/// GET `path`, retrying a connection the view closed before answering (a flood's eviction may
/// hit it); the status and how many tries it took.
fn get_with_retries(port: u16, path: &str, deadline: Instant) -> (u16, u32) {
    let mut tries = 0;
    loop {
        tries += 1;
        match request(port, "GET", path) {
            Ok((status, _, _)) => return (status, tries),
            Err(e) => assert!(
                Instant::now() < deadline,
                "GET {path}: no answer by the deadline ({tries} tries, last: {e})"
            ),
        }
    }
}

#[test]
fn a_flood_of_slow_request_heads_does_not_starve_a_client_that_asks_at_once() {
    let (_name, _field, _view, port) = field_and_view("view-slowloris", &[]);
    let stop = Arc::new(AtomicBool::new(false));
    let opened = Arc::new(AtomicUsize::new(0));
    let flood = {
        let (stop, opened) = (stop.clone(), opened.clone());
        std::thread::spawn(move || slowloris(port, stop, opened))
    };
    eventually(Duration::from_secs(20), "the flood's connections", || {
        (opened.load(Ordering::Relaxed) >= SLOW_CLIENTS).then_some(())
    });
    let deadline = Instant::now() + Duration::from_secs(60);
    let mut statuses = Vec::new();
    let mut retries = 0;
    for _ in 0..20 {
        let (status, tries) = get_with_retries(port, "/api/stats", deadline);
        statuses.push(status);
        retries += tries - 1;
    }
    stop.store(true, Ordering::Relaxed);
    flood.join().unwrap();
    eprintln!(
        "20 requests beside {} slow connections: {retries} retried",
        opened.load(Ordering::Relaxed)
    );
    assert!(
        statuses.iter().all(|&s| s == 200),
        "each request is answered 200 beside the flood: {statuses:?}"
    );
    // A connection of ours is closed only when 64 newer ones arrive before the view has read
    // its head (the flood reconnects at once): rare, not the rule. Before the connection limit
    // closed the oldest, 20 requests took 130,799 tries (the slots stayed full of slow heads).
    assert!(
        retries <= 20,
        "20 requests took {} tries beside the flood: at least one answer in two tries expected",
        20 + retries
    );
}

/// Sends `GET path` and never reads the answer.
fn ask_and_never_read(port: u16, path: &str) -> TcpStream {
    let mut s = TcpStream::connect(("127.0.0.1", port)).expect("connect");
    write!(s, "GET {path} HTTP/1.0\r\n\r\n").expect("send");
    s
}

#[test]
fn clients_that_never_read_their_big_answers_do_not_hold_up_the_others() {
    // 2048² cells as JSON (several MB each): more than the kernel buffers a connection.
    let name = unique("view-slowread");
    let _field = Proc::spawn(
        &Cmd::field(&name)
            .grid(2048, 2048)
            .cell_size(0.01)
            .model("none")
            .tick_hz(20)
            .argv(),
    );
    let (_view, port) = view_on(&name, &[]);
    let big = "/api/frame?max_side=2048";
    let stuck: Vec<TcpStream> = (0..6).map(|_| ask_and_never_read(port, big)).collect();
    let deadline = Instant::now() + Duration::from_secs(60);
    for _ in 0..5 {
        let (status, _) = get_with_retries(port, "/api/stats", deadline);
        assert_eq!(status, 200, "/api/stats beside clients that never read");
    }
    // A whole big frame still arrives for a client that reads it.
    let (status, _, body) = get(port, big);
    assert_eq!(status, 200);
    let frame: Value = serde_json::from_slice(&body).expect("the frame is JSON");
    let cells = frame["cells"].as_array().map_or(0, Vec::len);
    assert_eq!(cells, 2048 * 2048, "the whole frame's cells");
    drop(stuck);
}

#[test]
fn the_view_stops_on_sigterm_while_slow_clients_hang_on() {
    let (_name, _field, mut view, port) = field_and_view("view-term", &[]);
    let mut slow = Vec::new();
    for _ in 0..20 {
        let mut s = TcpStream::connect(("127.0.0.1", port)).expect("connect");
        s.write_all(b"GET /api/st").expect("send");
        slow.push(s);
    }
    // One mid-answer too: asked, never read.
    slow.push(ask_and_never_read(port, "/api/frame?max_side=4096"));
    view.terminate();
    assert!(
        !view.runs_after(Duration::from_secs(10)),
        "the view still runs 10 s after SIGTERM"
    );
    for s in &slow {
        let _ = s.shutdown(Shutdown::Both);
    }
}
