//! The cells of one merge run (`merge::merge_run`): the reference loop one cell at a time, and
//! the same operations eight cells at a time with AVX2 (the source cells fetched by two
//! gathers), chosen once per process by CPU detection.
//!
//! Both compute every cell's source index from the same 32.32 fixed-point walk (lane k of the
//! AVX2 loop holds `u + k·du`, which is what k additions of `du` give: integer adds are exact)
//! and the same f32 operations (`0.5 · (d + s)`, no FMA), so they give the same bits and the
//! same counts; `mapper::tests` checks it.

// The AVX2 loop's loads, stores and gathers take pointers: `unsafe_code` is denied everywhere
// but in a few such files.
#![allow(unsafe_code)]

use std::sync::OnceLock;

/// One run's walk: the source cell of the run's cell k is
/// `(clamp((u + k·du) >> 32, 0, sw − 1), clamp((v + k·dv) >> 32, 0, sh − 1))`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Walk {
    pub u: i64,
    pub v: i64,
    pub du: i64,
    pub dv: i64,
    pub sw: usize,
    pub sh: usize,
}

impl Walk {
    /// The walk from the run's cell `k` on.
    fn from(&self, k: usize) -> Self {
        Self {
            u: self.u.wrapping_add((k as i64).wrapping_mul(self.du)),
            v: self.v.wrapping_add((k as i64).wrapping_mul(self.dv)),
            ..*self
        }
    }
}

/// How runs are merged.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Runs {
    /// One cell at a time (the reference).
    Scalar,
    /// Eight cells at a time; only constructed when the CPU has AVX2 (`detect`).
    Avx2,
}

impl Runs {
    /// AVX2 if this CPU has it (checked once per process).
    pub(crate) fn detect() -> Self {
        static AVX2: OnceLock<bool> = OnceLock::new();
        let avx2 = *AVX2.get_or_init(|| {
            #[cfg(target_arch = "x86_64")]
            {
                std::arch::is_x86_feature_detected!("avx2")
            }
            #[cfg(not(target_arch = "x86_64"))]
            {
                false
            }
        });
        if avx2 {
            Runs::Avx2
        } else {
            Runs::Scalar
        }
    }

    /// Merges the source cells the walk visits into `d` (occupancy) and `p` (pheromone);
    /// returns the cells (adopted, averaged).
    pub(crate) fn run(
        self,
        d: &mut [f32],
        p: &mut [f32],
        so: &[f32],
        sp: &[f32],
        walk: &Walk,
    ) -> (usize, usize) {
        #[cfg(target_arch = "x86_64")]
        if self == Runs::Avx2 && avx2_fits(d.len().min(p.len()), so, sp, walk) {
            // SAFETY: `Runs::Avx2` is only constructed by `detect` when the CPU has AVX2;
            // `avx2_fits` checked the conditions `run_avx2` states.
            return unsafe { run_avx2(d, p, so, sp, walk) };
        }
        scalar(d, p, so, sp, walk)
    }
}

impl Runs {
    /// True if no cell of `plane` is NaN or ±∞: the exponent test of
    /// `MapView::first_non_finite`, branch-free per 1024-cell chunk so that it vectorizes,
    /// compiled for AVX2 where the CPU has it.
    pub(crate) fn all_finite(self, plane: &[f32]) -> bool {
        #[cfg(target_arch = "x86_64")]
        if self == Runs::Avx2 {
            // SAFETY: `Runs::Avx2` is only constructed by `detect` when the CPU has AVX2, the one
            // requirement of `all_finite_avx2` (safe code otherwise).
            return unsafe { all_finite_avx2(plane) };
        }
        all_finite(plane)
    }
}

#[inline(always)]
fn all_finite(plane: &[f32]) -> bool {
    let finite = |c: &[f32]| {
        c.iter().fold(true, |ok, v| {
            ok & (v.to_bits() & 0x7f80_0000 != 0x7f80_0000)
        })
    };
    plane.chunks(1024).all(finite)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn all_finite_avx2(plane: &[f32]) -> bool {
    all_finite(plane)
}

/// The reference: one cell at a time.
fn scalar(d: &mut [f32], p: &mut [f32], so: &[f32], sp: &[f32], walk: &Walk) -> (usize, usize) {
    let (u_max, v_max) = (walk.sw as i64 - 1, walk.sh as i64 - 1);
    let (mut u, mut v) = (walk.u, walk.v);
    let (mut adopted, mut averaged) = (0usize, 0usize);
    for (d, p) in d.iter_mut().zip(p.iter_mut()) {
        // `row_span` keeps u in [0, sw) and v in [0, sh); the clamp only guards rounding.
        let (cu, cv) = ((u >> 32).clamp(0, u_max), (v >> 32).clamp(0, v_max));
        let i = cv as usize * walk.sw + cu as usize;
        let (so, sp) = (so[i], sp[i]);
        let (od, op) = (*d, *p);
        let known = so != 0.0;
        let empty = od == 0.0;
        let nd = if empty { so } else { 0.5 * (od + so) };
        let np = if empty { sp } else { 0.5 * (op + sp) };
        *d = if known { nd } else { od };
        *p = if known { np } else { op };
        adopted += (known & empty) as usize;
        averaged += (known & !empty) as usize;
        u = u.wrapping_add(walk.du);
        v = v.wrapping_add(walk.dv);
    }
    (adopted, averaged)
}

/// The AVX2 loop's preconditions: every source index fits an i32 (`sw·sh ≤ i32::MAX`), both
/// source planes hold `sw·sh` cells, and the walk's integer parts stay within ±2³⁰ over the
/// run (they are then the high halves of the 64-bit lanes, read as i32; the walk is linear, so
/// its two ends bound it).
fn avx2_fits(n: usize, so: &[f32], sp: &[f32], walk: &Walk) -> bool {
    let cells = walk.sw.checked_mul(walk.sh);
    let small = |c: i64| (-(1i64 << 30)..(1i64 << 30)).contains(&(c >> 32));
    let last = walk.from(n.saturating_sub(1));
    walk.sw > 0
        && walk.sh > 0
        && cells.is_some_and(|c| c <= i32::MAX as usize && so.len() >= c && sp.len() >= c)
        && small(walk.u)
        && small(walk.v)
        && small(last.u)
        && small(last.v)
        && n < (1 << 24)
}

/// As [`scalar`], eight cells at a time.
///
/// # Safety
/// The CPU must have AVX2, and `avx2_fits(d.len().min(p.len()), so, sp, walk)` must hold.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn run_avx2(
    d: &mut [f32],
    p: &mut [f32],
    so: &[f32],
    sp: &[f32],
    walk: &Walk,
) -> (usize, usize) {
    use std::arch::x86_64::*;
    let n = d.len().min(p.len());
    let chunks = n / 8;
    let lanes = |c: i64, dc: i64, from: i64| {
        let at = |k: i64| c.wrapping_add(k.wrapping_mul(dc));
        _mm256_setr_epi64x(at(from), at(from + 1), at(from + 2), at(from + 3))
    };
    let (mut u_lo, mut u_hi) = (lanes(walk.u, walk.du, 0), lanes(walk.u, walk.du, 4));
    let (mut v_lo, mut v_hi) = (lanes(walk.v, walk.dv, 0), lanes(walk.v, walk.dv, 4));
    let step_u = _mm256_set1_epi64x(walk.du.wrapping_mul(8));
    let step_v = _mm256_set1_epi64x(walk.dv.wrapping_mul(8));
    // The high (integer) halves of four 64-bit lanes, in both 128-bit halves.
    let odd = _mm256_setr_epi32(1, 3, 5, 7, 1, 3, 5, 7);
    let int = |lo: __m256i, hi: __m256i| {
        _mm256_blend_epi32::<0xF0>(
            _mm256_permutevar8x32_epi32(lo, odd),
            _mm256_permutevar8x32_epi32(hi, odd),
        )
    };
    let zero = _mm256_setzero_si256();
    let u_max = _mm256_set1_epi32(walk.sw as i32 - 1);
    let v_max = _mm256_set1_epi32(walk.sh as i32 - 1);
    let sw = _mm256_set1_epi32(walk.sw as i32);
    let (half, zero_ps) = (_mm256_set1_ps(0.5), _mm256_setzero_ps());
    let (mut adopted, mut averaged) = (0usize, 0usize);
    let (dp, pp) = (d.as_mut_ptr(), p.as_mut_ptr());
    for c in 0..chunks {
        let x = 8 * c;
        let cu = _mm256_min_epi32(_mm256_max_epi32(int(u_lo, u_hi), zero), u_max);
        let cv = _mm256_min_epi32(_mm256_max_epi32(int(v_lo, v_hi), zero), v_max);
        let i = _mm256_add_epi32(_mm256_mullo_epi32(cv, sw), cu);
        // SAFETY: every lane of `i` is cv·sw + cu with 0 ≤ cu < sw and 0 ≤ cv < sh (clamped
        // above), so 0 ≤ i < sw·sh ≤ i32::MAX (no overflow in the multiply) and both source
        // planes hold sw·sh cells (`avx2_fits`); x + 8 ≤ 8·chunks ≤ n ≤ d.len(), p.len(), so
        // the loads and stores stay inside `d` and `p`, distinct `&mut` slices. Unaligned
        // loads and stores need no alignment. The caller guarantees AVX2.
        unsafe {
            let s_o = _mm256_i32gather_ps::<4>(so.as_ptr(), i);
            let s_p = _mm256_i32gather_ps::<4>(sp.as_ptr(), i);
            let od = _mm256_loadu_ps(dp.add(x));
            let op = _mm256_loadu_ps(pp.add(x));
            let known = _mm256_cmp_ps::<_CMP_NEQ_UQ>(s_o, zero_ps);
            let empty = _mm256_cmp_ps::<_CMP_EQ_OQ>(od, zero_ps);
            let nd = _mm256_blendv_ps(_mm256_mul_ps(half, _mm256_add_ps(od, s_o)), s_o, empty);
            let np = _mm256_blendv_ps(_mm256_mul_ps(half, _mm256_add_ps(op, s_p)), s_p, empty);
            _mm256_storeu_ps(dp.add(x), _mm256_blendv_ps(od, nd, known));
            _mm256_storeu_ps(pp.add(x), _mm256_blendv_ps(op, np, known));
            adopted += _mm256_movemask_ps(_mm256_and_ps(known, empty)).count_ones() as usize;
            averaged += _mm256_movemask_ps(_mm256_andnot_ps(empty, known)).count_ones() as usize;
        }
        u_lo = _mm256_add_epi64(u_lo, step_u);
        u_hi = _mm256_add_epi64(u_hi, step_u);
        v_lo = _mm256_add_epi64(v_lo, step_v);
        v_hi = _mm256_add_epi64(v_hi, step_v);
    }
    let x = 8 * chunks;
    let (a, b) = scalar(&mut d[x..n], &mut p[x..n], so, sp, &walk.from(x));
    (adopted + a, averaged + b)
}
