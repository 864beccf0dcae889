//! The frame `pheromone export` writes: a running field's next frame, or its current one when
//! none comes in time (a paused field, one waiting for its clock) or when the field is a mirror
//! whose origin went silent (it publishes nothing until its origin is back).

use std::time::{Duration, Instant};

use iceoryx2::node::Node;
use pheromone_field::shm::{mirror_info, FieldReader, MirrorInfo, ShmError, Svc};

/// Waiting for the frame failed.
#[derive(Debug, thiserror::Error)]
pub enum WaitError {
    #[error(transparent)]
    Shm(#[from] ShmError),
    #[error("interrupted while waiting for a frame of field '{0}'")]
    Interrupted(String),
}

pheromone_field::from_shm_errors!(WaitError);

/// What [`next_frame`] found; the frame is the one the reader then holds.
#[derive(Debug, Clone)]
pub struct NextFrame {
    /// A frame newer than the one held on attaching came.
    pub fresh: bool,
    /// The field's mirror state, if it is a mirror.
    pub mirror: Option<MirrorInfo>,
}

impl NextFrame {
    /// The mirror state of a stale mirror (its current frame was taken at once).
    pub fn stale_mirror(&self) -> Option<&MirrorInfo> {
        self.mirror.as_ref().filter(|m| m.stale)
    }
}

/// Waits up to `timeout` for a frame of `field` newer than the one `reader` holds (a stale
/// mirror's current frame at once); Ctrl-C or SIGTERM (seen on the node) interrupts it.
pub fn next_frame(
    node: &Node<Svc>,
    reader: &mut FieldReader,
    field: &str,
    timeout: Duration,
) -> Result<NextFrame, WaitError> {
    let mirror = mirror_info(node, field)?;
    let fresh = match mirror.as_ref().filter(|m| m.stale) {
        Some(_) => {
            if reader.frame().is_none() {
                reader.wait_frame(timeout)?;
            }
            false
        }
        None => wait_fresh(node, reader, field, timeout)?,
    };
    Ok(NextFrame { fresh, mirror })
}

/// Waits up to `timeout` for a frame newer than the one `reader` holds; whether one came.
fn wait_fresh(
    node: &Node<Svc>,
    reader: &mut FieldReader,
    field: &str,
    timeout: Duration,
) -> Result<bool, WaitError> {
    let held = reader.frame().map(|f| f.header.sequence);
    let deadline = Instant::now() + timeout;
    let mut fresh = false;
    while !fresh {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            break;
        }
        reader.wait_frame(left.min(Duration::from_millis(200)))?;
        fresh = reader
            .frame()
            .is_some_and(|f| Some(f.header.sequence) != held);
        if pheromone_field::shm::should_stop(node) {
            return Err(WaitError::Interrupted(field.to_string()));
        }
    }
    Ok(fresh)
}
