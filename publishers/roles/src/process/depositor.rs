//! The depositor's process loop.

use std::time::Duration;

use iceoryx2::node::Node;
use pheromone_field::process::lockstep::{self, Participant};
use pheromone_field::shm::{DepositPublisher, Svc};

use crate::depositor::Depositor;
use crate::{
    receiver, role_loop, summary_of, ProcessError, RobotServices, RoleOptions, RoleSummary,
};
use pheromone_messages::PoseMsg;

/// The depositor process: pose → deposits into the field. In lockstep it acknowledges each
/// step once its deposit is in the field's queue; a deposit the field did not take ends the run
/// (the field's answer would differ from a single-process run's).
pub fn run_depositor(
    node: &Node<Svc>,
    o: &RoleOptions,
    config: crate::depositor::DepositorConfig,
) -> Result<RoleSummary, ProcessError> {
    let robot = o.robot;
    let mut depositor = Depositor::new(config).map_err(|source| ProcessError::Depositor {
        robot: None,
        source,
    })?;
    let s = RobotServices::new(&o.world, robot);
    let poses = receiver::<PoseMsg>(node, &s.pose)?;
    let mut publisher =
        DepositPublisher::attach_within(node, &o.field, robot, Duration::from_secs(30))?;
    if o.lockstep {
        // The field acknowledges every tick: nothing is left to flush at the end.
        publisher.flush_timeout = Duration::ZERO;
    }
    let end = Participant::join(node, &o.world)?;
    let mut summary = summary_of(robot, "depositor");
    let mut rejected = 0u64;
    let lockstep = o.lockstep;
    role_loop(
        node,
        &end,
        &poses,
        |m: &PoseMsg| m.step,
        &mut summary,
        |p| {
            match depositor.process(p) {
                Ok(Some(d)) => match publisher.send(d) {
                    Ok(()) => {}
                    Err(e) if lockstep => return Err(e.into()),
                    Err(e) => eprintln!("depositor r{robot}: {e}"),
                },
                Ok(None) => {}
                Err(e) => {
                    rejected += 1;
                    eprintln!("depositor r{robot}: pose of step {} rejected: {e}", p.step);
                }
            }
            if lockstep {
                end.ack(p.step, lockstep::role::DEPOSITOR, robot)?;
            }
            Ok(())
        },
        || Ok(()),
    )?;
    summary.rejected = rejected;
    Ok(summary)
}
