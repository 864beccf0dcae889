//! The follower's process loop.

use std::time::Duration;

use iceoryx2::node::Node;
use pheromone_field::process::link::{Receiver, Sender};
use pheromone_field::process::lockstep::Participant;
use pheromone_field::shm::{now_ns, AttachError, FieldReader, Svc};

use crate::follower::{Follower, PoseSource};
use crate::mapper::{pose_msg_in_frame, Pose2};
use crate::{
    receiver, role_loop, sender, summary_of, ProcessError, RobotServices, RoleOptions, RoleSummary,
};
use pheromone_messages::{CmdMsg, FollowerStatusMsg, PoseMsg, TruthMsg};

/// Steps without a new frame after which a follower checks whether its field is still alive.
const STALE_STEPS: u32 = 10;

/// Own-map steering (seed 004): the follower reads its robot's map frame, field `field`
/// (`<world>-map-r<ID>`, published by its mapper), at its estimate moved into the map's frame,
/// whose origin in the world is `start`.
#[derive(Debug, Clone)]
pub struct OwnMap {
    pub field: String,
    pub start: Pose2,
}

/// The follower process: pose + the frame of its step → command and status. The pose is the
/// localizer's estimate, or the world's truth for a follower configured to steer by it. With
/// `own_map` the frame is the robot's map frame of the step instead of the shared field's.
pub fn run_follower(
    node: &Node<Svc>,
    o: &RoleOptions,
    follower: Follower,
    source: PoseSource,
    dt_s: f64,
    own_map: Option<OwnMap>,
) -> Result<RoleSummary, ProcessError> {
    let s = RobotServices::new(&o.world, o.robot);
    match source {
        PoseSource::Estimate => follow(
            node,
            o,
            (follower, own_map),
            dt_s,
            receiver::<PoseMsg>(node, &s.pose)?,
            |p: &PoseMsg| *p,
        ),
        PoseSource::Truth => follow(
            node,
            o,
            (follower, own_map),
            dt_s,
            receiver::<TruthMsg>(node, &s.truth)?,
            pheromone_messages::truth_as_pose,
        ),
    }
}

/// Whether `header` is the frame a follower steers on at link step `step`: the field's frame
/// `step + 1` (its tick of the step), or with own-map steering the map frame `step` (the
/// mapper's frame after the step; its frame 0 before the first step has field time 0).
fn frame_of_step(header: &pheromone_field::FrameHeader, step: u64, own_map: bool) -> bool {
    if own_map {
        header.sequence > step || (header.sequence == step && header.sim_time_s > 0.0)
    } else {
        header.sequence > step
    }
}

fn follow<T: std::fmt::Debug + iceoryx2::prelude::ZeroCopySend + Copy + 'static>(
    node: &Node<Svc>,
    o: &RoleOptions,
    (mut follower, own_map): (Follower, Option<OwnMap>),
    dt_s: f64,
    poses: Receiver<T>,
    to_pose: impl Fn(&T) -> PoseMsg,
) -> Result<RoleSummary, ProcessError> {
    let robot = o.robot;
    let field_name = own_map
        .as_ref()
        .map_or(o.field.as_str(), |m| m.field.as_str());
    let start = own_map.as_ref().map(|m| m.start);
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
                if !wait_for_step_frame(node, &end, &mut reader, o, (p.step, start.is_some()))? {
                    return Ok(());
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
            let p = match start {
                Some(origin) => pose_msg_in_frame(origin, &p),
                None => p,
            };
            let (cmd, status) = match follower.step_pose(&frame.view, &p, dt_s) {
                Ok(out) => (out.cmd, Some(out.status)),
                Err(e) => {
                    rejected += 1;
                    (stop_after_refusal(robot, p.step, &e), None)
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

/// Waits (lockstep) until the reader holds the frame of `step` (`frame_of_step`), and no other;
/// false when the run ends first.
fn wait_for_step_frame(
    node: &Node<Svc>,
    end: &Participant,
    reader: &mut FieldReader,
    o: &RoleOptions,
    (step, own_map): (u64, bool),
) -> Result<bool, ProcessError> {
    loop {
        reader.update()?;
        if reader
            .frame()
            .is_some_and(|f| frame_of_step(f.header, step, own_map))
        {
            return Ok(true);
        }
        if end.conductor_gone() || pheromone_field::shm::should_stop(node) {
            return Ok(false);
        }
        reader.wait_frame_with(o.frame_wait, Duration::from_millis(100))?;
    }
}

/// The command that stops robot `robot` after its follower refused step `step`, said on stderr.
fn stop_after_refusal(robot: u32, step: u64, e: &impl std::fmt::Display) -> CmdMsg {
    eprintln!("follower r{robot}: step {step}: {e}; stopping the robot");
    CmdMsg {
        robot_id: robot,
        ..Default::default()
    }
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
