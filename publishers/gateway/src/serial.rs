//! The gateway on a serial line (a byte stream, e.g. a half-duplex radio modem): bytes are fed to
//! a streaming [`Decoder`] as they arrive, and each decoded frame is answered on the same line,
//! one reply per request.
//!
//! The line is opened raw (no echo, no line editing, no translation of CR/LF or of 0x10/0x11/0x13),
//! 8 data bits, no parity, 1 stop bit, at the baud rate given; `CLOCAL` so a line without modem
//! control signals is served. A pseudo-terminal slave (`/dev/pts/N`) is opened the same way, which
//! is how the tests run it without hardware (a pty does not enforce the baud rate).

use std::fs::File;
use std::io::{ErrorKind, Read, Write};
use std::os::fd::AsFd;
use std::os::unix::fs::OpenOptionsExt;
use std::time::Duration;

use iceoryx2::node::Node;
use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
use nix::sys::termios::{self, BaudRate, ControlFlags, SetArg, SpecialCharacterIndices};
use pheromone_field::process::run::Housekeeping;
use pheromone_field::shm::{now_ns, Svc};
use pheromone_gateway_codec::{Decoder, MAX_ENCODED_BYTES};

use super::{Gateway, GatewayCounters, GatewayError, LOG_EVERY};

/// How long one poll(2) waits before the loop looks at Ctrl-C and the log clock.
const RECEIVE_SLICE: Duration = Duration::from_millis(100);

/// The termios rate of `baud` bits per second; `None` for a rate termios does not define.
pub fn baud_rate(baud: u32) -> Option<BaudRate> {
    use BaudRate::*;
    Some(match baud {
        50 => B50,
        75 => B75,
        110 => B110,
        134 => B134,
        150 => B150,
        200 => B200,
        300 => B300,
        600 => B600,
        1200 => B1200,
        1800 => B1800,
        2400 => B2400,
        4800 => B4800,
        9600 => B9600,
        19200 => B19200,
        38400 => B38400,
        57600 => B57600,
        115200 => B115200,
        230400 => B230400,
        460800 => B460800,
        500000 => B500000,
        576000 => B576000,
        921600 => B921600,
        1000000 => B1000000,
        1152000 => B1152000,
        1500000 => B1500000,
        2000000 => B2000000,
        2500000 => B2500000,
        3000000 => B3000000,
        3500000 => B3500000,
        4000000 => B4000000,
        _ => return None,
    })
}

fn serial_error(
    path: &str,
    action: &'static str,
    source: impl Into<std::io::Error>,
) -> GatewayError {
    GatewayError::Serial {
        path: path.to_string(),
        action,
        source: source.into(),
    }
}

/// Opens the tty at `path` non-blocking, and sets it raw, `baud` bits per second, 8N1, no flow
/// control. A rate termios does not define is [`GatewayError::Config`].
pub fn open(path: &str, baud: u32) -> Result<File, GatewayError> {
    let rate = baud_rate(baud).ok_or_else(|| GatewayError::Config {
        name: "baud",
        value: baud.to_string(),
        reason: "not a standard termios rate (e.g. 9600, 19200, 115200)",
    })?;
    let file = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .custom_flags(nix::libc::O_NOCTTY | nix::libc::O_NONBLOCK)
        .open(path)
        .map_err(|e| serial_error(path, "open", e))?;
    configure(&file, rate).map_err(|e| serial_error(path, "set raw 8N1 mode", e))?;
    Ok(file)
}

/// Raw mode, `rate`, 8N1, receiver on, modem control lines ignored, no flow control; reads
/// return what is there (VMIN = VTIME = 0: the caller waits with poll(2)).
pub fn configure(fd: impl AsFd, rate: BaudRate) -> nix::Result<()> {
    let mut t = termios::tcgetattr(fd.as_fd())?;
    termios::cfmakeraw(&mut t);
    termios::cfsetspeed(&mut t, rate)?;
    t.control_flags &= !(ControlFlags::PARENB
        | ControlFlags::CSTOPB
        | ControlFlags::CSIZE
        | ControlFlags::CRTSCTS);
    t.control_flags |= ControlFlags::CS8 | ControlFlags::CLOCAL | ControlFlags::CREAD;
    t.control_chars[SpecialCharacterIndices::VMIN as usize] = 0;
    t.control_chars[SpecialCharacterIndices::VTIME as usize] = 0;
    termios::tcsetattr(fd.as_fd(), SetArg::TCSANOW, &t)
}

/// Waits up to `timeout` for `fd` to be readable; true if it is (or hung up: the read says how).
pub(crate) fn wait_readable(fd: impl AsFd, timeout: Duration) -> nix::Result<bool> {
    let ms = timeout.as_millis().min(i32::MAX as u128) as i32;
    let mut fds = [PollFd::new(fd.as_fd(), PollFlags::POLLIN)];
    match poll(
        &mut fds,
        PollTimeout::try_from(ms).unwrap_or(PollTimeout::MAX),
    ) {
        Ok(n) => Ok(n > 0),
        Err(nix::errno::Errno::EINTR) => Ok(false),
        Err(e) => Err(e),
    }
}

/// Writes all of `bytes` to a non-blocking fd, waiting with poll(2) when its buffer is full.
pub(crate) fn write_all(file: &mut File, bytes: &[u8]) -> std::io::Result<()> {
    let mut at = 0;
    while at < bytes.len() {
        match file.write(&bytes[at..]) {
            Ok(0) => return Err(ErrorKind::WriteZero.into()),
            Ok(n) => at += n,
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            Err(e) if e.kind() == ErrorKind::WouldBlock => {
                let mut fds = [PollFd::new(file.as_fd(), PollFlags::POLLOUT)];
                match poll(&mut fds, PollTimeout::from(100u16)) {
                    Ok(_) | Err(nix::errno::Errno::EINTR) => {}
                    Err(e) => return Err(e.into()),
                }
            }
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

/// Serves `gateway` on the serial line `port` (from [`open`]) until the node sees a termination
/// request (Ctrl-C, SIGTERM); calls `log` with the counters once a second. Every decoded frame
/// is answered in turn on the same line (half duplex: one reply per request); rejections are
/// counted by the codec's reason ([`Gateway::rejected`]), and those with a trusted client ID get
/// their error reply. `path` names the line in errors.
pub fn serve(
    node: &Node<Svc>,
    gateway: &mut Gateway,
    port: &mut File,
    path: &str,
    mut log: impl FnMut(&GatewayCounters),
) -> Result<(), GatewayError> {
    let mut decoder = Decoder::new();
    let mut input = [0u8; 512];
    let mut out = [0u8; MAX_ENCODED_BYTES];
    let mut outcomes = Vec::new();
    let mut chores = Housekeeping::new(LOG_EVERY);
    while chores.running(node) {
        if chores.due(node) {
            log(gateway.counters());
        }
        if !wait_readable(&*port, RECEIVE_SLICE).map_err(|e| serial_error(path, "poll", e))? {
            continue;
        }
        let n = match port.read(&mut input) {
            Ok(0) => {
                // End of file (a hung-up line): nothing to read; wait on the node (which also
                // sees Ctrl-C) rather than spin.
                if pheromone_field::shm::node_wait(node, RECEIVE_SLICE).is_err() {
                    break;
                }
                continue;
            }
            Ok(n) => n,
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::Interrupted) => {
                continue
            }
            Err(e) => return Err(serial_error(path, "read", e)),
        };
        decoder.feed(&input[..n], |outcome| outcomes.push(outcome));
        for outcome in outcomes.drain(..) {
            let reply = match outcome {
                Ok(frame) => gateway.handle(frame, now_ns())?,
                Err(e) => gateway.rejected(&e),
            };
            if let Some(reply) = reply {
                let len = reply
                    .encode(&mut out)
                    .expect("a reply fits MAX_ENCODED_BYTES");
                write_all(port, &out[..len]).map_err(|e| serial_error(path, "write", e))?;
            }
        }
    }
    log(gateway.counters());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn standard_rates_map_and_others_are_refused_naming_the_value() {
        assert_eq!(baud_rate(9600), Some(BaudRate::B9600));
        assert_eq!(baud_rate(115200), Some(BaudRate::B115200));
        assert_eq!(baud_rate(9601), None);
        assert_eq!(baud_rate(0), None, "B0 hangs the line up: no serving rate");
        let e = open("/nonexistent", 12345).unwrap_err();
        assert!(e.to_string().contains("12345"), "{e}");
    }

    #[test]
    fn a_pty_slave_is_set_raw_8n1_at_the_rate() {
        let pty = nix::pty::openpty(None, None).unwrap();
        let path = nix::unistd::ttyname(&pty.slave).unwrap();
        let file = open(path.to_str().unwrap(), 9600).unwrap();
        let t = termios::tcgetattr(&file).unwrap();
        assert_eq!(termios::cfgetospeed(&t), BaudRate::B9600);
        assert!(t.control_flags.contains(ControlFlags::CS8));
        assert!(!t.control_flags.contains(ControlFlags::PARENB));
        assert!(!t.control_flags.contains(ControlFlags::CSTOPB));
        assert!(!t.local_flags.contains(termios::LocalFlags::ECHO));
        assert!(!t.local_flags.contains(termios::LocalFlags::ICANON));
        assert!(!t.input_flags.contains(termios::InputFlags::IXON));
    }
}
