//! The lockstep protocol of a simulated world `W`: what makes a run as separate processes give
//! the same answer as the same run in one process.
//!
//! One *conductor* (the world, or the graph writer) owns the clock `sim/W/clock`. Every other
//! process of the run is a *participant*: the field, each robot's localizer, depositor and
//! follower, and the observer of `pheromone sim`. A participant creates every other port it
//! needs first and joins last ([`Participant::join`]): it subscribes to the clock, opens the
//! step-done service `sim/W/step-done` and wakes the conductor on `sim/W/attached`. So once the
//! conductor counts all participants on its clock ([`Conductor::wait_for_participants`], woken
//! by each join, no fixed deadline per process), every port of the run exists, and every message
//! sent from then on is delivered.
//!
//! One step `k`, as the world runs it (`pheromone_world::run_world`):
//! 1. the world publishes step `k`'s sensors and truth and sends the scripted deposits due;
//! 2. each localizer turns its sensors into a pose; each depositor turns the pose into a deposit
//!    (or none), sends it to the field and then acknowledges step `k` ([`StepAck`]);
//! 3. once every depositor has acknowledged, the world sends clock `k` ([`Conductor::tick`]):
//!    every deposit of step `k` is in the field's queue by then;
//! 4. the field ticks once, publishing frame `k + 1`, and acknowledges; every follower waits for
//!    that frame and answers with its command; the observer records the frame and acknowledges;
//! 5. once every acknowledgement and command of step `k` is in, the world advances.
//!
//! The end is announced with a clock message whose `finished` is 1, also after a failure, so
//! every participant stops.

use std::time::{Duration, Instant};

use iceoryx2::node::Node;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;

use crate::messages::ClockMsg;
use crate::process::link::{Receiver, Sender};
use crate::shm::{
    now_ns, service_err, service_name, AttachError, ReceiveError, SendError, ShmError, Svc,
};

/// Who acknowledges a step (`StepAck::role`).
pub mod role {
    /// The field ticked for the step (its frame is published).
    pub const FIELD: u32 = 1;
    /// A depositor sent everything it deposits for the step.
    pub const DEPOSITOR: u32 = 2;
    /// The observer of `pheromone sim` recorded the step's frame.
    pub const OBSERVER: u32 = 3;
    /// A mapper (`pheromone mapper`) published its map frame of the step and holds the peer
    /// frames it merges at the next step.
    pub const MAPPER: u32 = 4;

    /// A role's name in messages.
    pub fn name(role: u32) -> &'static str {
        match role {
            FIELD => "field",
            DEPOSITOR => "depositor",
            OBSERVER => "observer",
            MAPPER => "mapper",
            _ => "unknown role",
        }
    }
}

/// "Done with step `step`", from one participant to the conductor.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[repr(C)]
pub struct StepAck {
    /// CLOCK_MONOTONIC (ns) when the acknowledgement was sent.
    pub stamp_ns: u64,
    /// The step acknowledged.
    pub step: u64,
    /// The robot the participant serves (0 for a participant of no robot, such as the field).
    pub robot_id: u32,
    /// One of [`role`].
    pub role: u32,
}

// repr(C): numbers and arrays of numbers only.
crate::wire_type!(StepAck, "StepAck", size = 24, align = 8);

use crate::wire::{
    attached_service, clock_services, step_done_services, ACK_LINK, CLOCK_LINK, MAX_PARTICIPANTS,
};

fn attached_event(
    node: &Node<Svc>,
    world: &str,
) -> Result<iceoryx2::service::port_factory::event::PortFactory<Svc>, AttachError> {
    let service = attached_service(world);
    Ok(node
        .service_builder(&service_name(&service)?)
        .event()
        .max_notifiers(MAX_PARTICIPANTS)
        .max_listeners(4)
        .max_nodes(MAX_PARTICIPANTS + 4)
        .open_or_create()
        .map_err(|e| service_err(&service, "open or create", e))?)
}

/// The conductor's side of the joins: woken by each participant that joins.
pub struct JoinWatch {
    world: String,
    listener: Listener<Svc>,
}

impl JoinWatch {
    /// Listens for the joins of world `world`'s participants. Create it before counting them.
    pub fn create(node: &Node<Svc>, world: &str) -> Result<Self, AttachError> {
        let listener = attached_event(node, world)?
            .listener_builder()
            .create()
            .map_err(|e| service_err(&attached_service(world), "create listener", e))?;
        Ok(Self {
            world: world.to_string(),
            listener,
        })
    }

    /// Waits until `count()` (the participants attached, as the conductor's ports see them)
    /// reaches `expected`, woken by each join; returns how long it took. `what` names the
    /// participants for the error.
    pub fn wait(
        &self,
        node: &Node<Svc>,
        expected: usize,
        what: &str,
        timeout: Duration,
        count: impl Fn() -> usize,
    ) -> Result<Duration, LockstepError> {
        let started = Instant::now();
        let deadline = started + timeout;
        loop {
            if count() >= expected {
                return Ok(started.elapsed());
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(LockstepError::Attach {
                    world: self.world.clone(),
                    attached: count(),
                    expected,
                    what: what.to_string(),
                    timeout_s: timeout.as_secs_f64(),
                });
            }
            if crate::shm::should_stop(node) {
                return Err(LockstepError::Interrupted {
                    world: self.world.clone(),
                });
            }
            // A join notifies; a participant that left again does not, so the wait is bounded.
            match crate::shm::listener_timed_wait(
                &self.listener,
                left.min(Duration::from_millis(500)),
            ) {
                Ok(_) | Err(iceoryx2::port::listener::ListenerWaitError::InterruptSignal) => {}
                Err(e) => {
                    let e = service_err(&attached_service(&self.world), "wait", e);
                    return Err(ReceiveError::from(e).into());
                }
            }
        }
    }
}

/// Tells world `world`'s conductor that this process has joined (call it once every port of
/// the process exists). Keep the notifier for as long as the process takes part.
pub fn announce_join(node: &Node<Svc>, world: &str) -> Result<Notifier<Svc>, AttachError> {
    let service = attached_service(world);
    let notifier = attached_event(node, world)?
        .notifier_builder()
        .create()
        .map_err(|e| service_err(&service, "create notifier", e))?;
    // No listener yet (the conductor starts later) is fine: it counts the participants when it
    // starts waiting.
    notifier
        .notify()
        .map_err(|e| service_err(&service, "notify", e))?;
    Ok(notifier)
}

/// Waits until every key of `missing` has arrived, for at most `stall` without progress:
/// `next(timeout)` waits up to `timeout` for the next arrival and returns its key, or `None`
/// (a timeout, or a message that completes nothing). `name` names a missing key for the error.
pub fn collect_step<K: PartialEq>(
    node: &Node<Svc>,
    world: &str,
    step: u64,
    missing: &mut Vec<K>,
    stall: Duration,
    name: impl Fn(&K) -> String,
    mut next: impl FnMut(Duration) -> Result<Option<K>, ShmError>,
) -> Result<(), LockstepError> {
    let mut deadline = Instant::now() + stall;
    while !missing.is_empty() {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            let mut names: Vec<String> = missing.iter().map(&name).collect();
            names.sort();
            return Err(LockstepError::Stalled {
                world: world.to_string(),
                step,
                missing: names.join(", "),
                timeout_s: stall.as_secs_f64(),
            });
        }
        if crate::shm::should_stop(node) {
            return Err(LockstepError::Interrupted {
                world: world.to_string(),
            });
        }
        if let Some(k) = next(left.min(Duration::from_millis(100)))? {
            if let Some(i) = missing.iter().position(|m| *m == k) {
                missing.swap_remove(i);
                deadline = Instant::now() + stall;
            }
        }
    }
    Ok(())
}

/// Why the conductor gave up.
#[derive(Debug, thiserror::Error)]
pub enum LockstepError {
    /// A shared-memory operation (attaching, sending the clock, receiving acknowledgements)
    /// failed.
    #[error(transparent)]
    Shm(#[from] ShmError),
    #[error(
        "only {attached} of the {expected} processes of the run ({what}) joined world '{world}' \
         within {timeout_s:.1} s (raise --attach-timeout on a slow host)"
    )]
    /// Not every participant joined within the attach timeout.
    Attach {
        /// The world.
        world: String,
        /// Participants on the clock when the wait gave up.
        attached: usize,
        /// Participants the run needs.
        expected: usize,
        /// Who they are, for the message (e.g. `field, localizers, depositors`).
        what: String,
        /// How long the conductor waited (s).
        timeout_s: f64,
    },
    #[error(
        "world '{world}': step {step} was not acknowledged by {missing} within {timeout_s:.1} s \
         (raise --stall-timeout on a slow host)"
    )]
    /// Some participants did not acknowledge a step within the stall timeout (a process died
    /// or hangs, or the host is too slow).
    Stalled {
        /// The world.
        world: String,
        /// The step waited for.
        step: u64,
        /// The participants that did not acknowledge it, sorted and comma-separated (e.g.
        /// `depositor r2, field`).
        missing: String,
        /// The longest wait without progress allowed (s).
        timeout_s: f64,
    },
    /// A termination signal stopped the wait.
    #[error("world '{world}': interrupted")]
    Interrupted {
        /// The world.
        world: String,
    },
}

crate::from_shm_errors!(LockstepError);

/// The conductor's end of the protocol: the clock, the acknowledgements, the joins.
pub struct Conductor {
    world: String,
    clock: Sender<ClockMsg>,
    /// None for a world on wall time: nobody waits, and acknowledgements go nowhere.
    acks: Option<Receiver<StepAck>>,
    joins: JoinWatch,
    /// Acknowledgements of a later step that arrived early.
    early: Vec<StepAck>,
}

impl Conductor {
    /// The conductor of world `world`; `lockstep` false for a world on wall time, which
    /// collects no acknowledgements.
    pub fn create(node: &Node<Svc>, world: &str, lockstep: bool) -> Result<Self, AttachError> {
        let joins = JoinWatch::create(node, world)?;
        let (clock_service, clock_wake) = clock_services(world);
        let (ack_service, ack_wake) = step_done_services(world);
        Ok(Self {
            world: world.to_string(),
            clock: Sender::create(node, &clock_service, &clock_wake, CLOCK_LINK)?,
            acks: if lockstep {
                Some(Receiver::create(node, &ack_service, &ack_wake, ACK_LINK)?)
            } else {
                None
            },
            joins,
            early: Vec::new(),
        })
    }

    /// Participants subscribed to the clock now.
    pub fn participants(&self) -> usize {
        self.clock.receivers()
    }

    /// Waits until `expected` participants have joined, woken by each join; returns how long
    /// it took. `what` names them for the error.
    pub fn wait_for_participants(
        &self,
        node: &Node<Svc>,
        expected: usize,
        what: &str,
        timeout: Duration,
    ) -> Result<Duration, LockstepError> {
        self.joins
            .wait(node, expected, what, timeout, || self.participants())
    }

    /// Sends clock message `step` (the field ticks once for it).
    pub fn tick(&self, step: u64, sim_time_s: f64, dt_s: f64) -> Result<(), SendError> {
        self.clock.send(ClockMsg {
            stamp_ns: now_ns(),
            step,
            sim_time_s,
            dt_s,
            finished: 0,
            _pad: 0,
        })?;
        Ok(())
    }

    /// Announces the end of the run: every participant stops.
    pub fn finish(&self, steps: u64, sim_time_s: f64, dt_s: f64) -> Result<(), SendError> {
        self.clock.send(ClockMsg {
            stamp_ns: now_ns(),
            step: steps,
            sim_time_s,
            dt_s,
            finished: 1,
            _pad: 0,
        })?;
        Ok(())
    }

    /// Waits until every `(role, robot)` of `expected` has acknowledged `step`, for at most
    /// `stall` without progress.
    pub fn collect(
        &mut self,
        node: &Node<Svc>,
        step: u64,
        expected: &[(u32, u32)],
        stall: Duration,
    ) -> Result<(), LockstepError> {
        let Some(acks) = self.acks.as_ref() else {
            return Ok(()); // on wall time nobody waits
        };
        let early_store = &mut self.early;
        let mut missing: Vec<(u32, u32)> = expected.to_vec();
        let take = |a: &StepAck, missing: &mut Vec<(u32, u32)>| {
            if let Some(i) = missing.iter().position(|m| *m == (a.role, a.robot_id)) {
                missing.swap_remove(i);
            }
        };
        let early = std::mem::take(early_store);
        for a in early {
            if a.step == step && expected.contains(&(a.role, a.robot_id)) {
                take(&a, &mut missing);
            } else if a.step >= step {
                early_store.push(a);
            }
        }
        collect_step(
            node,
            &self.world,
            step,
            &mut missing,
            stall,
            |(r, id)| match *r {
                role::DEPOSITOR | role::MAPPER => format!("{} r{id}", role::name(*r)),
                r => role::name(r).to_string(),
            },
            |timeout| {
                Ok(match acks.recv_timeout(timeout)? {
                    Some(a) if a.step == step && expected.contains(&(a.role, a.robot_id)) => {
                        Some((a.role, a.robot_id))
                    }
                    // Of this step, but for the other collection of the step (a mapper that
                    // acknowledged before every depositor did): kept for it.
                    Some(a) if a.step >= step => {
                        early_store.push(a);
                        None
                    }
                    _ => None, // a repeated acknowledgement of an earlier step, or nothing yet
                })
            },
        )
    }
}

/// A participant's end: the clock (its steps and its end) and the acknowledgements.
pub struct Participant {
    clock: Receiver<ClockMsg>,
    acks: Sender<StepAck>,
    /// Kept so the conductor's listener stays connected to a live notifier.
    _attached: Notifier<Svc>,
    /// The conductor has been seen on the clock (so its absence later means it is gone).
    seen: std::cell::Cell<bool>,
    /// The conductor's step count when it announced the end.
    final_steps: std::cell::Cell<Option<u64>>,
}

impl Participant {
    /// Joins world `world`. Create every other port first: the conductor starts the run once all
    /// participants have joined, and sends to whatever exists by then.
    pub fn join(node: &Node<Svc>, world: &str) -> Result<Self, AttachError> {
        let (ack_service, ack_wake) = step_done_services(world);
        let acks = Sender::create(node, &ack_service, &ack_wake, ACK_LINK)?;
        let (clock_service, clock_wake) = clock_services(world);
        let clock = Receiver::create(node, &clock_service, &clock_wake, CLOCK_LINK)?;
        let attached = announce_join(node, world)?;
        Ok(Self {
            clock,
            acks,
            _attached: attached,
            seen: std::cell::Cell::new(false),
            final_steps: std::cell::Cell::new(None),
        })
    }

    /// Acknowledges `step` as `role` (robot `robot_id`); returns whether a conductor got it.
    /// Nobody does for a world on wall time; a lockstep world that misses one reports the
    /// stall itself, naming who did not acknowledge.
    pub fn ack(&self, step: u64, role: u32, robot_id: u32) -> Result<bool, SendError> {
        let n = self.acks.send(StepAck {
            stamp_ns: now_ns(),
            step,
            robot_id,
            role,
        })?;
        Ok(n > 0)
    }

    /// The next clock message, waiting up to `timeout`.
    pub fn next_clock(&self, timeout: Duration) -> Result<Option<ClockMsg>, ReceiveError> {
        let m = self.clock.recv_timeout(timeout)?;
        if let Some(m) = m {
            if m.finished != 0 {
                self.final_steps.set(Some(m.step));
            }
        }
        self.seen.set(self.seen.get() | (self.clock.senders() > 0));
        Ok(m)
    }

    /// True once the conductor has announced the end, or has gone after it was seen (drains
    /// the clock queue: for roles that only watch for the end).
    pub fn finished(&self) -> Result<bool, ReceiveError> {
        let mut done = false;
        while let Some(m) = self.clock.try_recv()? {
            if m.finished != 0 {
                done = true;
                self.final_steps.set(Some(m.step));
            }
        }
        Ok(done || self.conductor_gone())
    }

    /// The conductor was seen on the clock and is gone now (ended or died).
    pub fn conductor_gone(&self) -> bool {
        let attached = self.clock.senders() > 0;
        let gone = self.seen.get() && !attached;
        self.seen.set(self.seen.get() | attached);
        gone
    }

    /// The conductor's step count at its announced end (None when it vanished without one).
    pub fn final_steps(&self) -> Option<u64> {
        self.final_steps.get()
    }

    /// The clock's listener, to wait on together with other ports.
    pub fn clock_listener(&self) -> &Listener<Svc> {
        self.clock.listener()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shm::create_node;

    fn world(tag: &str) -> String {
        format!("lockstep-test-{}-{tag}", std::process::id())
    }

    const STALL: Duration = Duration::from_secs(10);

    #[test]
    fn an_ack_for_the_other_collection_of_the_step_is_kept_for_it() {
        let node = create_node(&format!("lockstep-test-{}-keep", std::process::id())).unwrap();
        let w = world("keep");
        let mut conductor = Conductor::create(&node, &w, true).unwrap();
        let participant = Participant::join(&node, &w).unwrap();
        // The mapper acknowledges step 3 before the depositor does: the depositors' collection
        // of step 3 must not lose it.
        assert!(participant.ack(3, role::MAPPER, 0).unwrap());
        assert!(participant.ack(3, role::DEPOSITOR, 0).unwrap());
        conductor
            .collect(&node, 3, &[(role::DEPOSITOR, 0)], STALL)
            .unwrap();
        // Nothing more is sent: the mappers' collection of step 3 completes from the kept ack.
        conductor
            .collect(&node, 3, &[(role::MAPPER, 0)], Duration::from_millis(300))
            .unwrap();
        // Used once: the same collection again has nothing left and stalls, naming the mapper.
        let err = conductor
            .collect(&node, 3, &[(role::MAPPER, 0)], Duration::from_millis(300))
            .unwrap_err();
        assert!(
            matches!(&err, LockstepError::Stalled { step: 3, missing, .. } if missing == "mapper r0"),
            "{err}"
        );
    }

    #[test]
    fn an_ack_of_an_earlier_step_is_dropped_and_one_of_a_later_step_kept() {
        let node = create_node(&format!("lockstep-test-{}-drop", std::process::id())).unwrap();
        let w = world("drop");
        let mut conductor = Conductor::create(&node, &w, true).unwrap();
        let participant = Participant::join(&node, &w).unwrap();
        assert!(participant.ack(4, role::MAPPER, 1).unwrap()); // stale once step 5 is collected
        assert!(participant.ack(6, role::MAPPER, 2).unwrap()); // early for step 5
        assert!(participant.ack(5, role::DEPOSITOR, 0).unwrap());
        conductor
            .collect(&node, 5, &[(role::DEPOSITOR, 0)], STALL)
            .unwrap();
        let err = conductor
            .collect(&node, 5, &[(role::MAPPER, 1)], Duration::from_millis(300))
            .unwrap_err();
        assert!(
            matches!(&err, LockstepError::Stalled { step: 5, missing, .. } if missing == "mapper r1"),
            "{err}"
        );
        // Step 6's ack waited through step 5's collections.
        conductor
            .collect(&node, 6, &[(role::MAPPER, 2)], Duration::from_millis(300))
            .unwrap();
    }
}
