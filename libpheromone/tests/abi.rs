//! The C ABI called as C calls it (the `extern "C"` functions), against a field served in this
//! process: sampling gives the numbers of Rust's `FrameView` bit for bit, the hot calls (wait,
//! borrow, sample, release, deposit) allocate nothing, and a field of another layout is refused.
#![allow(unsafe_code)]

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::ffi::{CStr, CString};
use std::time::Duration;

use pheromone_c::*;
use pheromone_field::shm::{create_node, DepositPublisher, FieldReader, FieldServer};
use pheromone_field::{ChannelSpec, DepositMsg, Evaporation, FieldConfig, SamplePose};
use pheromone_field::{Deposit, Kernel};

/// Counts this thread's allocations while `COUNTING` is on.
struct Counting;

thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

fn note_allocation() {
    let _ = COUNTING.try_with(|on| {
        if on.get() {
            let _ = ALLOCATIONS.try_with(|n| n.set(n.get() + 1));
        }
    });
}

// SAFETY: forwards every call to the system allocator unchanged; counting touches only
// const-initialised thread-locals, which do not allocate.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note_allocation();
        // SAFETY: the caller's layout contract is the system allocator's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` came from `System.alloc` with this layout.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note_allocation();
        // SAFETY: as `dealloc`, with the caller's new size.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// Allocations `f` makes on this thread.
fn allocations_in(f: impl FnOnce()) -> u64 {
    ALLOCATIONS.with(|n| n.set(0));
    COUNTING.with(|c| c.set(true));
    f();
    COUNTING.with(|c| c.set(false));
    ALLOCATIONS.with(|n| n.get())
}

fn unique(tag: &str) -> String {
    use std::sync::atomic::{AtomicU32, Ordering};
    static N: AtomicU32 = AtomicU32::new(0);
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.subsec_nanos())
        .unwrap_or(0);
    format!(
        "{tag}-{}-{}-{nanos}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    )
}

fn config() -> FieldConfig {
    FieldConfig {
        width: 64,
        height: 32,
        cell_size_m: 0.1,
        origin_x_m: -1.0,
        channels: vec![
            ChannelSpec::new("trail", Evaporation::None),
            ChannelSpec::new("other", Evaporation::None),
        ],
        ..FieldConfig::default()
    }
}

fn last_error() -> String {
    // SAFETY: the library returns a NUL-terminated per-thread buffer, never NULL.
    unsafe { CStr::from_ptr(pheromone_last_error()) }
        .to_string_lossy()
        .into_owned()
}

fn attach(name: &str) -> Result<*mut PheromoneField, (PheromoneStatus, String)> {
    let c_name = CString::new(name).unwrap();
    let options = PheromoneAttachOptions {
        robot_id: 5,
        ..Default::default()
    };
    let mut handle = std::ptr::null_mut();
    // SAFETY: a NUL-terminated name, valid options and out pointer.
    let s = unsafe { pheromone_field_attach(c_name.as_ptr(), &options, &mut handle) };
    match s {
        PheromoneStatus::Ok => Ok(handle),
        s => Err((s, last_error())),
    }
}

const EVENT: PheromoneWaitPolicy = PheromoneWaitPolicy {
    kind: PHEROMONE_WAIT_EVENT,
    spin_ns: 0,
};

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

/// The C sampling calls on the borrowed frame of `h` against `FrameView`'s, at 20 poses and on
/// both channels, bit for bit.
fn compare_sampling(h: *mut PheromoneField, view: &pheromone_field::FrameView<'_>) {
    for i in 0..20 {
        let (x, y, theta) = (
            -1.0 + 0.37 * i as f32,
            0.1 + 0.15 * i as f32,
            0.3 * i as f32,
        );
        for ch in 0..2u32 {
            let c = ch as usize;
            let (mut v, mut gx, mut gy, mut l, mut r) = (0.0, 0.0, 0.0, 0.0, 0.0);
            let mut sectors = [0.0f32; 5];
            let pose = PheromonePose {
                x_m: x,
                y_m: y,
                theta_rad: theta,
            };
            // SAFETY: a live handle with a borrowed frame; every out pointer is writable.
            unsafe {
                assert_eq!(
                    pheromone_sample_value(h, ch, x, y, &mut v),
                    PheromoneStatus::Ok
                );
                assert_eq!(
                    pheromone_sample_gradient(h, ch, x, y, &mut gx, &mut gy),
                    PheromoneStatus::Ok
                );
                assert_eq!(
                    pheromone_sample_antennas(h, ch, pose, 0.3, &mut l, &mut r),
                    PheromoneStatus::Ok
                );
                assert_eq!(
                    pheromone_sample_sectors(h, ch, pose, 1.2, 2, sectors.as_mut_ptr(), 5),
                    PheromoneStatus::Ok
                );
            }
            let rust_pose = SamplePose::new(x, y, theta);
            assert_eq!(v.to_bits(), view.value(c, x, y).to_bits());
            assert_eq!((gx, gy), view.gradient(c, x, y));
            assert_eq!((l, r), view.antennas(c, rust_pose, 0.3));
            assert_eq!(sectors.to_vec(), view.sector_means(c, rust_pose, 1.2, 2));
        }
    }
}

/// `pheromone_sample_many` on the borrowed frame of `h`: values only, gradients only, both, on
/// both channels, equal bit for bit to `FrameView`'s point by point (points inside, on the
/// border and outside the grid); a non-finite point and two NULL outputs refused by name.
fn compare_sample_many(h: *mut PheromoneField, view: &pheromone_field::FrameView<'_>) {
    let xy: Vec<f32> = (0..200)
        .flat_map(|i| [-1.5 + 0.041 * i as f32, -0.3 + 0.019 * i as f32])
        .collect();
    let n = xy.len() / 2;
    for ch in 0..2u32 {
        let c = ch as usize;
        let (mut v1, mut v2, mut g1, mut g2) = (
            vec![0.0f32; n],
            vec![0.0f32; n],
            vec![0.0f32; 2 * n],
            vec![0.0f32; 2 * n],
        );
        // SAFETY: a live handle with a borrowed frame; xy holds 2n floats, the outputs n / 2n.
        unsafe {
            let null = std::ptr::null_mut();
            let s = pheromone_sample_many(h, ch, xy.as_ptr(), n, v1.as_mut_ptr(), null);
            assert_eq!(s, PheromoneStatus::Ok, "{}", last_error());
            let s = pheromone_sample_many(h, ch, xy.as_ptr(), n, null, g1.as_mut_ptr());
            assert_eq!(s, PheromoneStatus::Ok, "{}", last_error());
            let s = pheromone_sample_many(h, ch, xy.as_ptr(), n, v2.as_mut_ptr(), g2.as_mut_ptr());
            assert_eq!(s, PheromoneStatus::Ok, "{}", last_error());
        }
        for i in 0..n {
            let (x, y) = (xy[2 * i], xy[2 * i + 1]);
            let v = view.value(c, x, y);
            let (gx, gy) = view.gradient(c, x, y);
            assert_eq!(v1[i].to_bits(), v.to_bits(), "point {i}");
            assert_eq!(v2[i].to_bits(), v.to_bits(), "point {i}");
            assert_eq!((g1[2 * i], g1[2 * i + 1]), (gx, gy), "point {i}");
            assert_eq!((g2[2 * i], g2[2 * i + 1]), (gx, gy), "point {i}");
        }
    }
    let mut bad = xy.clone();
    bad[7] = f32::NAN;
    let mut out = vec![0.0f32; n];
    // SAFETY: as above.
    let s = unsafe {
        pheromone_sample_many(
            h,
            0,
            bad.as_ptr(),
            n,
            out.as_mut_ptr(),
            std::ptr::null_mut(),
        )
    };
    assert_eq!(s, PheromoneStatus::BadArgument);
    assert!(
        last_error().contains("point 3") && last_error().contains("xy[7]"),
        "{}",
        last_error()
    );
    assert!(out.iter().all(|v| *v == 0.0), "nothing written");
    // SAFETY: as above.
    let s = unsafe {
        pheromone_sample_many(
            h,
            0,
            xy.as_ptr(),
            n,
            std::ptr::null_mut(),
            std::ptr::null_mut(),
        )
    };
    assert_eq!(s, PheromoneStatus::BadArgument);
    assert!(last_error().contains("both NULL"), "{}", last_error());
    // SAFETY: as above.
    let s = unsafe {
        pheromone_sample_many(h, 2, xy.as_ptr(), n, out.as_mut_ptr(), std::ptr::null_mut())
    };
    assert_eq!(s, PheromoneStatus::BadArgument);
    assert!(last_error().contains("channel = 2"), "{}", last_error());
}

/// 53 rounds of wait, borrow, sample, release and two deposits, the last 50 counted: the
/// reading calls allocate nothing, the deposits only iceoryx2's one block per sample.
fn hot_path_allocations(h: *mut PheromoneField, server: &mut FieldServer) {
    // The hot path, a few rounds to warm up, then counted.
    let deposit = PheromoneDeposit {
        kernel: PHEROMONE_KERNEL_ELLIPSE,
        x_m: 1.0,
        y_m: 1.0,
        amount: 0.01,
        cov_xx: 0.04,
        cov_yy: 0.04,
        range_m: 1.0,
        gamma_max: 100.0,
        ..Default::default()
    };
    let pose = PheromonePoseEstimate {
        x_m: 2.0,
        y_m: 1.0,
        theta_rad: 0.1,
        cov: [0.04, 0.0, 0.0, 0.0, 0.05, 0.0, 0.0, 0.0, 0.1],
    };
    // (allocations reading, allocations depositing) in one round.
    let hot_round = || {
        let (mut v, mut gx, mut gy) = (0.0, 0.0, 0.0);
        let mut sectors = [0.0f32; 7];
        let xy = [1.0f32, 1.0, 2.0, 0.5, -3.0, 9.0, 0.2, 0.3];
        let (mut many, mut grads) = ([0.0f32; 4], [0.0f32; 8]);
        let mut view = empty_view();
        let p = PheromonePose::default();
        // SAFETY: a live handle; every pointer is valid for the call.
        let reading = allocations_in(|| unsafe {
            assert_eq!(
                pheromone_wait_frame(h, EVENT, 5_000_000_000),
                PheromoneStatus::Ok
            );
            assert_eq!(pheromone_frame_borrow(h, &mut view), PheromoneStatus::Ok);
            assert_eq!(
                pheromone_sample_value(h, 0, 1.0, 1.0, &mut v),
                PheromoneStatus::Ok
            );
            assert_eq!(
                pheromone_sample_gradient(h, 0, 1.0, 1.0, &mut gx, &mut gy),
                PheromoneStatus::Ok
            );
            assert_eq!(
                pheromone_sample_sectors(h, 0, p, 1.0, 3, sectors.as_mut_ptr(), 7),
                PheromoneStatus::Ok
            );
            assert_eq!(
                pheromone_sample_many(h, 0, xy.as_ptr(), 4, many.as_mut_ptr(), grads.as_mut_ptr()),
                PheromoneStatus::Ok
            );
            assert_eq!(pheromone_frame_release(h), PheromoneStatus::Ok);
        });
        // SAFETY: as above.
        let depositing = allocations_in(|| unsafe {
            assert_eq!(pheromone_deposit(h, &deposit), PheromoneStatus::Ok);
            assert_eq!(
                pheromone_deposit_pose(h, &pose, std::ptr::null()),
                PheromoneStatus::Ok
            );
        });
        (reading, depositing)
    };
    for _ in 0..3 {
        server.tick().unwrap();
        hot_round();
    }
    let (mut reading, mut depositing) = (0, 0);
    for _ in 0..50 {
        server.tick().unwrap();
        let (r, d) = hot_round();
        reading += r;
        depositing += d;
    }
    assert_eq!(
        reading, 0,
        "allocations in 50 rounds of wait/borrow/sample/release"
    );
    // The library adds none; iceoryx2 0.10's `Publisher::loan_uninit` (under `send_copy`)
    // allocates the `Rc` of each sample it loans (`ChunkMutSharedState::new`): one per deposit.
    assert_eq!(
        depositing, 100,
        "allocations in 100 deposits: iceoryx2's one per sample, no more"
    );
}

#[test]
fn sampling_gives_frame_views_numbers_and_the_hot_calls_do_not_allocate() {
    pheromone_field::shm::set_verbose(false);
    let name = unique("capi");
    let node = create_node(&name).unwrap();
    let mut server = FieldServer::start(&node, &name, config(), None).unwrap();
    let mut depositor = DepositPublisher::attach(&node, &name, 1).unwrap();
    for (x, y, ch) in [(1.0, 1.5, 0), (3.2, 0.7, 0), (2.0, 2.0, 1)] {
        depositor
            .send(DepositMsg::from(Deposit {
                channel: ch,
                x_m: x,
                y_m: y,
                kernel: Kernel::Ellipse {
                    tau: 0.02,
                    cov_m2: [0.05, 0.01, 0.08],
                    range_m: 1.5,
                    gamma_max: 100.0,
                },
            }))
            .unwrap();
    }
    let h = attach(&name).unwrap();
    let mut reader = FieldReader::attach(&node, &name).unwrap();
    server.tick().unwrap();
    server.tick().unwrap();
    assert!(reader.wait_frame(Duration::from_secs(5)).unwrap());
    // SAFETY: a live handle.
    let s = unsafe { pheromone_wait_frame(h, EVENT, 5_000_000_000) };
    assert_eq!(s, PheromoneStatus::Ok, "{}", last_error());
    let frame = reader.frame().unwrap();
    assert_eq!(frame.header.deposits_applied, 3);

    let mut view = empty_view();
    // SAFETY: a live handle and a writable view.
    let s = unsafe { pheromone_frame_borrow(h, &mut view) };
    assert_eq!(s, PheromoneStatus::Ok);
    assert_eq!(view.sequence, frame.header.sequence);
    assert_eq!((view.channels, view.width, view.height), (2, 64, 32));
    assert!(view.planes[2].is_null());
    for c in 0..2 {
        // SAFETY: the borrowed frame's plane `c` holds `plane_len` floats until the release.
        let plane = unsafe { std::slice::from_raw_parts(view.planes[c], view.plane_len) };
        assert_eq!(plane, frame.view.plane(c), "channel {c}");
    }
    compare_sampling(h, &frame.view);
    compare_sample_many(h, &frame.view);
    // SAFETY: a live handle.
    assert_eq!(unsafe { pheromone_frame_release(h) }, PheromoneStatus::Ok);

    hot_path_allocations(h, &mut server);
    server.tick().unwrap();
    server.tick().unwrap();
    assert!(reader.wait_frame(Duration::from_secs(5)).unwrap());
    let applied = reader.frame().unwrap().header.deposits_applied;
    assert_eq!(applied, 3 + 2 * 53, "every C deposit reached the field");
    // SAFETY: a live handle, nothing borrowed; detached once.
    assert_eq!(unsafe { pheromone_field_detach(h) }, PheromoneStatus::Ok);
}

/// A frame header of the next layout: the same bytes, another iceoryx2 type name.
#[derive(Debug, Clone, Copy, Default)]
#[repr(C)]
struct OtherLayoutHeader(pheromone_field::FrameHeader);

// SAFETY: a `#[repr(C)]` wrapper of a wire type (plain numbers); only its type name differs.
unsafe impl iceoryx2::prelude::ZeroCopySend for OtherLayoutHeader {
    unsafe fn type_name() -> &'static str {
        "pheromone::FrameHeader/v999"
    }
}

#[test]
fn a_missing_field_bad_arguments_and_a_field_of_another_layout_are_refused_by_name() {
    use iceoryx2::prelude::*;
    pheromone_field::shm::set_verbose(false);
    let missing = unique("capi-missing");
    let (status, msg) = attach(&missing).unwrap_err();
    assert_eq!(status, PheromoneStatus::NoField);
    assert!(msg.contains(&missing), "{msg}");

    let (status, msg) = attach("no/slash").unwrap_err();
    assert_eq!(status, PheromoneStatus::BadArgument);
    assert!(msg.contains("'no/slash'"), "{msg}");

    let name = unique("capi-layout");
    let node = create_node(&name).unwrap();
    let service = ServiceName::new(&format!("pheromone/{name}/frame")).unwrap();
    let _other = node
        .service_builder(&service)
        .publish_subscribe::<[f32]>()
        .user_header::<OtherLayoutHeader>()
        .open_or_create()
        .unwrap();
    let (status, msg) = attach(&name).unwrap_err();
    assert_eq!(status, PheromoneStatus::Layout, "{msg}");
    assert!(msg.contains("another message layout"), "{msg}");
    assert!(msg.contains("pheromone::FrameHeader/v1"), "{msg}");

    let old_header = PheromoneAttachOptions {
        layout_version: 0,
        ..Default::default()
    };
    let c_name = CString::new(name).unwrap();
    let mut handle = std::ptr::null_mut();
    // SAFETY: valid arguments.
    let s = unsafe { pheromone_field_attach(c_name.as_ptr(), &old_header, &mut handle) };
    assert_eq!(s, PheromoneStatus::Layout);
    assert!(
        last_error().contains("layout_version = 0"),
        "{}",
        last_error()
    );
    assert!(handle.is_null());

    // SAFETY: a NULL out pointer is refused, not written.
    let s = unsafe { pheromone_field_attach(c_name.as_ptr(), &old_header, std::ptr::null_mut()) };
    assert_eq!(s, PheromoneStatus::BadArgument);
    assert_eq!(last_error(), "out is NULL");
}

#[test]
fn statuses_have_descriptions_and_the_log_level_is_the_callers() {
    use iceoryx2_log::{get_log_level, LogLevel};
    // Every status a description of its own; another value "unknown status"; never NULL.
    let mut seen = std::collections::HashSet::new();
    for s in PheromoneStatus::ALL {
        // SAFETY: a static NUL-terminated string.
        let d = unsafe { CStr::from_ptr(pheromone_status_str(s as i32)) }
            .to_str()
            .unwrap();
        assert!(!d.is_empty() && d != "unknown status", "{s:?}: {d}");
        assert!(seen.insert(d), "{s:?}: {d} twice");
    }
    assert_eq!(
        PheromoneStatus::ALL.len(),
        PheromoneStatus::FieldDead as usize + 1
    );
    for v in [-1, 13, i32::MAX] {
        // SAFETY: as above.
        let d = unsafe { CStr::from_ptr(pheromone_status_str(v)) };
        assert_eq!(d.to_str().unwrap(), "unknown status");
    }
    // SAFETY: as above.
    let d = unsafe { CStr::from_ptr(pheromone_status_str(PheromoneStatus::Interrupted as i32)) };
    assert_eq!(d.to_str().unwrap(), "interrupted by a signal");

    assert_eq!(pheromone_set_log_level(6), PheromoneStatus::BadArgument);
    assert!(last_error().contains("log level = 6"), "{}", last_error());
    assert_eq!(
        pheromone_set_log_level(PHEROMONE_LOG_WARN),
        PheromoneStatus::Ok
    );
    assert_eq!(get_log_level(), LogLevel::Warn as u8);
    // Attaching (here to a field that does not exist) leaves the process's log level alone.
    let _ = attach(&unique("capi-loglevel"));
    assert_eq!(get_log_level(), LogLevel::Warn as u8);
    assert_eq!(
        pheromone_set_log_level(PHEROMONE_LOG_FATAL),
        PheromoneStatus::Ok
    );
    assert_eq!(get_log_level(), LogLevel::Fatal as u8);
}
