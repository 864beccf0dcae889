//! Run-time CPU dispatch of the ambient pass's row kernels (`kernels`, used by `crate::ambient`).
//!
//! Each kernel is plain Rust marked `#[inline(always)]`. This module instantiates it twice: as
//! is (the baseline of the build target, SSE2 on x86-64) and inside a function compiled with
//! `#[target_feature(enable = "avx2")]`, where LLVM vectorizes the same loops four f64 / eight
//! f32 wide. Neither enables FMA and Rust never contracts `a * b + c`, so both instantiations
//! perform the same IEEE operations in the same order: their results are bit-identical.
//!
//! The AVX2 instantiation may only run on a CPU that has AVX2; `Dispatch::detect` checks it once
//! with `is_x86_feature_detected!`.

// Calling the AVX2 instantiation (a `target_feature` function) and the prefetch intrinsic (it
// takes a pointer) is `unsafe`; `unsafe_code` is denied everywhere but in a few such files.
#![allow(unsafe_code)]

pub(crate) mod kernels;
mod rows;

use std::sync::OnceLock;

/// Which instantiation of the kernels runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Dispatch {
    /// True only if the running CPU has AVX2 (the constructor checks it).
    avx2: bool,
    /// The reference plane pass (one row at a time, `kernels::prefix_sum`) instead of the fast
    /// one (four rows at a time, `rows`); see `crate::ambient`.
    reference: bool,
}

impl Dispatch {
    /// The best instantiation for this CPU (detected once per process).
    pub fn detect() -> Self {
        static AVX2: OnceLock<bool> = OnceLock::new();
        Self {
            avx2: *AVX2.get_or_init(avx2_available),
            reference: false,
        }
    }

    /// The baseline instantiation, on any CPU.
    pub fn portable() -> Self {
        Self {
            avx2: false,
            reference: false,
        }
    }

    /// The AVX2 instantiation if this CPU has AVX2 (`None` otherwise).
    pub fn avx2() -> Option<Self> {
        avx2_available().then_some(Self {
            avx2: true,
            reference: false,
        })
    }

    /// The same instantiation running the reference ambient pass (the one-row prefix sums the
    /// fast pass is tested against; results within the bound of `crate::ambient`).
    pub fn reference(self) -> Self {
        Self {
            reference: true,
            ..self
        }
    }

    /// True for [`Dispatch::reference`].
    pub fn is_reference(&self) -> bool {
        self.reference
    }

    /// `out[k][i] = Σ cols[k][..i]` for four rows at once (`rows`): the same bits in both
    /// instantiations.
    #[inline]
    pub(crate) fn prefix_rows4(self, cols: [&[f64]; 4], out: [&mut [f64]; 4]) {
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: `avx2` is true only when `is_x86_feature_detected!("avx2")` returned true
            // on this CPU (`Dispatch::detect` / `Dispatch::avx2` set it), the one requirement
            // of `prefix_rows4_avx2`.
            unsafe { rows::prefix_rows4_avx2(cols, out) };
            return;
        }
        rows::prefix_rows4_portable(cols, out)
    }

    /// "avx2" or "portable" (with " reference" for the reference pass).
    pub fn name(&self) -> &'static str {
        match (self.avx2, self.reference) {
            (true, false) => "avx2",
            (false, false) => "portable",
            (true, true) => "avx2 reference",
            (false, true) => "portable reference",
        }
    }
}

fn avx2_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Hints the CPU to bring the cache line holding `v` into L1 (no effect on any result; a no-op
/// off x86-64).
#[inline(always)]
pub(crate) fn prefetch(v: &f32) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        // SAFETY: a prefetch is only a hint: it never faults and reads nothing into the
        // program, and `v` is a valid reference anyway; SSE, its one requirement, is part of
        // the x86-64 baseline.
        unsafe { _mm_prefetch::<_MM_HINT_T0>((v as *const f32).cast::<i8>()) };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = v;
}

macro_rules! dispatch {
    ($(fn $name:ident($($arg:ident: $ty:ty),*);)*) => {
        #[cfg(target_arch = "x86_64")]
        mod avx2 {
            use super::kernels;
            $(
                #[target_feature(enable = "avx2")]
                #[allow(clippy::too_many_arguments)]
                pub(super) unsafe fn $name($($arg: $ty),*) {
                    kernels::$name($($arg),*)
                }
            )*
        }

        impl Dispatch {
            $(
                #[inline]
                #[allow(clippy::too_many_arguments)]
                pub(crate) fn $name(self, $($arg: $ty),*) {
                    #[cfg(target_arch = "x86_64")]
                    if self.avx2 {
                        // SAFETY: `avx2` is true only when `is_x86_feature_detected!("avx2")`
                        // returned true on this CPU (`Dispatch::detect` / `Dispatch::avx2`
                        // are the only constructors that set it), which is the one requirement
                        // of a `#[target_feature(enable = "avx2")]` function; the kernel itself
                        // is safe Rust.
                        unsafe { avx2::$name($($arg),*) };
                        return;
                    }
                    kernels::$name($($arg),*)
                }
            )*
        }
    };
}

dispatch! {
    fn add_row(col_sum: &mut [f64], row: &[f32]);
    fn sub_row(col_sum: &mut [f64], row: &[f32]);
    fn add_row_into(dst: &mut [f64], src: &[f64], row: &[f32]);
    fn sub_row_into(dst: &mut [f64], src: &[f64], row: &[f32]);
    fn swap_row_into(
        dst: &mut [f64],
        src: &[f64],
        row_in: &[f32],
        row_out: &[f32],
        ahead: &[f32]
    );
    fn swap_row(col_sum: &mut [f64], row_in: &[f32], row_out: &[f32], ahead: &[f32]);
    fn prefix_sum(col: &[f64], prefix: &mut [f64]);
    fn mean_row(prefix: &[f64], inv_count: &[f64], span: usize, out: &mut [f32]);
    fn decay_row(
        prefix: &[f64],
        inv_count: &[f64],
        span: usize,
        src: &[f32],
        out: &mut [f32],
        factor: f32,
        alpha: f32
    );
    fn column_sums(col: &mut [f32], rows: &[f32]);
    fn mean_direct(col: &[f32], inv_count: &[f32], span: usize, out: &mut [f32]);
    fn decay_direct(
        col: &[f32],
        inv_count: &[f32],
        span: usize,
        src: &[f32],
        out: &mut [f32],
        factor: f32,
        alpha: f32
    );
}

/// `dst.copy_from_slice(src)` with non-temporal stores for the 16-byte-aligned body (plain
/// stores for the few cells before and after it): the cells go to memory without first reading
/// their cache lines and without evicting what the pass still reads. Same bits as a copy. The
/// caller ends the pass with [`store_fence`] before anyone else may read `dst`.
pub(crate) fn stream_copy(dst: &mut [f32], src: &[f32]) {
    assert_eq!(dst.len(), src.len(), "stream_copy: lengths");
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_loadu_ps, _mm_stream_ps};
        // Cells before the first 16-byte boundary of `dst`, and the aligned body (whole vectors).
        let head = dst.as_ptr().align_offset(16).min(dst.len());
        let body = (dst.len() - head) / 4 * 4;
        dst[..head].copy_from_slice(&src[..head]);
        let (d, s) = (
            dst[head..head + body].as_mut_ptr(),
            src[head..head + body].as_ptr(),
        );
        for k in (0..body).step_by(4) {
            // SAFETY: k + 4 ≤ body, so the load reads `src[head + k..head + k + 4]` and the store
            // writes `dst[head + k..head + k + 4]`, both in bounds (the two slices have one
            // length, asserted above); `dst` + head is 16-byte aligned (`align_offset`) and k is
            // a multiple of 4 cells (16 bytes), as `_mm_stream_ps` requires; `dst` is a
            // `&mut` slice, so it aliases `src` nowhere. SSE is part of the x86-64 baseline.
            unsafe { _mm_stream_ps(d.add(k), _mm_loadu_ps(s.add(k))) };
        }
        dst[head + body..].copy_from_slice(&src[head + body..]);
    }
    #[cfg(not(target_arch = "x86_64"))]
    dst.copy_from_slice(src);
}

/// Orders every earlier non-temporal store ([`stream_copy`]) before any later store (`sfence`),
/// so that a frame written with them is complete before it is published.
pub(crate) fn store_fence() {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: `sfence` only orders stores; SSE, its one requirement, is part of the x86-64
    // baseline.
    unsafe {
        std::arch::x86_64::_mm_sfence()
    };
}
