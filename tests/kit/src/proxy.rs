//! A fault-injecting TCP proxy for the tests (threads and `std::net`): each connection it
//! accepts is forwarded to `upstream`, both directions held back by a one-way delay plus a
//! uniform jitter; "loss" is modelled as TCP presents it to the application: a chunk chosen
//! with probability `loss` arrives one retransmission timeout (`rto`) later, and every chunk
//! behind it waits too (order is kept, nothing is dropped).

use std::io::{Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{mpsc, Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// What the proxy does to the bytes it forwards.
#[derive(Debug, Clone, Copy)]
pub struct Faults {
    pub delay: Duration,
    /// Each chunk waits `delay` plus a uniform `[0, jitter)` (never overtaking the one before).
    pub jitter: Duration,
    /// Probability that a chunk is "lost" and retransmitted `rto` later.
    pub loss: f64,
    pub rto: Duration,
    pub seed: u64,
}

#[derive(Default)]
struct Shared {
    stop: AtomicBool,
    bytes: AtomicU64,
    /// Every socket, shut down on drop (which ends the threads blocked reading them).
    sockets: Mutex<Vec<TcpStream>>,
    threads: Mutex<Vec<JoinHandle<()>>>,
}

/// The proxy: listens on a loopback port of its own until dropped.
pub struct FaultyProxy {
    addr: SocketAddr,
    shared: Arc<Shared>,
    accept: Option<JoinHandle<()>>,
}

/// xorshift64*: a uniform number in [0, 1).
fn uniform(state: &mut u64) -> f64 {
    *state ^= *state >> 12;
    *state ^= *state << 25;
    *state ^= *state >> 27;
    (state.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
}

impl FaultyProxy {
    pub fn start(upstream: SocketAddr, faults: Faults) -> std::io::Result<Self> {
        let listener = TcpListener::bind("127.0.0.1:0")?;
        let addr = listener.local_addr()?;
        let shared = Arc::new(Shared::default());
        let s = shared.clone();
        let accept = std::thread::spawn(move || {
            let mut seed = faults.seed | 1;
            for client in listener.incoming() {
                if s.stop.load(Ordering::SeqCst) {
                    return;
                }
                let (Ok(client), Ok(server)) = (client, TcpStream::connect(upstream)) else {
                    continue;
                };
                for (from, to) in [(&client, &server), (&server, &client)] {
                    seed = seed.wrapping_add(0x9E37_79B9_7F4A_7C15);
                    let f = Faults { seed, ..faults };
                    forward(&s, from, to, f);
                }
                s.sockets.lock().unwrap().extend([client, server]);
            }
        });
        Ok(Self {
            addr,
            shared,
            accept: Some(accept),
        })
    }

    /// The address to connect to instead of `upstream`.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// Bytes forwarded so far, both directions.
    pub fn bytes(&self) -> u64 {
        self.shared.bytes.load(Ordering::Relaxed)
    }
}

/// One direction: a reader thread stamps each chunk with the time it may leave, a writer thread
/// sends it then.
fn forward(s: &Arc<Shared>, from: &TcpStream, to: &TcpStream, f: Faults) {
    let (Ok(mut from), Ok(mut to)) = (from.try_clone(), to.try_clone()) else {
        return;
    };
    let (tx, rx) = mpsc::channel::<(Instant, Vec<u8>)>();
    let reader = std::thread::spawn(move || {
        let (mut rng, mut last) = (f.seed, Instant::now());
        let mut buf = vec![0u8; 64 * 1024];
        while let Ok(n @ 1..) = from.read(&mut buf) {
            let mut due = Instant::now() + f.delay + f.jitter.mul_f64(uniform(&mut rng));
            if uniform(&mut rng) < f.loss {
                due += f.rto;
            }
            last = last.max(due);
            if tx.send((last, buf[..n].to_vec())).is_err() {
                return;
            }
        }
    });
    let shared = s.clone();
    let writer = std::thread::spawn(move || {
        for (due, chunk) in rx {
            // The chunk's time in flight (the fault itself, not a wait for a condition).
            std::thread::sleep(due.saturating_duration_since(Instant::now()));
            if to.write_all(&chunk).is_err() {
                return;
            }
            shared
                .bytes
                .fetch_add(chunk.len() as u64, Ordering::Relaxed);
        }
        let _ = to.shutdown(Shutdown::Write);
    });
    s.threads.lock().unwrap().extend([reader, writer]);
}

impl Drop for FaultyProxy {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::SeqCst);
        // Wakes the accept loop, which sees `stop`.
        let _ = TcpStream::connect(self.addr);
        if let Some(a) = self.accept.take() {
            let _ = a.join();
        }
        for sock in self.shared.sockets.lock().unwrap().drain(..) {
            let _ = sock.shutdown(Shutdown::Both);
        }
        let threads: Vec<_> = self.shared.threads.lock().unwrap().drain(..).collect();
        for t in threads {
            let _ = t.join();
        }
    }
}
