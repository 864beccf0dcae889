//! Issue 29: libpheromone's C reader against the Rust `FieldReader`, in the same run.
//!
//! - Frame latency: a 1 MiB field ticking every 20 ms in this process, one reader process
//!   waiting on the frame event, from the frame's publish stamp to "the reader holds it" — the
//!   Rust reader once `wait_frame_with` returns, the C reader once `pheromone_wait_frame` and
//!   `pheromone_frame_borrow` have returned (it then has the plane pointers). The two readers
//!   alternate in `rounds` runs each, so drift on the machine touches both alike.
//! - Sampling cost: value + gradient at the same points of the same frame in this process,
//!   through `FrameView` on the Rust reader's frame, through `pheromone_sample_value` /
//!   `pheromone_sample_gradient` on the C handle's borrowed frame (two calls per point), and
//!   through one `pheromone_sample_many` call for all the points (issue 47's batch); the median
//!   over repetitions of the time per point, the three alternated.
//!
//! The C functions are called through their `extern "C"` symbols (libpheromone linked as an
//! rlib): the same code a C program runs, without a C compiler at bench time.
#![allow(unsafe_code)]

use std::ffi::CString;
use std::hint::black_box;
use std::time::{Duration, Instant};

use pheromone_c::{
    pheromone_field_attach, pheromone_field_detach, pheromone_frame_borrow,
    pheromone_frame_release, pheromone_last_error, pheromone_sample_gradient,
    pheromone_sample_many, pheromone_sample_value, pheromone_wait_frame, PheromoneAttachOptions,
    PheromoneField, PheromoneFrameView, PheromoneStatus, PheromoneWaitPolicy,
    PHEROMONE_MAX_CHANNELS, PHEROMONE_WAIT_BUSY_POLL, PHEROMONE_WAIT_EVENT, PHEROMONE_WAIT_SPIN,
};
use pheromone_field::shm::{create_node, now_ns, DepositPublisher, FieldReader, FieldServer};
use pheromone_field::{ChannelSpec, DepositMsg, Evaporation, FieldConfig};
use pheromone_field::{Deposit, Kernel};
use serde::Serialize;

use crate::frame_run::{record, FRAME_TIMEOUT};
use crate::frames::{self, FrameRun};
use crate::peer::{say_ready, FrameTransport, Launcher, ReaderWait};
use crate::{BenchError, Latency};

/// One C-vs-Rust measurement.
#[derive(Debug, Clone, Copy)]
pub struct CAbiRun {
    pub width: u32,
    /// Frames each reader records per round (after `skip`).
    pub count: usize,
    pub skip: usize,
    /// Rounds of (Rust reader, C reader).
    pub rounds: usize,
    /// Points sampled per repetition, and repetitions.
    pub points: usize,
    pub reps: usize,
    pub pin: bool,
}

/// What `pheromone bench` reports for issue 29.
#[derive(Debug, Clone, Serialize)]
pub struct CAbiReport {
    pub width: u32,
    pub frame_bytes: u64,
    /// Frame latency, ns: the Rust reader and the C reader.
    pub frame_rust_ns: Latency,
    pub frame_c_ns: Latency,
    /// C / Rust at p50 and p99 (goal ≤ 1.1).
    pub frame_ratio_p50: f64,
    pub frame_ratio_p99: f64,
    /// ns per point for value + gradient (median over the repetitions).
    pub sample_rust_ns: f64,
    pub sample_c_ns: f64,
    /// C / Rust, one point per pair of calls (issue 29's goal ≤ 1.1).
    pub sample_ratio: f64,
    /// ns per point for value + gradient through one `pheromone_sample_many` call for all the
    /// points, and its ratio to Rust's (issue 47's goal ≤ 1.1).
    pub sample_batch_c_ns: f64,
    pub sample_batch_ratio: f64,
    pub points: usize,
    pub method: &'static str,
}

fn ratio(c: f64, rust: f64) -> f64 {
    if rust > 0.0 {
        ((c / rust) * 1000.0).round() / 1000.0
    } else {
        f64::NAN
    }
}

/// Runs both measurements.
pub fn measure(
    launcher: &Launcher,
    tag: &mut impl FnMut() -> String,
    run: CAbiRun,
) -> Result<CAbiReport, BenchError> {
    let (mut rust, mut c) = (Vec::new(), Vec::new());
    for _ in 0..run.rounds.max(1) {
        for (transport, into) in [
            (FrameTransport::Ours, &mut rust),
            (FrameTransport::CAbi, &mut c),
        ] {
            let s = frames::measure(
                launcher,
                &tag(),
                FrameRun {
                    transport,
                    width: run.width,
                    readers: 1,
                    wait: ReaderWait::Event,
                    count: run.count,
                    skip: run.skip,
                    period: Duration::from_millis(20),
                    pin: run.pin,
                },
            )?;
            into.extend(s.samples_ns);
        }
    }
    let frame_rust_ns = crate::latency(&rust, "C ABI frames, Rust reader")?;
    let frame_c_ns = crate::latency(&c, "C ABI frames, C reader")?;
    let (sample_rust_ns, sample_c_ns, sample_batch_c_ns) =
        sampling_cost(&tag(), run.width, run.points, run.reps)?;
    Ok(CAbiReport {
        width: run.width,
        frame_bytes: run.width as u64 * run.width as u64 * 4,
        frame_ratio_p50: ratio(frame_c_ns.p50, frame_rust_ns.p50),
        frame_ratio_p99: ratio(frame_c_ns.p99, frame_rust_ns.p99),
        frame_rust_ns,
        frame_c_ns,
        sample_ratio: ratio(sample_c_ns, sample_rust_ns),
        sample_batch_ratio: ratio(sample_batch_c_ns, sample_rust_ns),
        sample_rust_ns,
        sample_c_ns,
        sample_batch_c_ns,
        points: run.points,
        method: "frames: publish stamp to the reader holding the frame (C: after wait + borrow), \
                 1 reader process waiting on the event, Rust and C alternated; sampling: value + \
                 gradient per point on the same frame in this process (C per point, and C batch: \
                 one pheromone_sample_many call), median of repetitions",
    })
}

fn c_policy(wait: ReaderWait) -> PheromoneWaitPolicy {
    match wait {
        ReaderWait::Event => PheromoneWaitPolicy {
            kind: PHEROMONE_WAIT_EVENT,
            spin_ns: 0,
        },
        ReaderWait::Spin { spin_us } => PheromoneWaitPolicy {
            kind: PHEROMONE_WAIT_SPIN,
            spin_ns: spin_us as u64 * 1000,
        },
        ReaderWait::BusyPoll => PheromoneWaitPolicy {
            kind: PHEROMONE_WAIT_BUSY_POLL,
            spin_ns: 0,
        },
    }
}

/// A C handle, detached when dropped.
struct CHandle(*mut PheromoneField);

impl CHandle {
    fn attach(field: &str) -> Result<Self, BenchError> {
        let name = CString::new(field).map_err(|e| BenchError::Peer(e.to_string()))?;
        let options = PheromoneAttachOptions {
            deposits: 0,
            attach_timeout_ns: 10_000_000_000,
            ..Default::default()
        };
        let mut h = std::ptr::null_mut();
        // SAFETY: a NUL-terminated name, valid options and out pointer.
        let s = unsafe { pheromone_field_attach(name.as_ptr(), &options, &mut h) };
        check(s, "pheromone_field_attach")?;
        Ok(Self(h))
    }
}

impl Drop for CHandle {
    fn drop(&mut self) {
        // SAFETY: the handle is live and nothing is borrowed when a `CHandle` goes (every borrow
        // below is released before the next call). A refusal would only leak the handle.
        let _ = unsafe { pheromone_field_detach(self.0) };
    }
}

fn check(s: PheromoneStatus, what: &str) -> Result<(), BenchError> {
    if s == PheromoneStatus::Ok {
        return Ok(());
    }
    // SAFETY: the library's last error is a NUL-terminated per-thread buffer, never NULL.
    let msg = unsafe { std::ffi::CStr::from_ptr(pheromone_last_error()) };
    Err(BenchError::Peer(format!(
        "{what}: {s:?}: {}",
        msg.to_string_lossy()
    )))
}

fn empty_view() -> PheromoneFrameView {
    PheromoneFrameView {
        sequence: 0,
        stamp_ns: 0,
        sim_time_s: 0.0,
        channels: 0,
        width: 0,
        height: 0,
        cell_size_m: 0.0,
        origin_x_m: 0.0,
        origin_y_m: 0.0,
        dt_s: 0.0,
        layout_version: 0,
        deposits_applied: 0,
        deposits_rejected: 0,
        plane_len: 0,
        planes: [std::ptr::null(); PHEROMONE_MAX_CHANNELS],
    }
}

/// The C reader process: records (holding the frame − its publish stamp).
pub fn read(source: &str, wait: ReaderWait, skip: usize, count: usize) -> Result<(), BenchError> {
    let h = CHandle::attach(source)?;
    let policy = c_policy(wait);
    let mut view = empty_view();
    // SAFETY: a live handle and a writable view; released right away.
    let mut last = unsafe {
        match pheromone_frame_borrow(h.0, &mut view) {
            PheromoneStatus::Ok => {
                pheromone_frame_release(h.0);
                view.sequence
            }
            _ => 0,
        }
    };
    say_ready();
    record(skip, count, || {
        // SAFETY: a live handle, nothing borrowed.
        let s = unsafe { pheromone_wait_frame(h.0, policy, FRAME_TIMEOUT.as_nanos() as u64) };
        if s == PheromoneStatus::Timeout {
            return Err(BenchError::Peer(format!(
                "no frame from field '{source}' within {FRAME_TIMEOUT:?}"
            )));
        }
        check(s, "pheromone_wait_frame")?;
        check(
            // SAFETY: `h.0` is live (attached by `CHandle::attach`, detached only when `h` drops,
            // after `record`) and only this thread calls on it; `view` is a local
            // `PheromoneFrameView`, valid for the write `pheromone_frame_borrow` makes.
            unsafe { pheromone_frame_borrow(h.0, &mut view) },
            "pheromone_frame_borrow",
        )?;
        let now = now_ns();
        let (sequence, stamp_ns) = (view.sequence, view.stamp_ns);
        check(
            // SAFETY: `h.0` is live (as above), and only this thread calls on it; the view's
            // plane pointers are not read after the release (its sequence and stamp were copied).
            unsafe { pheromone_frame_release(h.0) },
            "pheromone_frame_release",
        )?;
        if sequence == last {
            return Ok(None);
        }
        last = sequence;
        Ok(Some(now.saturating_sub(stamp_ns)))
    })
}

/// ns per point of value + gradient: (Rust `FrameView`, the C ABI per point, the C ABI's batch),
/// on one frame.
fn sampling_cost(
    tag: &str,
    width: u32,
    points: usize,
    reps: usize,
) -> Result<(f64, f64, f64), BenchError> {
    let name = format!("bench-cabi-{tag}");
    let node = create_node(&name)?;
    let config = FieldConfig {
        width,
        height: width,
        channels: vec![ChannelSpec::new("trail", Evaporation::None)],
        ..FieldConfig::default()
    };
    let mut server = FieldServer::start(&node, &name, config.clone(), None)?;
    let mut depositor = DepositPublisher::attach(&node, &name, 1)?;
    let side_m = width as f32 * config.cell_size_m;
    for i in 0..16 {
        let t = i as f32 / 16.0;
        depositor.send(DepositMsg::from(Deposit {
            channel: 0,
            x_m: side_m * (0.1 + 0.8 * t),
            y_m: side_m * (0.5 + 0.3 * (6.0 * t).sin()),
            kernel: Kernel::Ellipse {
                tau: 0.05,
                cov_m2: [0.5, 0.1, 0.8],
                range_m: 3.0,
                gamma_max: 100.0,
            },
        }))?;
    }
    let h = CHandle::attach(&name)?;
    let mut reader = FieldReader::attach(&node, &name)?;
    server.tick()?;
    server.tick()?;
    reader.wait_frame(Duration::from_secs(5))?;
    let event = c_policy(ReaderWait::Event);
    // SAFETY: a live handle, nothing borrowed.
    let s = unsafe { pheromone_wait_frame(h.0, event, 5_000_000_000) };
    if s != PheromoneStatus::Timeout {
        check(s, "pheromone_wait_frame")?;
    }
    let mut view = empty_view();
    check(
        // SAFETY: `h.0` is live (attached by `CHandle::attach`, detached only when `h` drops at
        // the end of this function) and only this thread calls on it; `view` is a local
        // `PheromoneFrameView`, valid for the write `pheromone_frame_borrow` makes.
        unsafe { pheromone_frame_borrow(h.0, &mut view) },
        "pheromone_frame_borrow",
    )?;
    let frame = reader
        .frame()
        .ok_or_else(|| BenchError::Peer("sampling: no frame".into()))?;
    if frame.header.sequence != view.sequence {
        return Err(BenchError::Peer(format!(
            "sampling: the Rust reader holds frame {} and the C reader {}",
            frame.header.sequence, view.sequence
        )));
    }
    let pts: Vec<(f32, f32)> = (0..points)
        .map(|i| {
            let t = i as f32 / points as f32;
            (
                side_m * (0.05 + 0.9 * t),
                side_m * (0.5 + 0.4 * (37.0 * t).sin()),
            )
        })
        .collect();
    let timed = time_sampling(&frame.view, &h, &pts, reps);
    check(
        // SAFETY: `h.0` is still live (`h` drops after this) and only this thread calls on it;
        // the sampling above, the only use of the borrowed frame, is over.
        unsafe { pheromone_frame_release(h.0) },
        "pheromone_frame_release",
    )?;
    timed
}

/// The sampling of `sampling_cost` timed, `reps` times each alternated: ns per point for
/// (Rust `FrameView`, the C ABI per point, one `pheromone_sample_many` call), medians. `h` holds
/// a borrowed frame equal to `view`'s.
fn time_sampling(
    view: &pheromone_field::FrameView<'_>,
    h: &CHandle,
    pts: &[(f32, f32)],
    reps: usize,
) -> Result<(f64, f64, f64), BenchError> {
    let points = pts.len();
    let xy: Vec<f32> = pts.iter().flat_map(|&(x, y)| [x, y]).collect();
    let (mut values, mut gradients) = (vec![0.0f32; points], vec![0.0f32; 2 * points]);
    let (mut rust_ns, mut c_ns, mut batch_ns) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..reps.max(1) {
        let t0 = Instant::now();
        let mut acc = 0.0f32;
        for &(x, y) in pts {
            let v = view.value(0, black_box(x), black_box(y));
            let (gx, gy) = view.gradient(0, black_box(x), black_box(y));
            acc += v + gx + gy;
        }
        black_box(acc);
        rust_ns.push(t0.elapsed().as_nanos() as f64 / points as f64);
        let t0 = Instant::now();
        let mut acc = 0.0f32;
        for &(x, y) in pts {
            let (mut v, mut gx, mut gy) = (0.0, 0.0, 0.0);
            // SAFETY: a live handle with a borrowed frame; the out pointers are locals.
            unsafe {
                pheromone_sample_value(h.0, 0, black_box(x), black_box(y), &mut v);
                pheromone_sample_gradient(h.0, 0, black_box(x), black_box(y), &mut gx, &mut gy);
            }
            acc += v + gx + gy;
        }
        black_box(acc);
        c_ns.push(t0.elapsed().as_nanos() as f64 / points as f64);
        let t0 = Instant::now();
        // SAFETY: a live handle with a borrowed frame; `xy` holds 2·points floats, `values`
        // points and `gradients` 2·points, none overlapping.
        let s = unsafe {
            pheromone_sample_many(
                h.0,
                0,
                black_box(xy.as_ptr()),
                points,
                values.as_mut_ptr(),
                gradients.as_mut_ptr(),
            )
        };
        black_box((&values, &gradients));
        batch_ns.push(t0.elapsed().as_nanos() as f64 / points as f64);
        check(s, "pheromone_sample_many")?;
    }
    Ok((
        median(&mut rust_ns),
        median(&mut c_ns),
        median(&mut batch_ns),
    ))
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let m = v[v.len() / 2];
    (m * 10.0).round() / 10.0
}
