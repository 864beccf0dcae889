//! `FieldRunOptions::spin` (`pheromone field --spin-us`): the field sleeps until `spin` before
//! its next deadline, then polls (the clock, and in the on-deposit mode the deposit queue) until
//! the deadline. A sleep ends one OS wake-up late (tens to hundreds of µs on a VM, more under
//! load); a poll ends at once. The cost is the polling: at most `spin` of CPU per period, so
//! `min(spin, period) / period` of a core (a spin as long as the period polls all the time).

use std::time::{Duration, Instant};

/// How a poll ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Polled {
    /// The deadline came.
    Deadline,
    /// `ready` said yes.
    Ready,
    /// SIGINT or SIGTERM asked the process to stop.
    Stop,
}

/// When to stop sleeping and start polling for `deadline`.
pub(super) fn sleep_until(deadline: Instant, spin: Duration) -> Instant {
    deadline.checked_sub(spin).unwrap_or(deadline)
}

/// Polls `ready` until `deadline` (busy, with a spin-loop hint between polls); also ends on a
/// termination request, which a poll cannot otherwise see.
pub(super) fn poll_until<E>(
    deadline: Instant,
    mut ready: impl FnMut() -> Result<bool, E>,
) -> Result<Polled, E> {
    loop {
        if ready()? {
            return Ok(Polled::Ready);
        }
        if crate::shm::stop_requested() {
            return Ok(Polled::Stop);
        }
        if Instant::now() >= deadline {
            return Ok(Polled::Deadline);
        }
        std::hint::spin_loop();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_poll_ends_at_the_deadline_or_when_ready_and_never_before() {
        let start = Instant::now();
        let deadline = start + Duration::from_millis(3);
        let end = poll_until::<()>(deadline, || Ok(false)).unwrap();
        assert_eq!(end, Polled::Deadline);
        assert!(Instant::now() >= deadline);
        let mut polls = 0;
        let end = poll_until::<()>(start + Duration::from_secs(60), || {
            polls += 1;
            Ok(polls == 5)
        })
        .unwrap();
        assert_eq!((end, polls), (Polled::Ready, 5));
        assert_eq!(
            sleep_until(deadline, Duration::from_millis(1)),
            deadline - Duration::from_millis(1)
        );
    }
}
