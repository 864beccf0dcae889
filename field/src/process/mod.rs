//! What the processes around a field need beyond the client API: the field process's own loop
//! (`run`: pace, spin, stats, housekeeping), small typed links between processes (`link`), the
//! lockstep by which a simulation steps the field and the robots together (`lockstep`),
//! `SCHED_FIFO` and `mlockall` (`realtime`), and checkpoint files (`checkpoint`). A program that
//! only reads a field and deposits into it needs none of these: see the crate root and `prelude`.

pub mod checkpoint;
pub mod link;
pub mod lockstep;
pub mod realtime;
pub mod run;
