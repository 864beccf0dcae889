//! The shared-memory service within one process: frames, deposits, readers, layout errors.

use std::time::Duration;

use pheromone_field::shm::{
    create_node, AttachError, DepositPublisher, FieldReader, FieldServer, StartError,
};
use pheromone_field::{ChannelSpec, DepositMsg, Evaporation, FieldConfig};
use pheromone_field::{Deposit, Kernel};

use pheromone_testkit::unique;

fn small_config(evaporation: Evaporation) -> FieldConfig {
    FieldConfig {
        width: 64,
        height: 32,
        cell_size_m: 0.1,
        channels: vec![ChannelSpec::new("trail", evaporation)],
        ..FieldConfig::default()
    }
}

#[test]
fn deposit_arrives_in_a_frame_and_evaporates() {
    pheromone_field::shm::set_verbose(false);
    let name = unique("inproc");
    let node = create_node(&name).unwrap();
    let mut server = FieldServer::start(
        &node,
        &name,
        small_config(Evaporation::Exponential { decay_per_s: 5.0 }),
        None,
    )
    .unwrap();
    let mut reader = FieldReader::attach(&node, &name).unwrap();
    let mut depositor = DepositPublisher::attach(&node, &name, 7).unwrap();
    depositor
        .send(DepositMsg::from(Deposit {
            channel: 0,
            x_m: 3.0,
            y_m: 1.5,
            kernel: Kernel::Ellipse {
                tau: 0.01,
                cov_m2: [0.01, 0.0, 0.01],
                range_m: 1.0,
                gamma_max: 100.0,
            },
        }))
        .unwrap();
    let out = server.tick().unwrap();
    server.tick().unwrap();
    // Its flush waits for a tick this thread would make: nothing is left to flush anyway.
    depositor.flush_timeout = Duration::ZERO;
    assert_eq!(out.report.deposits_applied, 1);
    assert!(reader.wait_frame(Duration::from_secs(5)).unwrap());
    let f = reader.frame().unwrap();
    assert_eq!(f.header.sequence, 2);
    assert_eq!(f.header.deposits_applied, 1);
    let peak = f.view.value(0, 3.0, 1.5);
    assert!(peak > 50.0, "peak {peak}");
    let _ = f;
    for _ in 0..20 {
        server.tick().unwrap();
    }
    reader.update().unwrap();
    let later = reader.frame().unwrap().view.value(0, 3.0, 1.5);
    // 20 ticks of dt = 1/50 s at K = 5/s: factor e^(−2).
    assert!(
        (later / peak - (-2.0f32).exp()).abs() < 1e-3,
        "{later} vs {peak}"
    );
    assert_eq!(reader.frame().unwrap().header.sequence, 22);
}

#[test]
fn bad_deposits_are_counted_in_the_header_and_never_reach_the_grid() {
    pheromone_field::shm::set_verbose(false);
    let name = unique("bad");
    let node = create_node(&name).unwrap();
    let mut server =
        FieldServer::start(&node, &name, small_config(Evaporation::None), None).unwrap();
    let mut depositor = DepositPublisher::attach(&node, &name, 1).unwrap();
    depositor.flush_timeout = Duration::ZERO;
    let mut nan = DepositMsg::from(Deposit {
        channel: 0,
        x_m: 3.0,
        y_m: 1.5,
        kernel: Kernel::Ellipse {
            tau: 1.0,
            cov_m2: [0.01, 0.0, 0.01],
            range_m: 1.0,
            gamma_max: 100.0,
        },
    });
    nan.x_m = f32::NAN;
    depositor.send(nan).unwrap();
    depositor
        .send(DepositMsg::from(Deposit {
            channel: 0,
            x_m: 3.0,
            y_m: 1.5,
            kernel: Kernel::Ellipse {
                tau: 1.0,
                cov_m2: [0.01, 0.5, 0.01],
                range_m: 1.0,
                gamma_max: 100.0,
            },
        }))
        .unwrap();
    depositor
        .send(DepositMsg::from(Deposit {
            channel: 9,
            x_m: 3.0,
            y_m: 1.5,
            kernel: Kernel::Ellipse {
                tau: 1.0,
                cov_m2: [0.01, 0.0, 0.01],
                range_m: 1.0,
                gamma_max: 100.0,
            },
        }))
        .unwrap();
    let out = server.tick().unwrap();
    assert_eq!(out.rejected, 3);
    let (h, view) = server.latest().unwrap();
    assert_eq!(h.deposits_rejected_total(), 3);
    assert_eq!(
        h.deposits_rejected[pheromone_field::RejectReason::NonFinite as usize],
        1
    );
    assert_eq!(
        h.deposits_rejected[pheromone_field::RejectReason::NotPsd as usize],
        1
    );
    assert_eq!(
        h.deposits_rejected[pheromone_field::RejectReason::UnknownChannel as usize],
        1
    );
    assert_eq!(view.total(0), 0.0);
}

#[test]
fn a_reader_without_a_field_gets_a_clear_error() {
    pheromone_field::shm::set_verbose(false);
    let name = unique("nofield");
    let node = create_node(&name).unwrap();
    let err = FieldReader::attach(&node, &name).err().unwrap();
    assert!(matches!(err, AttachError::NoField { .. }), "{err}");
    assert!(err.to_string().contains(&name));
}

#[test]
fn a_second_field_with_the_same_name_is_refused() {
    pheromone_field::shm::set_verbose(false);
    let name = unique("twice");
    let node = create_node(&name).unwrap();
    let _first = FieldServer::start(&node, &name, small_config(Evaporation::None), None).unwrap();
    let err = FieldServer::start(&node, &name, small_config(Evaporation::None), None)
        .err()
        .unwrap();
    assert!(matches!(err, StartError::AlreadyRunning { .. }), "{err}");
}

#[test]
fn many_waiting_deposit_commands_leave_room_for_a_bridge() {
    // Each `deposit` command holds a config subscriber while it waits for its receipt; with 4
    // slots, five of them kept a bridge (whose InputsSubscriber takes one) from starting.
    pheromone_field::shm::set_verbose(false);
    let name = unique("cfgsubs");
    let node = create_node(&name).unwrap();
    let _field = FieldServer::start(&node, &name, small_config(Evaporation::None), None).unwrap();
    let deposits: Vec<_> = (0..64)
        .map(|i| {
            pheromone_field::shm::ConfigSubscriber::attach(&node, &name)
                .unwrap_or_else(|e| panic!("deposit {i}'s config subscriber: {e}"))
        })
        .collect();
    let bridge = pheromone_field::shm::InputsSubscriber::attach(&node, &name);
    assert!(bridge.is_ok(), "{}", bridge.err().unwrap());
    drop(deposits);
}

/// `DepositMsg` as a build with the next layout version would declare it: the same bytes, the
/// type name of another layout.
#[derive(Debug, Clone, Copy)]
#[repr(C)]
struct OtherLayoutDeposit(pheromone_field::DepositMsg);

fn other_layout_name(name: &str) -> &'static str {
    let v = pheromone_field::wire::LAYOUT_VERSION + 1;
    Box::leak(format!("pheromone::{name}/v{v}").into_boxed_str())
}

// The layout test needs a wire type under another type name, which `wire_type!` cannot give.
#[allow(unsafe_code)]
// SAFETY: a `#[repr(C)]` wrapper of a wire type (plain numbers); only its type name differs.
unsafe impl iceoryx2::prelude::ZeroCopySend for OtherLayoutDeposit {
    unsafe fn type_name() -> &'static str {
        static NAME: std::sync::OnceLock<&'static str> = std::sync::OnceLock::new();
        NAME.get_or_init(|| other_layout_name("DepositMsg"))
    }
}

#[test]
fn a_client_built_with_another_layout_is_refused_by_a_running_field() {
    use iceoryx2::prelude::*;
    pheromone_field::shm::set_verbose(false);
    let name = unique("layout-new");
    let node = create_node(&name).unwrap();
    let _field = FieldServer::start(&node, &name, small_config(Evaporation::None), None).unwrap();
    // This build's depositor attaches; one of the next layout, byte for byte the same message
    // but named for its layout, is refused.
    DepositPublisher::attach(&node, &name, 1).unwrap();
    let service_name = ServiceName::new(&format!("pheromone/{name}/deposit")).unwrap();
    let Err(err) = node
        .service_builder(&service_name)
        .publish_subscribe::<OtherLayoutDeposit>()
        .open()
    else {
        panic!("a client of another layout must be refused");
    };
    assert_eq!(
        err,
        iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenError::IncompatibleTypes
    );
}

#[test]
fn a_client_with_another_message_layout_gets_a_clear_error() {
    use iceoryx2::prelude::*;
    pheromone_field::shm::set_verbose(false);
    let name = unique("layout");
    let node = create_node(&name).unwrap();
    // A field of the next layout created the deposit service.
    let service_name = ServiceName::new(&format!("pheromone/{name}/deposit")).unwrap();
    let _other = node
        .service_builder(&service_name)
        .publish_subscribe::<OtherLayoutDeposit>()
        .open_or_create()
        .unwrap();
    let err = DepositPublisher::attach(&node, &name, 1).err().unwrap();
    assert!(matches!(err, AttachError::Layout { .. }), "{err}");
    assert!(
        err.to_string()
            .contains(pheromone_field::wire_type_name!("DepositMsg")),
        "{err}"
    );
}

#[test]
fn a_node_directory_left_by_a_killed_process_is_removed_and_a_live_ones_kept() {
    // What a process SIGKILLed while it created its node leaves: a directory with the node's
    // details (naming the process) and no monitor token, so no listing shows it.
    use iceoryx2::prelude::*;
    let mut config = iceoryx2::config::Config::default();
    // Not under the default prefix `iox2_`: a default-domain process would take these for its own.
    let prefix = format!("o{}_iox2_", std::process::id() % 100_000);
    config.global.prefix = FileName::new(prefix.as_bytes()).unwrap();
    let node_dir = std::path::PathBuf::from(config.global.node_dir().to_string());
    let orphan = |id: u128, pid: u32| {
        let dir = node_dir.join(id.to_string());
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(
            dir.join(format!("{prefix}node.details")),
            format!("executable = \"pheromone\"\nprocess = {pid}\nname = \"x\"\n"),
        )
        .unwrap();
        dir
    };
    let base = 7_000_000_000_000_000_000_000_000_000u128 + std::process::id() as u128 * 10;
    // A pid above the kernel's limit (4194304) belongs to no process.
    let gone = orphan(base, 99_999_999);
    let alive = orphan(base + 1, std::process::id());
    pheromone_field::shm::cleanup_dead_nodes_of(&config);
    let (gone_left, alive_left) = (gone.exists(), alive.exists());
    std::fs::remove_dir_all(&alive).unwrap();
    assert!(!gone_left, "the dead process's node directory is removed");
    assert!(
        alive_left,
        "a node of a live process (being created) is kept"
    );
}

/// Every wait policy sees a frame the field publishes while the reader waits, and ends at its
/// timeout when none comes.
#[test]
fn every_wait_policy_sees_the_next_frame_and_honours_its_timeout() {
    use pheromone_field::shm::WaitPolicy;
    pheromone_field::shm::set_verbose(false);
    let name = unique("waitpolicy");
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let (started_tx, started_rx) = std::sync::mpsc::channel();
    let ticking = {
        let (name, stop) = (name.clone(), stop.clone());
        std::thread::spawn(move || {
            let node = create_node(&format!("{name}-field")).unwrap();
            let mut server = FieldServer::start(
                &node,
                &name,
                small_config(Evaporation::Exponential { decay_per_s: 1.0 }),
                None,
            )
            .unwrap();
            started_tx.send(()).unwrap();
            while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                server.tick().unwrap();
                // Node wait: 5 ms between frames.
                let _ = pheromone_field::shm::node_wait(&node, Duration::from_millis(5));
            }
        })
    };
    started_rx.recv_timeout(Duration::from_secs(10)).unwrap();
    let node = create_node(&format!("{name}-reader")).unwrap();
    let mut reader = FieldReader::attach_within(&node, &name, Duration::from_secs(5)).unwrap();
    for policy in [
        WaitPolicy::Event,
        WaitPolicy::Spin(Duration::from_micros(200)),
        WaitPolicy::Spin(Duration::from_millis(50)),
        WaitPolicy::BusyPoll,
    ] {
        for _ in 0..5 {
            let before = reader.frame().map(|f| f.header.sequence).unwrap_or(0);
            assert!(
                reader
                    .wait_frame_with(policy, Duration::from_secs(5))
                    .unwrap(),
                "{policy:?}: no frame within 5 s"
            );
            let after = reader.frame().unwrap().header.sequence;
            assert!(after > before, "{policy:?}: {before} -> {after}");
        }
    }
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    ticking.join().unwrap();
    // The field is gone: no frame comes, and each policy returns at its timeout.
    reader.update().unwrap();
    for policy in [
        WaitPolicy::Event,
        WaitPolicy::Spin(Duration::from_millis(1)),
        WaitPolicy::BusyPoll,
    ] {
        let t = std::time::Instant::now();
        assert!(!reader
            .wait_frame_with(policy, Duration::from_millis(30))
            .unwrap());
        assert!(t.elapsed() >= Duration::from_millis(30), "{policy:?}");
    }
}

/// `--wait` values: the three policies parse and print back the same; anything else is an
/// error that names the value.
#[test]
fn wait_policies_parse_from_their_names_and_refuse_anything_else() {
    use pheromone_field::shm::WaitPolicy;
    for (text, policy) in [
        ("event", WaitPolicy::Event),
        ("busy-poll", WaitPolicy::BusyPoll),
        ("spin:200", WaitPolicy::Spin(Duration::from_micros(200))),
        ("spin:1000000", WaitPolicy::Spin(Duration::from_secs(1))),
    ] {
        assert_eq!(text.parse::<WaitPolicy>(), Ok(policy), "{text}");
        assert_eq!(policy.to_string(), text);
    }
    for bad in [
        "",
        "Event",
        "spin",
        "spin:",
        "spin:0",
        "spin:-5",
        "spin:1.5",
        "spin:1000001",
    ] {
        let e = bad.parse::<WaitPolicy>().unwrap_err();
        assert!(e.to_string().contains(&format!("\"{bad}\"")), "{bad}: {e}");
    }
}

/// A wait of less than a microsecond ends at once: iceoryx2 0.10 turns such a timeout into a
/// zero `SO_RCVTIMEO`, which means "wait for ever" (a field on deposit once hung there until
/// its follower, waiting for a frame, gave up).
#[test]
fn a_listener_wait_shorter_than_a_microsecond_does_not_block() {
    use iceoryx2::prelude::*;
    pheromone_field::shm::set_verbose(false);
    let name = unique("subus");
    let (done_tx, done) = std::sync::mpsc::channel();
    let waiter = std::thread::spawn(move || {
        let node = create_node(&name).unwrap();
        let service = node
            .service_builder(&ServiceName::new(&name).unwrap())
            .event()
            .open_or_create()
            .unwrap();
        let listener = service.listener_builder().create().unwrap();
        for ns in [0, 1, 500, 999] {
            let n = pheromone_field::shm::listener_timed_wait(&listener, Duration::from_nanos(ns))
                .unwrap();
            assert_eq!(n, 0, "{ns} ns");
        }
        done_tx.send(()).unwrap();
    });
    // With the bug the thread never ends: no event ever comes.
    assert!(
        done.recv_timeout(Duration::from_secs(20)).is_ok(),
        "a sub-microsecond wait blocked"
    );
    waiter.join().unwrap();
}
