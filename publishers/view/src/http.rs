//! The view's HTTP/1.x server: GET and HEAD, no request bodies, one request per connection
//! (`Connection: close`). Each connection lives on a thread of its own, with bounds — the
//! request line [`MAX_LINE`] bytes, the whole head [`MAX_HEAD`] — so an oversized request costs
//! no more memory than that: a request line over the bound is answered 414 and a head over it
//! 431 as soon as the bound is reached, without repeating anything of it, and the rest of what
//! the client sends is read and dropped. The requests that fit go to the view's loop
//! ([`Server::recv_timeout`]), which computes the answer and hands it back to the connection's
//! thread to write: the loop never waits on a client.
//!
//! **Slow clients.** At most [`MAX_CONNECTIONS`] connections are open at once. A new one beyond
//! that closes the oldest (whatever it is doing: sending its head slowly, or reading its answer
//! slowly), so a flood of slow connections costs each its place in turn and a client that
//! sends its request at once is served. A client has [`HEAD_TIMEOUT`] to send its head and
//! [`WRITE_TIMEOUT`] for each write of its answer to make progress.

use std::collections::BTreeMap;
use std::io::{ErrorKind, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::{mpsc, Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

/// The longest request line read (method, target, version).
pub const MAX_LINE: usize = 4096;
/// The longest request head read (request line and headers).
pub const MAX_HEAD: usize = 16 * 1024;
/// Connections open at once; a new one beyond closes the oldest.
pub const MAX_CONNECTIONS: usize = 64;
/// How long a client may take to send its head.
pub const HEAD_TIMEOUT: Duration = Duration::from_secs(5);
/// How long one write of an answer may wait for the client to read.
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(5);
/// How long a connection waits for the view's loop to answer its request.
const ANSWER_TIMEOUT: Duration = Duration::from_secs(30);
/// A connection's thread: it reads a head and writes an answer, nothing deep.
const THREAD_STACK_BYTES: usize = 256 * 1024;
/// After an error answer: how long, and how much, of the rest is read and dropped (closing with
/// unread data would reset the connection before the client reads the answer).
const DRAIN_TIMEOUT: Duration = Duration::from_secs(2);
const DRAIN_BYTES: u64 = 256 << 20;

/// An answer the view's loop hands back to the connection's thread.
struct Answer {
    status: u16,
    headers: Vec<(&'static str, &'static str)>,
    body: Vec<u8>,
}

/// A request whose head fitted: its method and target, and the way back to its connection.
pub struct Request {
    pub method: String,
    pub target: String,
    answer: mpsc::SyncSender<Answer>,
}

impl Request {
    /// Answers with `status`, the headers and `body` (not sent for HEAD): the connection's own
    /// thread writes it and closes, so a client that reads slowly holds up nobody else.
    pub fn respond(self, status: u16, headers: &[(&'static str, &'static str)], body: Vec<u8>) {
        // A connection closed meanwhile (evicted, timed out) has nobody to answer.
        let _ = self.answer.send(Answer {
            status,
            headers: headers.to_vec(),
            body,
        });
    }
}

/// The open connections, oldest first (ids grow), each with a handle to close it.
#[derive(Default)]
struct Connections {
    next_id: u64,
    open: BTreeMap<u64, TcpStream>,
}

impl Connections {
    /// Registers `stream`; beyond [`MAX_CONNECTIONS`], closes the oldest first.
    fn admit(&mut self, stream: &TcpStream) -> Option<u64> {
        while self.open.len() >= MAX_CONNECTIONS {
            let (_, oldest) = self.open.pop_first()?;
            // Its thread's read or write fails at once, and it ends.
            let _ = oldest.shutdown(Shutdown::Both);
        }
        let handle = stream.try_clone().ok()?;
        let id = self.next_id;
        self.next_id += 1;
        self.open.insert(id, handle);
        Some(id)
    }
}

type Shared = Arc<Mutex<Connections>>;

fn lock(c: &Shared) -> std::sync::MutexGuard<'_, Connections> {
    // The map stays consistent whatever a panicking holder did: insert and remove only.
    c.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The listening side: requests arrive from the connections' threads.
pub struct Server {
    requests: mpsc::Receiver<Request>,
    local: SocketAddr,
}

impl Server {
    /// Listens on `address` (port 0: any free one) and starts accepting.
    pub fn bind(address: &str) -> std::io::Result<Server> {
        let listener = TcpListener::bind(address)?;
        let local = listener.local_addr()?;
        let (tx, requests) = mpsc::channel();
        std::thread::Builder::new()
            .name("view-accept".into())
            .spawn(move || accept(listener, tx))?;
        Ok(Server { requests, local })
    }

    pub fn local_addr(&self) -> SocketAddr {
        self.local
    }

    /// The next request, waiting up to `timeout`.
    pub fn recv_timeout(&self, timeout: Duration) -> Option<Request> {
        self.requests.recv_timeout(timeout).ok()
    }
}

/// Accepts connections for as long as the process runs; each lives on its own thread.
fn accept(listener: TcpListener, tx: mpsc::Sender<Request>) {
    let connections = Shared::default();
    for stream in listener.incoming() {
        let Ok(stream) = stream else { continue };
        let Some(id) = lock(&connections).admit(&stream) else {
            continue;
        };
        let (tx, conns) = (tx.clone(), connections.clone());
        let spawned = std::thread::Builder::new()
            .name("view-conn".into())
            .stack_size(THREAD_STACK_BYTES)
            .spawn(move || {
                serve_connection(stream, &tx);
                lock(&conns).open.remove(&id);
            });
        if spawned.is_err() {
            // The stream went with the failed spawn (closed); forget its handle.
            lock(&connections).open.remove(&id);
            eprintln!("view: cannot start a thread for a connection");
        }
    }
}

/// One connection: its head, then the view's answer (or a refusal), then close.
fn serve_connection(mut stream: TcpStream, tx: &mpsc::Sender<Request>) {
    match read_head(&mut stream) {
        Ok((method, target)) => {
            let head_only = method == "HEAD";
            let (answer, answered) = mpsc::sync_channel(1);
            let request = Request {
                method,
                target,
                answer,
            };
            if tx.send(request).is_err() {
                return; // the view is stopping
            }
            let Ok(a) = answered.recv_timeout(ANSWER_TIMEOUT) else {
                return;
            };
            if stream.set_write_timeout(Some(WRITE_TIMEOUT)).is_ok() {
                // A client that went away mid-answer is no failure of the view.
                let _ = write_response(&mut stream, a.status, &a.headers, &a.body, head_only);
            }
            let _ = stream.shutdown(Shutdown::Write);
        }
        Err(Some((status, text))) => refuse(stream, status, text),
        Err(None) => {}
    }
}

/// The method and target of the request on `stream`; `Err(Some(..))`: the answer to refuse it
/// with; `Err(None)`: the client went away or was too slow.
fn read_head(stream: &mut TcpStream) -> Result<(String, String), Option<(u16, &'static str)>> {
    let deadline = Instant::now() + HEAD_TIMEOUT;
    let mut head: Vec<u8> = Vec::with_capacity(1024);
    let mut buf = [0u8; 4096];
    let line_end = loop {
        if let Some(at) = find(&head, b"\r\n") {
            break at;
        }
        if head.len() > MAX_LINE {
            return Err(Some((414, "request line too long")));
        }
        read_some(stream, &mut buf, &mut head, deadline)?;
    };
    if line_end > MAX_LINE {
        return Err(Some((414, "request line too long")));
    }
    while find(&head, b"\r\n\r\n").is_none() {
        if head.len() > MAX_HEAD {
            return Err(Some((431, "request header fields too large")));
        }
        read_some(stream, &mut buf, &mut head, deadline)?;
    }
    let line = std::str::from_utf8(&head[..line_end]).map_err(|_| Some((400, "bad request")))?;
    let mut parts = line.split(' ');
    match (parts.next(), parts.next(), parts.next(), parts.next()) {
        (Some(m), Some(t), Some(v), None) if !m.is_empty() && v.starts_with("HTTP/1.") => {
            Ok((m.to_string(), t.to_string()))
        }
        _ => Err(Some((400, "bad request line"))),
    }
}

/// Reads what has arrived into `head`.
fn read_some(
    stream: &mut TcpStream,
    buf: &mut [u8],
    head: &mut Vec<u8>,
    deadline: Instant,
) -> Result<(), Option<(u16, &'static str)>> {
    let left = deadline.saturating_duration_since(Instant::now());
    if left.is_zero() || stream.set_read_timeout(Some(left)).is_err() {
        return Err(None);
    }
    match stream.read(buf) {
        Ok(0) => Err(None),
        Ok(n) => {
            head.extend_from_slice(&buf[..n]);
            Ok(())
        }
        Err(e) if e.kind() == ErrorKind::Interrupted => Ok(()),
        Err(_) => Err(None),
    }
}

/// Answers `status` with `text`, then reads and drops the rest the client sends (bounded).
fn refuse(mut stream: TcpStream, status: u16, text: &str) {
    let _ = stream.set_write_timeout(Some(WRITE_TIMEOUT));
    let _ = write_response(&mut stream, status, &[], text.as_bytes(), false);
    let _ = stream.shutdown(Shutdown::Write);
    let _ = stream.set_read_timeout(Some(DRAIN_TIMEOUT));
    let _ = std::io::copy(&mut (&stream).take(DRAIN_BYTES), &mut std::io::sink());
}

fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

fn reason(status: u16) -> &'static str {
    match status {
        200 => "OK",
        400 => "Bad Request",
        404 => "Not Found",
        405 => "Method Not Allowed",
        414 => "URI Too Long",
        431 => "Request Header Fields Too Large",
        500 => "Internal Server Error",
        503 => "Service Unavailable",
        _ => "",
    }
}

/// Writes a whole response: status line, `Content-Length`, `Connection: close`, the headers
/// given (plain text when they name no `Content-Type`), the body unless `head_only`.
fn write_response(
    stream: &mut TcpStream,
    status: u16,
    headers: &[(&str, &str)],
    body: &[u8],
    head_only: bool,
) -> std::io::Result<()> {
    let mut out = format!("HTTP/1.1 {status} {}\r\n", reason(status));
    if !headers
        .iter()
        .any(|(k, _)| k.eq_ignore_ascii_case("content-type"))
    {
        out.push_str("Content-Type: text/plain; charset=utf-8\r\n");
    }
    for (k, v) in headers {
        out.push_str(&format!("{k}: {v}\r\n"));
    }
    out.push_str(&format!(
        "Content-Length: {}\r\nConnection: close\r\n\r\n",
        body.len()
    ));
    stream.write_all(out.as_bytes())?;
    if !head_only {
        stream.write_all(body)?;
    }
    stream.flush()
}
