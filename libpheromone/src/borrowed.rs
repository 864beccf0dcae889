//! The frame a caller has borrowed, kept as its geometry and a pointer into the sample the
//! handle's reader holds, so sampling rebuilds the `FrameView` without asking iceoryx2 again.
#![allow(unsafe_code)]

use pheromone_field::sample::FrameView;
use pheromone_field::shm::Frame;
use pheromone_field::GridGeometry;

/// A borrowed frame's view, valid while the reader keeps the sample (the handle does not update
/// its reader while a frame is borrowed, and drops this before it does).
pub struct Borrowed {
    geometry: GridGeometry,
    channels: usize,
    cells: *const f32,
    len: usize,
}

impl Borrowed {
    pub fn of(frame: &Frame<'_>) -> Self {
        Self {
            geometry: frame.view.geometry,
            channels: frame.view.channels,
            cells: frame.view.cells.as_ptr(),
            len: frame.view.cells.len(),
        }
    }

    pub fn view(&self) -> FrameView<'_> {
        FrameView {
            geometry: self.geometry,
            channels: self.channels,
            // SAFETY: `cells` and `len` come from the slice of the sample the reader holds; it
            // stays mapped and unchanged while this `Borrowed` exists (the handle drops it before
            // updating the reader), and the returned view borrows `self`.
            cells: unsafe { std::slice::from_raw_parts(self.cells, self.len) },
        }
    }
}
