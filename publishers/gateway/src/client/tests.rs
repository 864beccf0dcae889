//! The client against fake in-process gateways: a UDP socket or a pty answered by a closure.

use std::io::Write;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use pheromone_gateway_codec::{DepositReply, PirReply};

use super::*;

fn wire(client_id: u8, message: Message) -> Vec<u8> {
    let mut out = [0u8; MAX_ENCODED_BYTES];
    let n = encode(&message, client_id, &mut out).unwrap();
    out[..n].to_vec()
}

/// What a fake gateway sends back for its `nth` request (from 0): datagrams, or serial chunks.
type Answer = Box<dyn FnMut(Frame, usize) -> Vec<Vec<u8>> + Send>;

/// A fake gateway on a UDP socket; stops when dropped. `seen` holds every request it got.
struct FakeUdp {
    address: String,
    seen: Arc<Mutex<Vec<Frame>>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl FakeUdp {
    fn new(mut answer: Answer) -> FakeUdp {
        let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
        socket
            .set_read_timeout(Some(Duration::from_millis(10)))
            .unwrap();
        let address = socket.local_addr().unwrap().to_string();
        let seen = Arc::new(Mutex::new(Vec::new()));
        let stop = Arc::new(AtomicBool::new(false));
        let (seen2, stop2) = (seen.clone(), stop.clone());
        let thread = std::thread::spawn(move || {
            let mut buf = [0u8; 1024];
            while !stop2.load(Ordering::Relaxed) {
                let Ok((n, from)) = socket.recv_from(&mut buf) else {
                    continue;
                };
                let Some(Ok(frame)) = decode(&buf[..n]) else {
                    continue;
                };
                let nth = {
                    let mut seen = seen2.lock().unwrap();
                    seen.push(frame);
                    seen.len() - 1
                };
                for datagram in answer(frame, nth) {
                    socket.send_to(&datagram, from).unwrap();
                }
            }
        });
        FakeUdp {
            address,
            seen,
            stop,
            thread: Some(thread),
        }
    }

    fn seen(&self) -> Vec<Frame> {
        self.seen.lock().unwrap().clone()
    }
}

impl Drop for FakeUdp {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            t.join().unwrap();
        }
    }
}

/// A gateway that answers every request correctly (deposits with their seq, applied).
fn honest(frame: Frame) -> Vec<u8> {
    let reply = match frame.message {
        Message::Pir(p) => Message::PirReply(PirReply {
            p_left: p.x_m,
            p_right: p.y_m,
            frame_seq: 7,
        }),
        Message::Deposit(d) => Message::DepositReply(DepositReply {
            seq: d.seq,
            status: DepositStatus::Applied,
        }),
        Message::Ping => Message::Status(StatusReply {
            frame_seq: 7,
            field_time_s: 0.5,
            channels: 2,
        }),
        _ => Message::Error(ErrorReason::UnknownOpcode),
    };
    wire(frame.client_id, reply)
}

fn config(timeout_ms: u64, retries: u32) -> ClientConfig {
    ClientConfig {
        client_id: 5,
        timeout: Duration::from_millis(timeout_ms),
        retries,
        ..Default::default()
    }
}

#[test]
fn requests_get_their_replies_and_deposits_take_successive_seqs() {
    let fake = FakeUdp::new(Box::new(|f, _| vec![honest(f)]));
    let mut c = GatewayClient::new(Transport::udp(&fake.address).unwrap(), config(500, 0));
    let r = c.pir(1.5, 2.5, 0.0, 0.1, 0).unwrap();
    assert_eq!((r.p_left, r.p_right, r.frame_seq), (1.5, 2.5, 7));
    assert_eq!(c.ping().unwrap().channels, 2);
    assert_eq!(c.deposit(1.0, 1.0, 1.0, 0).unwrap(), 0);
    assert_eq!(c.deposit(1.0, 1.0, 1.0, 0).unwrap(), 1);
    assert_eq!(c.active(), Which::Primary);
    assert!(fake.seen().iter().all(|f| f.client_id == 5));
}

#[test]
fn a_deposit_is_retried_with_the_same_seq_until_answered() {
    // Silent to the first two requests.
    let fake = FakeUdp::new(Box::new(
        |f, nth| {
            if nth < 2 {
                vec![]
            } else {
                vec![honest(f)]
            }
        },
    ));
    let mut c = GatewayClient::new(Transport::udp(&fake.address).unwrap(), config(50, 3));
    assert_eq!(c.deposit(2.0, 3.0, 1.0, 1).unwrap(), 0);
    let seqs: Vec<u8> = fake
        .seen()
        .iter()
        .map(|f| match f.message {
            Message::Deposit(d) => d.seq,
            m => panic!("{m:?}"),
        })
        .collect();
    assert_eq!(seqs, vec![0, 0, 0], "three sends of one seq");
    assert_eq!(c.deposit(2.0, 3.0, 1.0, 1).unwrap(), 1, "the next deposit");
}

#[test]
fn replies_to_others_stale_replies_and_garbage_are_skipped() {
    let fake = FakeUdp::new(Box::new(|f, _| {
        let mut out = vec![
            b"noise".to_vec(),
            // Another robot's reply on the same channel.
            wire(9, Message::Ping),
            wire(
                9,
                Message::Status(StatusReply {
                    frame_seq: 1,
                    field_time_s: 0.0,
                    channels: 9,
                }),
            ),
        ];
        if let Message::Deposit(d) = f.message {
            // A late reply to an earlier deposit.
            out.push(wire(
                f.client_id,
                Message::DepositReply(DepositReply {
                    seq: d.seq.wrapping_sub(1),
                    status: DepositStatus::Applied,
                }),
            ));
        }
        out.push(honest(f));
        out
    }));
    let mut c = GatewayClient::new(Transport::udp(&fake.address).unwrap(), config(500, 0));
    assert_eq!(c.ping().unwrap().channels, 2);
    assert_eq!(c.deposit(0.0, 0.0, 1.0, 0).unwrap(), 0);
}

#[test]
fn error_replies_and_refused_deposits_name_the_reason_and_do_not_switch() {
    let fake = FakeUdp::new(Box::new(|f, _| match f.message {
        Message::Deposit(d) => vec![wire(
            f.client_id,
            Message::DepositReply(DepositReply {
                seq: d.seq,
                status: DepositStatus::Rejected(ErrorReason::UnknownChannel),
            }),
        )],
        _ => vec![wire(f.client_id, Message::Error(ErrorReason::RateLimited))],
    }));
    let backup = FakeUdp::new(Box::new(|f, _| vec![honest(f)]));
    let mut c = GatewayClient::new(Transport::udp(&fake.address).unwrap(), config(500, 0))
        .with_backup(Transport::udp(&backup.address).unwrap());
    let e = c.pir(0.0, 0.0, 0.0, 0.1, 0).unwrap_err();
    assert!(
        matches!(
            e,
            ClientError::ErrorReply {
                reason: ErrorReason::RateLimited,
                ..
            }
        ),
        "{e}"
    );
    let text = e.to_string();
    assert!(
        text.contains(&fake.address) && text.contains("reason 5"),
        "{text}"
    );
    let e = c.deposit(0.0, 0.0, 1.0, 9).unwrap_err();
    assert!(e.to_string().contains("reason 4"), "{e}");
    assert_eq!(c.active(), Which::Primary);
    assert!(backup.seen().is_empty());
}

#[test]
fn a_silent_primary_makes_the_client_switch_to_the_backup_and_stay() {
    let primary = FakeUdp::new(Box::new(|_, _| vec![]));
    let backup = FakeUdp::new(Box::new(|f, _| vec![honest(f)]));
    let mut c = GatewayClient::new(Transport::udp(&primary.address).unwrap(), config(30, 1))
        .with_backup(Transport::udp(&backup.address).unwrap());
    let r = c.pir(4.0, 5.0, 0.0, 0.1, 0).unwrap();
    assert_eq!(r.p_left, 4.0);
    assert_eq!(c.active(), Which::Backup);
    assert!(c.active_address().contains(&backup.address));
    assert_eq!(primary.seen().len(), 2, "first attempt and one retry");
    // The deposit goes straight to the backup now.
    assert_eq!(c.deposit(1.0, 1.0, 1.0, 0).unwrap(), 0);
    assert_eq!(primary.seen().len(), 2);
    assert_eq!(c.switches().0, 1);
}

#[test]
fn both_gateways_silent_is_a_timeout_naming_the_last_one() {
    let primary = FakeUdp::new(Box::new(|_, _| vec![]));
    let backup = FakeUdp::new(Box::new(|_, _| vec![]));
    let mut c = GatewayClient::new(Transport::udp(&primary.address).unwrap(), config(20, 0))
        .with_backup(Transport::udp(&backup.address).unwrap());
    let e = c.ping().unwrap_err();
    assert!(matches!(e, ClientError::Timeout { attempts: 1, .. }), "{e}");
    assert!(e.to_string().contains(&backup.address), "{e}");
}

/// A gateway that answers honestly unless `silent` is set.
fn switchable(silent: &Arc<AtomicBool>) -> FakeUdp {
    let silent = silent.clone();
    FakeUdp::new(Box::new(move |f, _| {
        if silent.load(Ordering::Relaxed) {
            vec![]
        } else {
            vec![honest(f)]
        }
    }))
}

fn deposit_seqs(fake: &FakeUdp) -> Vec<u8> {
    fake.seen()
        .iter()
        .filter_map(|f| match f.message {
            Message::Deposit(d) => Some(d.seq),
            _ => None,
        })
        .collect()
}

#[test]
fn a_deposit_moved_to_the_other_gateway_keeps_its_seq_unless_that_one_was_sent_it() {
    let (a_silent, b_silent) = (
        Arc::new(AtomicBool::new(true)),
        Arc::new(AtomicBool::new(false)),
    );
    let (a, b) = (switchable(&a_silent), switchable(&b_silent));
    let mut c = GatewayClient::new(Transport::udp(&a.address).unwrap(), config(20, 0))
        .with_backup(Transport::udp(&b.address).unwrap());
    // A silent: seq 0 moves to B with its seq.
    assert_eq!(c.deposit(0.0, 0.0, 1.0, 0).unwrap(), 0);
    assert_eq!((deposit_seqs(&a), deposit_seqs(&b)), (vec![0], vec![0]));
    // B silent, A back: seq 1 moves to A.
    a_silent.store(false, Ordering::Relaxed);
    b_silent.store(true, Ordering::Relaxed);
    assert_eq!(c.deposit(0.0, 0.0, 1.0, 0).unwrap(), 1);
    assert_eq!(c.active(), Which::Primary);
    // 254 deposits on A: seqs 2..=255, then the counter wraps to 0.
    for seq in 2..=255u8 {
        assert_eq!(c.deposit(0.0, 0.0, 1.0, 0).unwrap(), seq);
    }
    // A silent again: seq 0 moves to B, which applied a seq 0 of this client and would answer
    // it without applying; so B gets a seq it was not sent (1 it was sent too, so 2).
    a_silent.store(true, Ordering::Relaxed);
    b_silent.store(false, Ordering::Relaxed);
    assert_eq!(c.deposit(0.0, 0.0, 1.0, 0).unwrap(), 2);
    assert_eq!(deposit_seqs(&a).last(), Some(&0));
    assert_eq!(deposit_seqs(&b), vec![0, 1, 2]);
}

#[test]
fn same_gateway_deposits_are_not_resent_after_a_switch() {
    let primary = FakeUdp::new(Box::new(|_, _| vec![]));
    let backup = FakeUdp::new(Box::new(|f, _| vec![honest(f)]));
    let mut c = GatewayClient::new(
        Transport::udp(&primary.address).unwrap(),
        ClientConfig {
            deposit_retry: DepositRetry::SameGateway,
            ..config(20, 0)
        },
    )
    .with_backup(Transport::udp(&backup.address).unwrap());
    let e = c.deposit(0.0, 0.0, 1.0, 0).unwrap_err();
    assert!(matches!(e, ClientError::Timeout { .. }), "{e}");
    assert!(backup.seen().is_empty(), "never sent to the backup");
    assert_eq!(c.active(), Which::Backup, "but the next request goes there");
    assert_eq!(c.deposit(0.0, 0.0, 1.0, 0).unwrap(), 1);
}

#[test]
fn a_udp_port_nobody_listens_on_fails_fast_as_unreachable() {
    let address = UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .to_string();
    let mut c = GatewayClient::new(Transport::udp(&address).unwrap(), config(2000, 1));
    let t0 = Instant::now();
    let e = c.ping().unwrap_err();
    assert!(matches!(e, ClientError::Unreachable { .. }), "{e}");
    assert!(
        t0.elapsed() < Duration::from_millis(1500),
        "{:?}",
        t0.elapsed()
    );
}

#[test]
fn non_finite_requests_are_refused_before_sending() {
    let fake = FakeUdp::new(Box::new(|f, _| vec![honest(f)]));
    let mut c = GatewayClient::new(Transport::udp(&fake.address).unwrap(), config(100, 0));
    let e = c.pir(f32::NAN, 0.0, 0.0, 0.1, 0).unwrap_err();
    assert!(matches!(e, ClientError::Encode { .. }), "{e}");
    assert!(fake.seen().is_empty());
}

#[test]
fn over_a_pty_replies_arriving_a_byte_at_a_time_are_decoded() {
    let pty = nix::pty::openpty(None, None).unwrap();
    serial::configure(&pty.slave, nix::sys::termios::BaudRate::B9600).unwrap();
    let mut slave = File::from(pty.slave);
    let responder = std::thread::spawn(move || {
        let mut decoder = pheromone_gateway_codec::Decoder::new();
        let mut buf = [0u8; 64];
        let mut answered = 0;
        while answered < 3 {
            let n = slave.read(&mut buf).unwrap();
            let mut frames = Vec::new();
            decoder.feed(&buf[..n], |o| frames.push(o.unwrap()));
            for f in frames {
                for byte in honest(f) {
                    slave.write_all(&[byte]).unwrap();
                }
                answered += 1;
            }
        }
        slave
    });
    let master = Transport::serial_fd(pty.master, "pty").unwrap();
    let mut c = GatewayClient::new(master, config(2000, 0));
    assert_eq!(c.ping().unwrap().frame_seq, 7);
    assert_eq!(c.pir(3.0, 4.0, 0.0, 0.1, 0).unwrap().p_right, 4.0);
    assert_eq!(c.deposit(3.0, 4.0, 1.0, 0).unwrap(), 0);
    let _slave = responder.join().unwrap();
}

#[test]
fn a_rate_limited_request_backs_off_and_is_sent_again_without_switching() {
    // "Over your rate" to the first four requests, then honest.
    let limited = |f: Frame, nth: usize| {
        if nth < 4 {
            vec![wire(f.client_id, Message::Error(ErrorReason::RateLimited))]
        } else {
            vec![honest(f)]
        }
    };
    let fake = FakeUdp::new(Box::new(limited));
    let backup = FakeUdp::new(Box::new(|f, _| vec![honest(f)]));
    let mut c = GatewayClient::new(Transport::udp(&fake.address).unwrap(), config(200, 0))
        .with_backup(Transport::udp(&backup.address).unwrap());
    let started = Instant::now();
    assert_eq!(c.deposit(2.0, 3.0, 1.0, 1).unwrap(), 0);
    let waited = started.elapsed();
    assert_eq!(c.backoffs(), 4);
    assert_eq!(c.active(), Which::Primary, "no switch for a rate limit");
    assert!(backup.seen().is_empty());
    // 10 + 20 + 40 + 80 ms of backoff.
    assert!(waited >= Duration::from_millis(150), "{waited:?}");
    let seqs: Vec<u8> = fake
        .seen()
        .iter()
        .map(|f| match f.message {
            Message::Deposit(d) => d.seq,
            m => panic!("{m:?}"),
        })
        .collect();
    assert_eq!(seqs, vec![0; 5], "the same deposit, sent five times");
    // A gateway that stays over the rate: the request fails with its reason once the
    // backoff's budget is spent.
    let always = FakeUdp::new(Box::new(|f: Frame, _| {
        vec![wire(f.client_id, Message::Error(ErrorReason::RateLimited))]
    }));
    let mut c = GatewayClient::new(
        Transport::udp(&always.address).unwrap(),
        ClientConfig {
            rate_limited_wait: Duration::from_millis(100),
            ..config(200, 0)
        },
    );
    let e = c.pir(1.0, 1.0, 0.0, 0.1, 0).unwrap_err();
    assert!(
        matches!(
            e,
            ClientError::ErrorReply {
                reason: ErrorReason::RateLimited,
                ..
            }
        ),
        "{e}"
    );
    assert!(c.backoffs() >= 2, "{}", c.backoffs());
}
