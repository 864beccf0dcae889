//! The per-thread last error: a fixed buffer (no allocation) holding the message of the last
//! failed call on this thread, NUL-terminated, for `pheromone_last_error`.

use std::cell::RefCell;
use std::fmt::{self, Write};

use pheromone_field::shm::{AttachError, NameError, ReceiveError, SendError};

use crate::types::{PheromoneStatus, PHEROMONE_ERROR_CAPACITY};

/// A failed call: its status; the message is in this thread's last-error buffer already.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Failure(pub PheromoneStatus);

/// The message buffer: UTF-8, cut at a character boundary when too long, NUL-terminated.
struct Message {
    bytes: [u8; PHEROMONE_ERROR_CAPACITY],
    len: usize,
}

impl Write for Message {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        let room = PHEROMONE_ERROR_CAPACITY - 1 - self.len;
        let mut take = s.len().min(room);
        while !s.is_char_boundary(take) {
            take -= 1;
        }
        self.bytes[self.len..self.len + take].copy_from_slice(&s.as_bytes()[..take]);
        self.len += take;
        self.bytes[self.len] = 0;
        Ok(())
    }
}

thread_local! {
    static LAST: RefCell<Message> = const {
        RefCell::new(Message { bytes: [0; PHEROMONE_ERROR_CAPACITY], len: 0 })
    };
}

/// Records `message` as this thread's last error and returns the failure `status`.
pub fn fail(status: PheromoneStatus, message: fmt::Arguments<'_>) -> Failure {
    LAST.with(|m| {
        if let Ok(mut m) = m.try_borrow_mut() {
            m.len = 0;
            m.bytes[0] = 0;
            // The writer never fails; a Display impl that does leaves the message cut short.
            let _ = m.write_fmt(message);
        }
    });
    Failure(status)
}

/// Returns early with a failure: `bail!(Status, "format", args…)`.
macro_rules! bail {
    ($status:expr, $($arg:tt)*) => {
        return Err($crate::error::fail($status, format_args!($($arg)*)))
    };
}
pub(crate) use bail;

/// The message of this thread's last failure, with its NUL (`""` before any).
pub fn last_message_ptr() -> *const core::ffi::c_char {
    LAST.with(|m| m.as_ptr().cast::<u8>().cast())
}

/// This thread's last message as a Rust string (tests, the C++-free Rust callers).
pub fn last_message() -> String {
    LAST.with(|m| {
        m.try_borrow()
            .map(|m| String::from_utf8_lossy(&m.bytes[..m.len]).into_owned())
            .unwrap_or_default()
    })
}

/// A field error's status.
pub trait Status: std::error::Error {
    fn status(&self) -> PheromoneStatus;
}

impl Status for NameError {
    fn status(&self) -> PheromoneStatus {
        PheromoneStatus::BadArgument
    }
}

impl Status for AttachError {
    fn status(&self) -> PheromoneStatus {
        match self {
            AttachError::NoField { .. } => PheromoneStatus::NoField,
            AttachError::Layout { .. } => PheromoneStatus::Layout,
            AttachError::Name(e) => e.status(),
            AttachError::Interrupted { .. } => PheromoneStatus::Interrupted,
            AttachError::Node { .. }
            | AttachError::Domain(_)
            | AttachError::BadFrame { .. }
            | AttachError::Service(_) => PheromoneStatus::ShmError,
        }
    }
}

impl Status for SendError {
    fn status(&self) -> PheromoneStatus {
        match self {
            SendError::NoSubscriber { .. } | SendError::NotDelivered { .. } => {
                PheromoneStatus::NotDelivered
            }
            // `pheromone_deposit_confirmed` got no receipt in time: it may still be applied,
            // once.
            SendError::Unconfirmed { .. } => PheromoneStatus::Timeout,
            // Interrupted while it waited for the receipt: it may still be applied, once.
            SendError::Interrupted { .. } => PheromoneStatus::Interrupted,
            SendError::Service(_) => PheromoneStatus::ShmError,
        }
    }
}

impl Status for ReceiveError {
    fn status(&self) -> PheromoneStatus {
        match self {
            ReceiveError::BadFrame { .. } | ReceiveError::Service(_) => PheromoneStatus::ShmError,
            ReceiveError::Interrupted { .. } => PheromoneStatus::Interrupted,
        }
    }
}

/// A field error as a status and message: the error and its sources, outermost first.
pub fn from_shm(what: &str, e: &impl Status) -> Failure {
    fail(e.status(), format_args!("{what}: {}", Chain(e)))
}

/// An error with its sources, `a: b: c`.
struct Chain<'a>(&'a dyn std::error::Error);

impl fmt::Display for Chain<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.0)?;
        let mut source = self.0.source();
        while let Some(s) = source {
            write!(f, ": {s}")?;
            source = s.source();
        }
        Ok(())
    }
}
