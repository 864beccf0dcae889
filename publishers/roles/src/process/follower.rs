//! The follower's process loop.

use std::time::Duration;

use field::link::{Receiver, Sender};
use field::lockstep::Participant;
use field::shm::{now_ns, AttachError, FieldReader, Svc};
use iceoryx2::node::Node;

use crate::follower::{Follower, PoseSource};
use crate::{
    receiver, role_loop, sender, summary_of, ProcessError, RobotServices, RoleOptions, RoleSummary,
};
use messages::{CmdMsg, FollowerStatusMsg, PoseMsg, TruthMsg};

/// Steps without a new frame after which a follower checks whether its field is still alive.
const STALE_STEPS: u32 = 10;
/// The follower process: pose + the frame of its step → command and status. The pose is the
/// localizer's estimate, or the world's truth for a follower configured to steer by it.
pub fn run_follower(
    node: &Node<Svc>,
    o: &RoleOptions,
    follower: Follower,
    source: PoseSource,
    dt_s: f64,
) -> Result<RoleSummary, ProcessError> {
    let s = RobotServices::new(&o.world, o.robot);
    match source {
        PoseSource::Estimate => follow(
            node,
            o,
            follower,
            dt_s,
            receiver::<PoseMsg>(node, &s.pose)?,
            |p: &PoseMsg| *p,
        ),
        PoseSource::Truth => follow(
            node,
            o,
            follower,
            dt_s,
            receiver::<TruthMsg>(node, &s.truth)?,
            messages::truth_as_pose,
        ),
    }
}

fn follow<T: std::fmt::Debug + iceoryx2::prelude::ZeroCopySend + Copy + 'static>(
    node: &Node<Svc>,
    o: &RoleOptions,
    mut follower: Follower,
    dt_s: f64,
    poses: Receiver<T>,
    to_pose: impl Fn(&T) -> PoseMsg,
) -> Result<RoleSummary, ProcessError> {
    let (robot, field_name) = (o.robot, o.field.as_str());
    let s = RobotServices::new(&o.world, robot);
    let cmds = sender::<CmdMsg>(node, &s.cmd)?;
    let statuses = sender::<FollowerStatusMsg>(node, &s.status)?;
    let mut reader = FieldReader::attach_within(node, field_name, Duration::from_secs(30))?;
    let end = Participant::join(node, &o.world)?;
    let mut summary = summary_of(robot, "follower");
    let last = std::cell::Cell::new(None::<CmdMsg>);
    let mut rejected = 0u64;
    let (mut stale_steps, mut field_gone) = (0u32, false);
    role_loop(
        node,
        &end,
        &poses,
        |m: &T| to_pose(m).step,
        &mut summary,
        |m| {
            let p = to_pose(m);
            if o.lockstep {
                // The frame the field computed for this step (sequence step + 1), and no other.
                let want = p.step + 1;
                loop {
                    reader.update()?;
                    if reader.frame().is_some_and(|f| f.header.sequence >= want) {
                        break;
                    }
                    if end.conductor_gone() || node.wait(Duration::ZERO).is_err() {
                        return Ok(());
                    }
                    reader.wait_frame_with(o.frame_wait, Duration::from_millis(100))?;
                }
            } else if reader.update()? {
                // A field that died leaves its last frame with the reader: steer on it, say
                // so once, and say when a field of that name publishes again.
                stale_steps = 0;
                if field_gone {
                    field_gone = false;
                    eprintln!("follower r{robot}: field '{field_name}' is publishing again");
                }
            } else {
                stale_steps += 1;
                if stale_steps >= STALE_STEPS && !field_gone && !reader.field_alive() {
                    field_gone = true;
                    eprintln!(
                        "follower r{robot}: field '{field_name}' is gone; steering on its last frame until it returns"
                    );
                }
            }
            if reader.frame().is_none() {
                reader.wait_frame(Duration::from_secs(5))?;
            }
            let Some(frame) = reader.frame() else {
                return Err(AttachError::NoField {
                    field: field_name.to_string(),
                    service: format!("pheromone/{field_name}/frame"),
                }
                .into());
            };
            let (cmd, status) = match follower.step_pose(&frame.view, &p, dt_s) {
                Ok(out) => (out.cmd, Some(out.status)),
                Err(e) => {
                    rejected += 1;
                    eprintln!(
                        "follower r{robot}: step {}: {e}; stopping the robot",
                        p.step
                    );
                    (
                        CmdMsg {
                            robot_id: robot,
                            ..Default::default()
                        },
                        None,
                    )
                }
            };
            send_step(&cmds, &statuses, &last, p.step, (cmd, status))
        },
        || {
            if let Some(c) = last.get() {
                cmds.send(c)?;
            }
            Ok(())
        },
    )?;
    summary.rejected = rejected;
    Ok(summary)
}

/// Sends a step's command, and its status if the step produced one, both stamped now and
/// numbered `step`; keeps the command for a repeated step (`role_loop`'s `on_repeat`).
pub(super) fn send_step(
    cmds: &Sender<CmdMsg>,
    statuses: &Sender<FollowerStatusMsg>,
    last: &std::cell::Cell<Option<CmdMsg>>,
    step: u64,
    (mut cmd, status): (CmdMsg, Option<FollowerStatusMsg>),
) -> Result<(), ProcessError> {
    cmd.step = step;
    cmd.stamp_ns = now_ns();
    cmds.send(cmd)?;
    if let Some(mut st) = status {
        st.step = step;
        st.stamp_ns = cmd.stamp_ns;
        statuses.send(st)?;
    }
    last.set(Some(cmd));
    Ok(())
}
