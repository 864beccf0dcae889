//! The C ABI: every `extern "C"` function of `pheromone.h`. Each one checks its pointers, runs
//! the safe call of [`crate::handle`] inside `catch_unwind` (no panic crosses the boundary) and
//! returns a status; the message of a failure is in the thread's last error.
//!
//! Thread safety (also stated on each function in `pheromone.h`): a handle may move between
//! threads but is used by one thread at a time — no two calls on the same handle run at once;
//! different handles are independent; `pheromone_last_error` is per thread.
#![allow(unsafe_code)]

use std::ffi::{c_char, CStr};
use std::panic::{catch_unwind, AssertUnwindSafe};

use crate::error::{bail, fail, last_message_ptr, Failure};
use crate::handle::{Options, PheromoneField};
use crate::types::*;

const BAD: PheromoneStatus = PheromoneStatus::BadArgument;

/// Runs `f`, turning its result or a panic into a status.
fn guard(f: impl FnOnce() -> Result<(), Failure>) -> PheromoneStatus {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(Ok(())) => PheromoneStatus::Ok,
        Ok(Err(Failure(s))) => s,
        Err(_) => {
            fail(
                PheromoneStatus::Internal,
                format_args!("libpheromone: a panic was caught at the C boundary (a bug)"),
            );
            PheromoneStatus::Internal
        }
    }
}

fn null(what: &str) -> Failure {
    fail(BAD, format_args!("{what} is NULL"))
}

/// A C string argument as UTF-8.
///
/// # Safety
/// `p` is NULL or points to a NUL-terminated string that outlives the call.
unsafe fn c_str<'a>(p: *const c_char, what: &str) -> Result<&'a str, Failure> {
    if p.is_null() {
        return Err(null(what));
    }
    // SAFETY: non-null, and the caller guarantees a NUL-terminated string valid for the call.
    let s = unsafe { CStr::from_ptr(p) };
    s.to_str()
        .map_err(|e| fail(BAD, format_args!("{what} is not UTF-8: {e}")))
}

/// A shared reference from a C pointer argument.
///
/// # Safety
/// `p` is NULL or points to a valid, aligned `T` that nothing mutates during the call.
unsafe fn arg<'a, T>(p: *const T, what: &str) -> Result<&'a T, Failure> {
    // SAFETY: the caller guarantees `p` is NULL or valid for reads during the call.
    unsafe { p.as_ref() }.ok_or_else(|| null(what))
}

/// A mutable reference from a C pointer argument.
///
/// # Safety
/// `p` is NULL or points to a valid, aligned `T` that nothing else accesses during the call.
unsafe fn arg_mut<'a, T>(p: *mut T, what: &str) -> Result<&'a mut T, Failure> {
    // SAFETY: the caller guarantees `p` is NULL or valid and unaliased during the call.
    unsafe { p.as_mut() }.ok_or_else(|| null(what))
}

/// Fills `*options` with the defaults: this header's layout version, robot id 0, deposits on,
/// no attach retry, the environment's iceoryx2 domain.
///
/// Thread safety: any thread, any time.
///
/// # Safety
/// `options` is NULL or points to writable memory for a `PheromoneAttachOptions`.
#[no_mangle]
pub unsafe extern "C" fn pheromone_attach_options_init(
    options: *mut PheromoneAttachOptions,
) -> PheromoneStatus {
    guard(|| {
        // SAFETY: forwarded from this function's contract.
        let o = unsafe { arg_mut(options, "options") }?;
        *o = PheromoneAttachOptions::default();
        Ok(())
    })
}

/// Fills `*params` with the Rust depositor's defaults (τ 0.2, γmax 100, z_rng 1 m, ellipse
/// kernel, channel 0, no σ floor).
///
/// Thread safety: any thread, any time.
///
/// # Safety
/// `params` is NULL or points to writable memory for a `PheromoneEllipseParams`.
#[no_mangle]
pub unsafe extern "C" fn pheromone_ellipse_params_init(
    params: *mut PheromoneEllipseParams,
) -> PheromoneStatus {
    guard(|| {
        // SAFETY: forwarded from this function's contract.
        *unsafe { arg_mut(params, "params") }? = PheromoneEllipseParams::default();
        Ok(())
    })
}

/// Attaches to the running field `name` and stores a new handle in `*out` (NULL on failure).
/// Fails with `PHEROMONE_STATUS_NO_FIELD` if no such field runs (after retrying for
/// `options->attach_timeout_ns`), `PHEROMONE_STATUS_LAYOUT` if the field or this program's
/// `pheromone.h` speaks another layout version, `PHEROMONE_STATUS_INTERRUPTED` if a signal the
/// program handles cut a wait between retries short. `options` NULL: the defaults. Installs no
/// signal handler and leaves iceoryx2's log level as it is (`pheromone_set_log_level`).
/// Allocates.
///
/// Thread safety: any thread; handles are independent.
///
/// # Safety
/// `name` is a NUL-terminated string; `options` is NULL or valid; `out` is valid for a write.
#[no_mangle]
pub unsafe extern "C" fn pheromone_field_attach(
    name: *const c_char,
    options: *const PheromoneAttachOptions,
    out: *mut *mut PheromoneField,
) -> PheromoneStatus {
    guard(|| {
        // SAFETY: forwarded from this function's contract.
        let out = unsafe { arg_mut(out, "out") }?;
        *out = std::ptr::null_mut();
        // SAFETY: forwarded from this function's contract.
        let name = unsafe { c_str(name, "name") }?;
        let c = if options.is_null() {
            PheromoneAttachOptions::default()
        } else {
            // SAFETY: non-null, valid per this function's contract.
            *unsafe { arg(options, "options") }?
        };
        let iox_domain = if c.iox_domain.is_null() {
            None
        } else {
            // SAFETY: a non-null domain is a NUL-terminated string per the options' contract.
            Some(unsafe { c_str(c.iox_domain, "options.iox_domain") }?)
        };
        let field = PheromoneField::attach(name, &Options { c, iox_domain })?;
        *out = Box::into_raw(field);
        Ok(())
    })
}

/// Detaches and frees the handle (NULL: nothing to do). Refused with
/// `PHEROMONE_STATUS_BORROWED` while a frame is borrowed (the handle stays valid). A handle that
/// deposited waits up to 1 s for the field to take its deposits.
///
/// Thread safety: not concurrently with any other call on this handle.
///
/// # Safety
/// `field` is NULL or a handle from `pheromone_field_attach` not yet detached.
#[no_mangle]
pub unsafe extern "C" fn pheromone_field_detach(field: *mut PheromoneField) -> PheromoneStatus {
    guard(|| {
        if field.is_null() {
            return Ok(());
        }
        // SAFETY: a live handle per this function's contract.
        unsafe { &*field }.check_detach()?;
        // SAFETY: the handle came from Box::into_raw in attach and is dropped once.
        drop(unsafe { Box::from_raw(field) });
        Ok(())
    })
}

/// Waits up to `timeout_ns` for a frame newer than the one held, as `policy` says:
/// `PHEROMONE_STATUS_OK` when one came, `PHEROMONE_STATUS_TIMEOUT` when none did,
/// `PHEROMONE_STATUS_INTERRUPTED` when a signal the program handles cut the sleep on the frame
/// event short (the program's handler ran; the spin of `PHEROMONE_WAIT_SPIN` and
/// `PHEROMONE_WAIT_BUSY_POLL` make no system call a signal could cut and go on until the frame or
/// the timeout). Refused with `PHEROMONE_STATUS_BORROWED` while a frame is borrowed. Takes the
/// frame-ready notifications pending on `pheromone_field_fd` first: after a `poll` on it, call
/// this with a zero timeout. Does not allocate.
///
/// Thread safety: not concurrently with any other call on this handle.
///
/// # Safety
/// `field` is a live handle.
#[no_mangle]
pub unsafe extern "C" fn pheromone_wait_frame(
    field: *mut PheromoneField,
    policy: PheromoneWaitPolicy,
    timeout_ns: u64,
) -> PheromoneStatus {
    let mut fresh = false;
    let status = guard(|| {
        // SAFETY: forwarded from this function's contract.
        fresh = unsafe { arg_mut(field, "field") }?.wait(policy, timeout_ns)?;
        Ok(())
    });
    match status {
        PheromoneStatus::Ok if !fresh => PheromoneStatus::Timeout,
        s => s,
    }
}

/// Borrows the newest frame held: fills `*view` with its header's numbers and a pointer per
/// channel into shared memory. The frame stays in place (not freed, not overwritten) until
/// `pheromone_frame_release`. Borrowing again before the release gives the same frame.
/// `PHEROMONE_STATUS_NO_FRAME` before the first frame. Does not allocate.
///
/// Thread safety: not concurrently with any other call on this handle.
///
/// # Safety
/// `field` is a live handle; `view` is valid for a write.
#[no_mangle]
pub unsafe extern "C" fn pheromone_frame_borrow(
    field: *mut PheromoneField,
    view: *mut PheromoneFrameView,
) -> PheromoneStatus {
    guard(|| {
        // SAFETY: forwarded from this function's contract.
        let f = unsafe { arg_mut(field, "field") }?;
        // SAFETY: forwarded from this function's contract.
        let v = unsafe { arg_mut(view, "view") }?;
        f.borrow(v)
    })
}

/// Ends the borrow: the view's plane pointers must not be used any more. Releasing when nothing
/// is borrowed is allowed. Does not allocate.
///
/// Thread safety: not concurrently with any other call on this handle.
///
/// # Safety
/// `field` is a live handle.
#[no_mangle]
pub unsafe extern "C" fn pheromone_frame_release(field: *mut PheromoneField) -> PheromoneStatus {
    guard(|| {
        // SAFETY: forwarded from this function's contract.
        unsafe { arg_mut(field, "field") }?.release();
        Ok(())
    })
}

/// `*out` = the bilinear value of `channel` at (x_m, y_m) in the borrowed frame (Rust's
/// `FrameView::value`: 0 outside the grid). Does not allocate.
///
/// Thread safety: not concurrently with a wait, borrow, release, deposit or detach on this
/// handle.
///
/// # Safety
/// `field` is a live handle; `out` is valid for a write.
#[no_mangle]
pub unsafe extern "C" fn pheromone_sample_value(
    field: *const PheromoneField,
    channel: u32,
    x_m: f32,
    y_m: f32,
    out: *mut f32,
) -> PheromoneStatus {
    guard(|| {
        // SAFETY: forwarded from this function's contract.
        let f = unsafe { arg(field, "field") }?;
        // SAFETY: forwarded from this function's contract.
        let out = unsafe { arg_mut(out, "out") }?;
        *out = f.value(channel, x_m, y_m)?;
        Ok(())
    })
}

/// (`*gx`, `*gy`) = ∇P per metre at (x_m, y_m) in the borrowed frame (Rust's
/// `FrameView::gradient`, central differences one cell apart). Does not allocate.
///
/// Thread safety: as `pheromone_sample_value`.
///
/// # Safety
/// `field` is a live handle; `gx` and `gy` are valid for writes.
#[no_mangle]
pub unsafe extern "C" fn pheromone_sample_gradient(
    field: *const PheromoneField,
    channel: u32,
    x_m: f32,
    y_m: f32,
    gx: *mut f32,
    gy: *mut f32,
) -> PheromoneStatus {
    guard(|| {
        // SAFETY: forwarded from this function's contract.
        let f = unsafe { arg(field, "field") }?;
        // SAFETY: forwarded from this function's contract.
        let gx = unsafe { arg_mut(gx, "gx") }?;
        // SAFETY: forwarded from this function's contract.
        let gy = unsafe { arg_mut(gy, "gy") }?;
        (*gx, *gy) = f.gradient(channel, x_m, y_m)?;
        Ok(())
    })
}

/// Samples `channel` of the borrowed frame at `n` points in one call: `xy` holds `2·n` floats,
/// `x0, y0, x1, y1, …` (an array of `struct { float x, y; }`); writes `values[i]` (Rust's
/// `FrameView::value`) when `values` is not NULL and `gradients[2i]`, `gradients[2i + 1]`
/// (`FrameView::gradient`: ∂P/∂x, ∂P/∂y per metre) when `gradients` is not NULL — the numbers
/// of `pheromone_sample_value` / `_gradient` point by point, with the checks made once per call.
/// Every coordinate must be finite (`PHEROMONE_STATUS_BAD_ARGUMENT` names the first that is not,
/// and nothing is written); `values` and `gradients` both NULL is `BAD_ARGUMENT`; `n = 0` does
/// nothing (`xy` may then be NULL). Does not allocate.
///
/// Thread safety: as `pheromone_sample_value`.
///
/// # Safety
/// `field` is a live handle; `xy` is valid for `2·n` floats; `values` is NULL or valid for `n`
/// floats, `gradients` NULL or valid for `2·n` floats, neither overlapping `xy`.
#[no_mangle]
pub unsafe extern "C" fn pheromone_sample_many(
    field: *const PheromoneField,
    channel: u32,
    xy: *const f32,
    n: usize,
    values: *mut f32,
    gradients: *mut f32,
) -> PheromoneStatus {
    guard(|| {
        // SAFETY: forwarded from this function's contract.
        let f = unsafe { arg(field, "field") }?;
        if n > (isize::MAX as usize) / 8 {
            return Err(fail(BAD, format_args!("n = {n}: too many points")));
        }
        let points: &[[f32; 2]] = if n == 0 {
            &[]
        } else if xy.is_null() {
            return Err(null("xy"));
        } else {
            // SAFETY: non-null, valid for 2·n floats per the contract; [f32; 2] has the size of
            // two floats and the alignment of one.
            unsafe { std::slice::from_raw_parts(xy.cast::<[f32; 2]>(), n) }
        };
        let values = (!values.is_null()).then(|| {
            // SAFETY: non-null, valid for n floats and not overlapping `xy` per the contract.
            unsafe { std::slice::from_raw_parts_mut(values, n) }
        });
        let gradients = (!gradients.is_null()).then(|| {
            // SAFETY: non-null, valid for 2·n floats and not overlapping `xy` or `values`.
            unsafe { std::slice::from_raw_parts_mut(gradients.cast::<[f32; 2]>(), n) }
        });
        f.sample_many(channel, points, values, gradients)
    })
}

/// (`*left`, `*right`) = the readings of two antennas half `wheel_base_m` to each side of `pose`
/// in the borrowed frame (Rust's `FrameView::antennas`, seed 002). Does not allocate.
///
/// Thread safety: as `pheromone_sample_value`.
///
/// # Safety
/// `field` is a live handle; `left` and `right` are valid for writes.
#[no_mangle]
pub unsafe extern "C" fn pheromone_sample_antennas(
    field: *const PheromoneField,
    channel: u32,
    pose: PheromonePose,
    wheel_base_m: f32,
    left: *mut f32,
    right: *mut f32,
) -> PheromoneStatus {
    guard(|| {
        // SAFETY: forwarded from this function's contract.
        let f = unsafe { arg(field, "field") }?;
        // SAFETY: forwarded from this function's contract.
        let l = unsafe { arg_mut(left, "left") }?;
        // SAFETY: forwarded from this function's contract.
        let r = unsafe { arg_mut(right, "right") }?;
        (*l, *r) = f.antennas(channel, pose, wheel_base_m)?;
        Ok(())
    })
}

/// `out[0 .. 2·half_sectors + 1]` = the mean of `channel` in each of `2·half_sectors + 1` equal
/// sectors spanning [−90°, 90°] around the heading over the half-disc of radius `radius_m`
/// (Rust's `FrameView::sector_means`, seed 004; sector 0 is the rightmost). `out_len` must be
/// at least `2·half_sectors + 1`. Does not allocate.
///
/// Thread safety: as `pheromone_sample_value`.
///
/// # Safety
/// `field` is a live handle; `out` is valid for `out_len` floats.
#[no_mangle]
pub unsafe extern "C" fn pheromone_sample_sectors(
    field: *const PheromoneField,
    channel: u32,
    pose: PheromonePose,
    radius_m: f32,
    half_sectors: u32,
    out: *mut f32,
    out_len: usize,
) -> PheromoneStatus {
    guard(|| {
        // SAFETY: forwarded from this function's contract.
        let f = unsafe { arg(field, "field") }?;
        if out.is_null() {
            return Err(null("out"));
        }
        let n = 2 * half_sectors as usize + 1;
        if half_sectors > 1024 || out_len < n {
            return Err(fail(
                BAD,
                format_args!(
                    "half_sectors = {half_sectors} needs out_len ≥ {n} (at most 2049), got {out_len}"
                ),
            ));
        }
        // SAFETY: `out` is non-null and valid for `out_len ≥ n` floats per the contract.
        let out = unsafe { std::slice::from_raw_parts_mut(out, n) };
        f.sectors(channel, pose, radius_m, out)
    })
}

/// Sends a deposit to the field (stamped with this handle's robot id and the monotonic clock).
/// Every number must be finite and the kernel known (`PHEROMONE_STATUS_BAD_ARGUMENT`
/// otherwise); `PHEROMONE_STATUS_NOT_DELIVERED` if no field took it. Allocates nothing of its
/// own (iceoryx2 0.10 allocates one small block per sample it sends).
///
/// Thread safety: not concurrently with any other call on this handle.
///
/// # Safety
/// `field` is a live handle; `deposit` is valid for reads.
#[no_mangle]
pub unsafe extern "C" fn pheromone_deposit(
    field: *mut PheromoneField,
    deposit: *const PheromoneDeposit,
) -> PheromoneStatus {
    guard(|| {
        // SAFETY: forwarded from this function's contract.
        let f = unsafe { arg_mut(field, "field") }?;
        // SAFETY: forwarded from this function's contract.
        let d = unsafe { arg(deposit, "deposit") }?;
        f.deposit(d)
    })
}

/// Sends a deposit as `pheromone_deposit` does, then waits at most `timeout_ns` for the field's
/// receipt (any tick rate: the field answers with the frame that applied it):
/// - `PHEROMONE_STATUS_OK`: applied in frame `receipt->sequence` (`PHEROMONE_RECEIPT_APPLIED`),
///   or taken by a mirror for its origin (`PHEROMONE_RECEIPT_FORWARDED`);
/// - `PHEROMONE_STATUS_REJECTED`: the field refused it; `receipt->reason` and the last error
///   say why; nothing was applied;
/// - `PHEROMONE_STATUS_TIMEOUT`: no receipt in time; the deposit may still be applied, at most
///   once (do not resend it blindly);
/// - `PHEROMONE_STATUS_INTERRUPTED`: a signal the program handles cut the wait for the receipt
///   short; as with `TIMEOUT`, the deposit may still be applied, at most once;
/// - `PHEROMONE_STATUS_BAD_ARGUMENT` (before sending) and `_NOT_DELIVERED` as
///   `pheromone_deposit`.
///
/// `receipt` may be NULL; it is written only with an answer (OK or REJECTED). Blocks the calling thread until the receipt or the timeout: for a
/// loop that deposits every step, `pheromone_deposit` does not wait.
///
/// Thread safety: not concurrently with any other call on this handle.
///
/// # Safety
/// `field` is a live handle; `deposit` is valid for reads; `receipt` is NULL or valid for
/// writes.
#[no_mangle]
pub unsafe extern "C" fn pheromone_deposit_confirmed(
    field: *mut PheromoneField,
    deposit: *const PheromoneDeposit,
    timeout_ns: u64,
    receipt: *mut PheromoneReceipt,
) -> PheromoneStatus {
    guard(|| {
        // SAFETY: forwarded from this function's contract.
        let f = unsafe { arg_mut(field, "field") }?;
        // SAFETY: forwarded from this function's contract.
        let d = unsafe { arg(deposit, "deposit") }?;
        let mut got = PheromoneReceipt::default();
        let result = f.deposit_confirmed(d, timeout_ns, &mut got);
        let answered = matches!(result, Ok(()) | Err(Failure(PheromoneStatus::Rejected)));
        // Without an answer (timeout, not delivered, a bad argument) the receipt is untouched.
        if answered && !receipt.is_null() {
            // SAFETY: non-null, valid for writes per this function's contract.
            unsafe { receipt.write(got) };
        }
        result
    })
}

/// Sends seed 000's uncertainty-aware deposit for a pose estimate, as the Rust depositor does:
/// the ellipse of the pose's Σxy block, amount τ (γ = τ / det Σxy ≤ γmax, computed by the
/// field), cut at z_rng. A pose with a non-finite number or a covariance that is not symmetric
/// positive semi-definite is refused (`PHEROMONE_STATUS_BAD_ARGUMENT`, the entry named).
/// Allocates as `pheromone_deposit`.
///
/// Thread safety: not concurrently with any other call on this handle.
///
/// # Safety
/// `field` is a live handle; `pose` and `params` are valid for reads (`params` NULL: defaults).
#[no_mangle]
pub unsafe extern "C" fn pheromone_deposit_pose(
    field: *mut PheromoneField,
    pose: *const PheromonePoseEstimate,
    params: *const PheromoneEllipseParams,
) -> PheromoneStatus {
    guard(|| {
        // SAFETY: forwarded from this function's contract.
        let f = unsafe { arg_mut(field, "field") }?;
        // SAFETY: forwarded from this function's contract.
        let pose = unsafe { arg(pose, "pose") }?;
        let params = if params.is_null() {
            PheromoneEllipseParams::default()
        } else {
            // SAFETY: non-null, valid per this function's contract.
            *unsafe { arg(params, "params") }?
        };
        f.deposit_pose(pose, &params)
    })
}

/// The file descriptor of the handle's frame-ready event, in `*out_fd`, for `poll`/`epoll`/`select`
/// in the program's own event loop: it becomes readable when the field publishes a frame. On
/// readable, call `pheromone_wait_frame(field, policy, 0)`, which takes the pending
/// notifications and the frame (`OK`; `TIMEOUT` after a wake-up for a frame already taken).
/// The descriptor belongs to the handle: valid until `pheromone_field_detach`; do not read,
/// close or change its flags. Does not allocate.
///
/// Thread safety: any thread may poll the descriptor; the calls on the handle stay one thread
/// at a time.
///
/// # Safety
/// `field` is a live handle; `out_fd` is valid for a write.
#[no_mangle]
pub unsafe extern "C" fn pheromone_field_fd(
    field: *const PheromoneField,
    out_fd: *mut core::ffi::c_int,
) -> PheromoneStatus {
    guard(|| {
        use iceoryx2_bb_posix::file_descriptor::FileDescriptorBased;
        // SAFETY: forwarded from this function's contract.
        let f = unsafe { arg(field, "field") }?;
        // SAFETY: forwarded from this function's contract.
        let out = unsafe { arg_mut(out_fd, "out_fd") }?;
        // SAFETY: the value is handed to the caller, who is told (above) that the listener owns
        // it for the handle's life and must not close it; it is not stored here.
        *out = unsafe { f.frame_ready_listener().file_descriptor().native_handle() };
        Ok(())
    })
}

/// Whether the field's process is alive and which generation of it the handle reads, in
/// `*out` (`PheromoneLiveness`): `alive` turns 0 when the field's process died, `generation`
/// counts the field processes the handle has taken frames from (one more after each restart
/// or standby takeover under the name), `sequence` is the newest frame's. A handle keeps
/// working across a restart: wait as before; a new `generation` says the field's state may have
/// been reset. `alive` scans the host's iceoryx2 nodes: call it when frames stop coming, not per
/// frame. Does not wait, does not change the handle's frame.
///
/// Thread safety: one thread at a time per handle, as every call on it.
///
/// # Safety
/// `field` is a live handle; `out` is valid for a write.
#[no_mangle]
pub unsafe extern "C" fn pheromone_field_liveness(
    field: *const PheromoneField,
    out: *mut PheromoneLiveness,
) -> PheromoneStatus {
    guard(|| {
        // SAFETY: forwarded from this function's contract.
        let f = unsafe { arg(field, "field") }?;
        // SAFETY: forwarded from this function's contract.
        let out = unsafe { arg_mut(out, "out") }?;
        *out = f.liveness();
        Ok(())
    })
}

/// A static description of `status` (a `PheromoneStatus` value), e.g. "no field of that name
/// is running" for `PHEROMONE_STATUS_NO_FIELD`; "unknown status" for a value that is none.
/// Never NULL. (`pheromone_last_error()` says more about the last failure.)
///
/// Thread safety: any thread, any time.
#[no_mangle]
pub extern "C" fn pheromone_status_str(status: i32) -> *const c_char {
    PheromoneStatus::ALL
        .iter()
        .find(|s| **s as i32 == status)
        .map_or(c"unknown status", |s| s.description())
        .as_ptr()
}

/// Sets iceoryx2's log level, which is process-wide (every iceoryx2 user in the process shares
/// it): `PHEROMONE_LOG_TRACE` (0) to `PHEROMONE_LOG_FATAL` (5, only fatal messages). The
/// library never changes it by itself; iceoryx2's default is `PHEROMONE_LOG_INFO` (or its
/// `IOX2_LOG_LEVEL` environment variable, if something in the process reads it).
/// `PHEROMONE_STATUS_BAD_ARGUMENT` for another value.
///
/// Thread safety: any thread, any time.
#[no_mangle]
pub extern "C" fn pheromone_set_log_level(level: u32) -> PheromoneStatus {
    use iceoryx2::prelude::{set_log_level, LogLevel};
    guard(|| {
        let l = match level {
            PHEROMONE_LOG_TRACE => LogLevel::Trace,
            PHEROMONE_LOG_DEBUG => LogLevel::Debug,
            PHEROMONE_LOG_INFO => LogLevel::Info,
            PHEROMONE_LOG_WARN => LogLevel::Warn,
            PHEROMONE_LOG_ERROR => LogLevel::Error,
            PHEROMONE_LOG_FATAL => LogLevel::Fatal,
            l => bail!(
                BAD,
                "log level = {l}: expected PHEROMONE_LOG_TRACE (0) … PHEROMONE_LOG_FATAL (5)"
            ),
        };
        set_log_level(l);
        Ok(())
    })
}

/// The message of the last failed call on this thread (NUL-terminated UTF-8, at most
/// `PHEROMONE_ERROR_CAPACITY` bytes; "" before any failure). Valid until the next failing call
/// on this thread; never NULL.
///
/// Thread safety: per thread.
#[no_mangle]
pub extern "C" fn pheromone_last_error() -> *const c_char {
    last_message_ptr()
}
