//! Frame delivery: the field publishes a frame, N reader processes hold it. Ours (the field's
//! shared-memory frame, lent without a copy) against the same f32 plane serialized with serde
//! (postcard) over a Unix domain socket and, with the `zenoh` feature, sent over Zenoh on
//! loopback. Each reader records (time it holds the frame − the frame's publish stamp).

use std::io::{Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::time::Duration;

use iceoryx2::prelude::*;
use pheromone_field::shm::{create_node, now_ns, FieldReader, FieldServer, Svc};
use pheromone_field::{ChannelSpec, Evaporation, FieldConfig};
use serde::{Deserialize, Serialize};

use crate::frame_run::{drive, pause, record, spawn_readers, test_plane, FRAME_TIMEOUT};
pub use crate::frame_run::{FrameRun, FrameSamples};
use crate::peer::{say_ready, FrameTransport, Launcher, ReaderWait};
use crate::BenchError;

/// The plane on the socket, as sent.
#[derive(Serialize)]
struct PlaneRef<'a> {
    stamp_ns: u64,
    sequence: u64,
    width: u32,
    height: u32,
    cells: &'a [f32],
}

/// The plane on the socket, as received (deserialized into an owned Vec).
#[derive(Deserialize)]
struct PlaneMsg {
    stamp_ns: u64,
    #[allow(dead_code)]
    sequence: u64,
    width: u32,
    height: u32,
    cells: Vec<f32>,
}

fn io(what: impl Into<String>) -> impl FnOnce(std::io::Error) -> BenchError {
    let what = what.into();
    move |source| BenchError::Io { what, source }
}

fn field_config(width: u32, readers: usize) -> FieldConfig {
    FieldConfig {
        width,
        height: width,
        max_readers: readers,
        channels: vec![ChannelSpec::new(
            "trail",
            Evaporation::Exponential {
                decay_per_s: 0.0057,
            },
        )],
        ..FieldConfig::default()
    }
}

/// Runs one frame-delivery measurement; returns every reader's latencies (ns), pooled, and the
/// readers' CPU share.
pub fn measure(launcher: &Launcher, tag: &str, run: FrameRun) -> Result<FrameSamples, BenchError> {
    let node = create_node(&format!("bench-frames-{tag}"))?;
    match run.transport {
        // The same field for the Rust reader and libpheromone's C reader (issue 29).
        FrameTransport::Ours | FrameTransport::CAbi => {
            let name = format!("bench-{tag}");
            let mut server =
                FieldServer::start(&node, &name, field_config(run.width, run.readers), None)?;
            let mut peers = spawn_readers(launcher, &run, &name)?;
            drive(&node, &mut peers, &run, || {
                server.tick()?;
                Ok(())
            })
        }
        FrameTransport::UdsSerde => {
            // A private directory of its own (0700, removed when dropped): nobody else can
            // plant or squat the socket's name.
            let dir = tempfile::Builder::new()
                .prefix("pheromone-bench-")
                .tempdir()
                .map_err(io("create the socket's directory"))?;
            let path = dir.path().join(format!("{tag}.sock"));
            let listener =
                UnixListener::bind(&path).map_err(io(format!("bind {}", path.display())))?;
            let source = path.to_string_lossy().into_owned();
            let mut peers = spawn_readers(launcher, &run, &source)?;
            let mut streams = Vec::with_capacity(run.readers);
            for _ in 0..run.readers {
                // Every reader connected before it said ready, so accept does not block.
                let (s, _) = listener.accept().map_err(io("accept a reader"))?;
                streams.push(Some(s));
            }
            let mut cells = test_plane(run.width);
            let mut sequence = 0u64;
            drive(&node, &mut peers, &run, || {
                sequence += 1;
                let n = cells.len();
                cells[sequence as usize % n] += 1.0;
                let plane = PlaneRef {
                    stamp_ns: now_ns(),
                    sequence,
                    width: run.width,
                    height: run.width,
                    cells: &cells,
                };
                let bytes = postcard::to_allocvec(&plane)
                    .map_err(|e| BenchError::Peer(format!("postcard: {e}")))?;
                for slot in streams.iter_mut() {
                    if let Some(s) = slot {
                        let sent = s
                            .write_all(&(bytes.len() as u64).to_le_bytes())
                            .and_then(|_| s.write_all(&bytes));
                        if sent.is_err() {
                            // The reader has what it needs and left.
                            *slot = None;
                        }
                    }
                }
                Ok(())
            })
        }
        FrameTransport::Zenoh => zenoh_side::measure(&node, launcher, tag, &run),
        FrameTransport::RawIceoryx => crate::raw_frames::measure(&node, launcher, tag, &run),
    }
}

/// The reader process.
pub fn read(
    transport: FrameTransport,
    source: &str,
    wait: ReaderWait,
    skip: usize,
    count: usize,
) -> Result<(), BenchError> {
    match transport {
        FrameTransport::Ours => {
            let node = create_node(&format!("bench-reader-{}", std::process::id()))?;
            let mut reader = FieldReader::attach_within(&node, source, Duration::from_secs(10))?;
            let mut last = reader.frame().map(|f| f.header.sequence).unwrap_or(0);
            say_ready();
            let (mut previous_ns, mut last_ns) = (0, 0);
            record(skip, count, || {
                pause(&node, wait.pause_after(previous_ns, last_ns, now_ns()))?;
                let fresh = reader.wait_frame_with(wait.policy(), FRAME_TIMEOUT)?;
                let now = now_ns();
                if !fresh {
                    return Err(BenchError::Peer(format!(
                        "no frame from field '{source}' within {FRAME_TIMEOUT:?}"
                    )));
                }
                let frame = reader.frame().expect("a fresh frame is held");
                if frame.header.sequence == last {
                    return Ok(None);
                }
                last = frame.header.sequence;
                (previous_ns, last_ns) = (last_ns, frame.header.stamp_ns);
                Ok(Some(now.saturating_sub(frame.header.stamp_ns)))
            })
        }
        FrameTransport::UdsSerde => {
            let mut stream =
                UnixStream::connect(source).map_err(io(format!("connect to {source}")))?;
            stream
                .set_read_timeout(Some(FRAME_TIMEOUT))
                .map_err(io("set the socket timeout"))?;
            say_ready();
            let mut buf = Vec::new();
            record(skip, count, || {
                let mut len = [0u8; 8];
                stream
                    .read_exact(&mut len)
                    .map_err(io("read a frame length"))?;
                buf.resize(u64::from_le_bytes(len) as usize, 0);
                stream.read_exact(&mut buf).map_err(io("read a frame"))?;
                let plane: PlaneMsg = postcard::from_bytes(&buf)
                    .map_err(|e| BenchError::Peer(format!("postcard: {e}")))?;
                let now = now_ns();
                if plane.cells.len() != plane.width as usize * plane.height as usize {
                    return Err(BenchError::Peer("a frame arrived truncated".into()));
                }
                Ok(Some(now.saturating_sub(plane.stamp_ns)))
            })
        }
        FrameTransport::Zenoh => zenoh_side::read(source, skip, count),
        FrameTransport::RawIceoryx => crate::raw_frames::read(source, wait, skip, count),
        FrameTransport::CAbi => Err(BenchError::Peer(
            "the C reader is c_abi::read (frames reads the other transports)".into(),
        )),
    }
}

#[cfg(feature = "zenoh")]
mod zenoh_side {
    use super::*;
    use zenoh::qos::CongestionControl;
    use zenoh::Wait;

    fn zerr(what: &str, e: impl std::fmt::Display) -> BenchError {
        BenchError::Zenoh(format!("{what}: {e}"))
    }

    /// Loopback only: no multicast scouting, no gossip, no listening beyond 127.0.0.1.
    fn config(
        mode: &str,
        listen: &[String],
        connect: &[String],
    ) -> Result<zenoh::Config, BenchError> {
        let mut c = zenoh::Config::default();
        let set = |c: &mut zenoh::Config, k: &str, v: String| {
            c.insert_json5(k, &v)
                .map_err(|e| zerr(&format!("config {k}"), e))
        };
        set(&mut c, "mode", format!("\"{mode}\""))?;
        set(&mut c, "scouting/multicast/enabled", "false".into())?;
        set(&mut c, "scouting/gossip/enabled", "false".into())?;
        set(
            &mut c,
            "listen/endpoints",
            serde_json::to_string(listen).expect("strings"),
        )?;
        set(
            &mut c,
            "connect/endpoints",
            serde_json::to_string(connect).expect("strings"),
        )?;
        Ok(c)
    }

    fn free_port() -> Result<u16, BenchError> {
        let l = std::net::TcpListener::bind("127.0.0.1:0").map_err(io("find a free port"))?;
        Ok(l.local_addr().map_err(io("find a free port"))?.port())
    }

    pub fn measure(
        node: &Node<Svc>,
        launcher: &Launcher,
        tag: &str,
        run: &FrameRun,
    ) -> Result<FrameSamples, BenchError> {
        let endpoint = format!("tcp/127.0.0.1:{}", free_port()?);
        let key = format!("pheromone/bench/{tag}/frame");
        let session = zenoh::open(config("peer", std::slice::from_ref(&endpoint), &[])?)
            .wait()
            .map_err(|e| zerr("open the publishing session", e))?;
        let publisher = session
            .declare_publisher(key.clone())
            .congestion_control(CongestionControl::Block)
            .wait()
            .map_err(|e| zerr("declare the publisher", e))?;
        let mut peers = spawn_readers(launcher, run, &format!("{endpoint}#{key}"))?;
        let mut cells = test_plane(run.width);
        let mut sequence = 0u64;
        let samples = drive(node, &mut peers, run, || {
            sequence += 1;
            let n = cells.len();
            cells[sequence as usize % n] += 1.0;
            let stamp = now_ns();
            let mut bytes = Vec::with_capacity(8 + 4 * n);
            bytes.extend_from_slice(&stamp.to_le_bytes());
            for c in &cells {
                bytes.extend_from_slice(&c.to_le_bytes());
            }
            publisher.put(bytes).wait().map_err(|e| zerr("put", e))
        });
        drop(publisher);
        // The samples are in; a session that fails to close ends with the process.
        let _ = session.close().wait();
        samples
    }

    pub fn read(source: &str, skip: usize, count: usize) -> Result<(), BenchError> {
        let (endpoint, key) = source
            .split_once('#')
            .ok_or_else(|| BenchError::Zenoh(format!("bad zenoh source '{source}'")))?;
        let session = zenoh::open(config("client", &[], &[endpoint.to_string()])?)
            .wait()
            .map_err(|e| zerr("open the reading session", e))?;
        let subscriber = session
            .declare_subscriber(key)
            .wait()
            .map_err(|e| zerr("declare the subscriber", e))?;
        say_ready();
        record(skip, count, || {
            let sample = subscriber
                .recv_timeout(FRAME_TIMEOUT)
                .map_err(|e| zerr("receive", e))?
                .ok_or_else(|| BenchError::Zenoh(format!("no frame within {FRAME_TIMEOUT:?}")))?;
            let bytes = sample.payload().to_bytes();
            if bytes.len() < 8 {
                return Err(BenchError::Zenoh("a frame arrived truncated".into()));
            }
            let stamp = u64::from_le_bytes(bytes[..8].try_into().expect("8 bytes"));
            let cells: Vec<f32> = bytes[8..]
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes(b.try_into().expect("4 bytes")))
                .collect();
            let now = now_ns();
            std::hint::black_box(&cells);
            Ok(Some(now.saturating_sub(stamp)))
        })
    }
}

#[cfg(not(feature = "zenoh"))]
mod zenoh_side {
    use super::*;

    pub fn measure(
        _node: &Node<Svc>,
        _launcher: &Launcher,
        _tag: &str,
        _run: &FrameRun,
    ) -> Result<FrameSamples, BenchError> {
        Err(BenchError::NoZenoh)
    }

    pub fn read(_source: &str, _skip: usize, _count: usize) -> Result<(), BenchError> {
        Err(BenchError::NoZenoh)
    }
}
