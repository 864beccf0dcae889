//! The cells of one merge run (`merge::merge_run`), by either rule: the reference loops one
//! cell at a time, and the same operations eight cells at a time with AVX2 (the source cells
//! fetched by two gathers), chosen once per process by CPU detection.
//!
//! Both compute every cell's source index from the same 32.32 fixed-point walk (lane k of the
//! AVX2 loop holds `u + k·du`, which is what k additions of `du` give: integer adds are exact;
//! `Lanes`, shared by both rules' AVX2 loops). By `adopt-unknown` they run the same f32
//! operations (`0.5 · (d + s)`, no FMA), so they give the same bits and the same counts. By
//! `average` they test the same cells (the same counts) and give the same pheromone bits; the
//! occupancy mean of two log-odds is computed in another form (`merge_logodds`), within its
//! proven bound of the one-cell result. `tests/merge_fast.rs` and `tests/merge_average.rs`
//! check both.

// The AVX2 loop's loads, stores and gathers take pointers: `unsafe_code` is denied everywhere
// but in a few such files.
#![allow(unsafe_code)]

use std::sync::OnceLock;

use super::merge_logodds::average_logodds;
#[cfg(target_arch = "x86_64")]
use super::merge_logodds::{average_logodds_avx2, AVX2_LOGODDS_MAX};

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

    /// The source index of each of the run's cells in turn, endless (zip it with the run):
    /// the fixed-point walk every one-cell pass takes.
    pub(crate) fn indices(&self) -> impl Iterator<Item = usize> {
        let (u_max, v_max) = (self.sw as i64 - 1, self.sh as i64 - 1);
        let (du, dv, sw) = (self.du, self.dv, self.sw);
        std::iter::successors(Some((self.u, self.v)), move |&(u, v)| {
            Some((u.wrapping_add(du), v.wrapping_add(dv)))
        })
        .map(move |(u, v)| {
            // `row_span` keeps u in [0, sw) and v in [0, sh); the clamp only guards rounding.
            let (cu, cv) = ((u >> 32).clamp(0, u_max), (v >> 32).clamp(0, v_max));
            cv as usize * sw + cu as usize
        })
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
    /// Seed 004's `average` rule over the source cells the walk visits, into `d` (occupancy)
    /// and `p` (pheromone), log-odds clamped to ±`logodds_max`; returns the cells (0 adopted,
    /// averaged). Eight cells at a time where the CPU has AVX2 and FMA and 0 < `logodds_max` ≤
    /// `AVX2_LOGODDS_MAX` (occupancy within `average_logodds_bound` of the one-cell pass's,
    /// pheromone and counts bit for bit), else one cell at a time.
    pub(crate) fn average(
        self,
        (d, p): (&mut [f32], &mut [f32]),
        (so, sp): (&[f32], &[f32]),
        walk: &Walk,
        logodds_max: f32,
    ) -> (usize, usize) {
        #[cfg(target_arch = "x86_64")]
        if self == Runs::Avx2
            && has_fma()
            && logodds_max > 0.0
            && logodds_max <= AVX2_LOGODDS_MAX
            && avx2_fits(d.len().min(p.len()), so, sp, walk)
        {
            // SAFETY: `Runs::Avx2` is only constructed by `detect` when the CPU has AVX2, and
            // `has_fma` checked FMA; `avx2_fits` and the test of `logodds_max` checked what
            // `average_avx2` states.
            return unsafe { average_avx2(d, p, (so, sp), walk, logodds_max) };
        }
        average_scalar(d, p, (so, sp), walk, logodds_max)
    }
}

/// True if the CPU has FMA (checked once per process): the `average` rule's eight-lane pass
/// evaluates its polynomials with it.
#[cfg(target_arch = "x86_64")]
fn has_fma() -> bool {
    static FMA: OnceLock<bool> = OnceLock::new();
    *FMA.get_or_init(|| std::arch::is_x86_feature_detected!("fma"))
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
    let (mut adopted, mut averaged) = (0usize, 0usize);
    for ((d, p), i) in d.iter_mut().zip(p.iter_mut()).zip(walk.indices()) {
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

/// The eight lanes' source indices along a walk: lane k's walk position in 64-bit lanes (two
/// registers of four), advanced by 8·du, 8·dv per chunk; the integer halves clamped to the
/// source and turned into indices. Shared by both AVX2 passes.
#[cfg(target_arch = "x86_64")]
struct Lanes {
    u: [std::arch::x86_64::__m256i; 2],
    v: [std::arch::x86_64::__m256i; 2],
    step: [std::arch::x86_64::__m256i; 2],
    max: [std::arch::x86_64::__m256i; 2],
    sw: std::arch::x86_64::__m256i,
}

#[cfg(target_arch = "x86_64")]
impl Lanes {
    #[target_feature(enable = "avx2")]
    fn new(walk: &Walk) -> Self {
        use std::arch::x86_64::*;
        let lanes = |c: i64, dc: i64, from: i64| {
            let at = |k: i64| c.wrapping_add(k.wrapping_mul(dc));
            _mm256_setr_epi64x(at(from), at(from + 1), at(from + 2), at(from + 3))
        };
        Self {
            u: [lanes(walk.u, walk.du, 0), lanes(walk.u, walk.du, 4)],
            v: [lanes(walk.v, walk.dv, 0), lanes(walk.v, walk.dv, 4)],
            step: [
                _mm256_set1_epi64x(walk.du.wrapping_mul(8)),
                _mm256_set1_epi64x(walk.dv.wrapping_mul(8)),
            ],
            max: [
                _mm256_set1_epi32(walk.sw as i32 - 1),
                _mm256_set1_epi32(walk.sh as i32 - 1),
            ],
            sw: _mm256_set1_epi32(walk.sw as i32),
        }
    }

    /// The current eight cells' source indices `clamp(v) · sw + clamp(u)`; then the walk moves
    /// on by eight cells.
    #[target_feature(enable = "avx2")]
    #[inline]
    fn next(&mut self) -> std::arch::x86_64::__m256i {
        use std::arch::x86_64::*;
        // The high (integer) halves of four 64-bit lanes, in both 128-bit halves.
        let odd = _mm256_setr_epi32(1, 3, 5, 7, 1, 3, 5, 7);
        let int = |[lo, hi]: [__m256i; 2]| {
            _mm256_blend_epi32::<0xF0>(
                _mm256_permutevar8x32_epi32(lo, odd),
                _mm256_permutevar8x32_epi32(hi, odd),
            )
        };
        let zero = _mm256_setzero_si256();
        let cu = _mm256_min_epi32(_mm256_max_epi32(int(self.u), zero), self.max[0]);
        let cv = _mm256_min_epi32(_mm256_max_epi32(int(self.v), zero), self.max[1]);
        let i = _mm256_add_epi32(_mm256_mullo_epi32(cv, self.sw), cu);
        for (c, step) in [(&mut self.u, self.step[0]), (&mut self.v, self.step[1])] {
            *c = [_mm256_add_epi64(c[0], step), _mm256_add_epi64(c[1], step)];
        }
        i
    }
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
    let mut lanes = Lanes::new(walk);
    let (half, zero_ps) = (_mm256_set1_ps(0.5), _mm256_setzero_ps());
    let (mut adopted, mut averaged) = (0usize, 0usize);
    let (dp, pp) = (d.as_mut_ptr(), p.as_mut_ptr());
    for c in 0..chunks {
        let x = 8 * c;
        let i = lanes.next();
        // SAFETY: every lane of `i` is cv·sw + cu with 0 ≤ cu < sw and 0 ≤ cv < sh (clamped
        // in `Lanes::next`), so 0 ≤ i < sw·sh ≤ i32::MAX (no overflow in the multiply) and both
        // source planes hold sw·sh cells (`avx2_fits`); x + 8 ≤ 8·chunks ≤ n ≤ d.len(),
        // p.len(), so the loads and stores stay inside `d` and `p`, distinct `&mut` slices.
        // Unaligned loads and stores need no alignment. The caller guarantees AVX2.
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
    }
    let x = 8 * chunks;
    let (a, b) = scalar(&mut d[x..n], &mut p[x..n], so, sp, &walk.from(x));
    (adopted + a, averaged + b)
}

/// Seed 004's `average` rule over one run, one cell at a time (the reference): every cell
/// either map knows (a nonzero log-odds or pheromone on either side) becomes the average of
/// both, occupancy as probabilities ([`average_logodds`]); returns (0 adopted, averaged).
fn average_scalar(
    d: &mut [f32],
    p: &mut [f32],
    (so, sp): (&[f32], &[f32]),
    walk: &Walk,
    logodds_max: f32,
) -> (usize, usize) {
    let mut averaged = 0usize;
    for ((d, p), i) in d.iter_mut().zip(p.iter_mut()).zip(walk.indices()) {
        let (so, sp) = (so[i], sp[i]);
        let (od, op) = (*d, *p);
        if so != 0.0 || od != 0.0 || sp != 0.0 || op != 0.0 {
            *d = average_logodds(od, so, logodds_max);
            *p = 0.5 * (op + sp);
            averaged += 1;
        }
    }
    (0, averaged)
}

/// As [`average_scalar`], eight cells at a time, the run's last cells (fewer than eight) too,
/// by masked loads and stores: the same cells averaged (the same test, as blends), the same
/// pheromone bits, occupancy by `average_logodds_avx2` (within
/// `merge_logodds::average_logodds_bound` of the reference's) in every cell, so that a cell's
/// result does not depend on where it falls in a run (the merge stays symmetric).
///
/// # Safety
/// The CPU must have AVX2 and FMA, `avx2_fits(d.len().min(p.len()), so, sp, walk)` must hold
/// and 0 < `logodds_max` ≤ `AVX2_LOGODDS_MAX`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn average_avx2(
    d: &mut [f32],
    p: &mut [f32],
    (so, sp): (&[f32], &[f32]),
    walk: &Walk,
    logodds_max: f32,
) -> (usize, usize) {
    use std::arch::x86_64::*;
    let n = d.len().min(p.len());
    let mut lanes = Lanes::new(walk);
    let max = _mm256_set1_ps(logodds_max);
    let mut averaged = 0usize;
    let (dp, pp) = (d.as_mut_ptr(), p.as_mut_ptr());
    for x in (0..n).step_by(8) {
        let i = lanes.next();
        // Lanes k < n − x are the run's cells (all eight but in the last chunk).
        let rest = (n - x).min(8) as i32;
        let mask = _mm256_cmpgt_epi32(
            _mm256_set1_epi32(rest),
            _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7),
        );
        // SAFETY: every lane of `i` lies in [0, sw·sh) (clamped in `Lanes::next`, lanes past
        // the run's end included; sw·sh ≤ i32::MAX and both source planes hold sw·sh cells by
        // `avx2_fits`), so the gathers read inside `so` and `sp`. A full chunk's loads and
        // stores touch d[x..x + 8], p[x..x + 8] (x + 8 ≤ n ≤ d.len(), p.len()); lane k of the
        // masked ones `d[x + k]`, `p[x + k]` only where k < n − x (x < n); masked-out lanes are
        // neither read nor written and cannot fault. `d` and `p` are distinct `&mut` slices;
        // no alignment is needed. The caller guarantees AVX2 and FMA.
        unsafe {
            let s_o = _mm256_i32gather_ps::<4>(so.as_ptr(), i);
            let s_p = _mm256_i32gather_ps::<4>(sp.as_ptr(), i);
            // Full chunks by plain loads and stores (a masked store is slow on some CPUs).
            let full = rest == 8;
            let (od, op) = match full {
                true => (_mm256_loadu_ps(dp.add(x)), _mm256_loadu_ps(pp.add(x))),
                false => (
                    _mm256_maskload_ps(dp.add(x), mask),
                    _mm256_maskload_ps(pp.add(x), mask),
                ),
            };
            let (nd, np, known) = average8((od, op), (s_o, s_p), max);
            if full {
                _mm256_storeu_ps(dp.add(x), nd);
                _mm256_storeu_ps(pp.add(x), np);
            } else {
                _mm256_maskstore_ps(dp.add(x), mask, nd);
                _mm256_maskstore_ps(pp.add(x), mask, np);
            }
            let known = _mm256_and_ps(known, _mm256_castsi256_ps(mask));
            averaged += _mm256_movemask_ps(known).count_ones() as usize;
        }
    }
    (0, averaged)
}

/// One chunk of [`average_avx2`]: the destination's (occupancy, pheromone) lanes and the
/// source's; returns the new lanes and which of them were averaged (a nonzero value on either
/// side; the others are returned as they were).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
fn average8(
    (od, op): (std::arch::x86_64::__m256, std::arch::x86_64::__m256),
    (s_o, s_p): (std::arch::x86_64::__m256, std::arch::x86_64::__m256),
    max: std::arch::x86_64::__m256,
) -> (
    std::arch::x86_64::__m256,
    std::arch::x86_64::__m256,
    std::arch::x86_64::__m256,
) {
    use std::arch::x86_64::*;
    let zero = _mm256_setzero_ps();
    let nonzero = |v: __m256| _mm256_cmp_ps::<_CMP_NEQ_UQ>(v, zero);
    let known = _mm256_or_ps(
        _mm256_or_ps(nonzero(s_o), nonzero(od)),
        _mm256_or_ps(nonzero(s_p), nonzero(op)),
    );
    let nd = average_logodds_avx2(od, s_o, max);
    let np = _mm256_mul_ps(_mm256_set1_ps(0.5), _mm256_add_ps(op, s_p));
    (
        _mm256_blendv_ps(od, nd, known),
        _mm256_blendv_ps(op, np, known),
        known,
    )
}

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    use std::arch::x86_64::*;

    use super::super::merge_logodds::avx2::{exp_avx2, ln_avx2};
    use super::super::merge_logodds::AVX2_LOGODDS_MAX;

    /// The largest error of an eight-lane function over every `stride`-th f32 of [lo, hi]
    /// (by bit pattern, both signs), against `exact` in f64, as `error(got, exact)`.
    fn worst(
        (lo, hi): (f32, f32),
        stride: u32,
        lanes: impl Fn(__m256) -> __m256,
        exact: impl Fn(f64) -> f64,
        error: impl Fn(f64, f64) -> f64,
    ) -> f64 {
        let xs: Vec<f32> = (0..=0x7f7f_ffffu32)
            .step_by(stride as usize)
            .flat_map(|b| [f32::from_bits(b), -f32::from_bits(b)])
            .filter(|x| (lo..=hi).contains(x))
            .collect();
        xs.chunks_exact(8).fold(0.0f64, |m, c| {
            let mut out = [0.0f32; 8];
            // SAFETY: `c` and `out` hold eight f32 each (unaligned loads and stores).
            unsafe { _mm256_storeu_ps(out.as_mut_ptr(), lanes(_mm256_loadu_ps(c.as_ptr()))) };
            c.iter()
                .zip(out)
                .fold(m, |m, (&x, y)| m.max(error(y as f64, exact(x as f64))))
        })
    }

    /// ε_e and ε_l of `merge_logodds`'s bound: e^x within 2u (relative) over [−M, M] for the
    /// largest M served, ln x within 2u(1 + |ln x|) over [e^−M, e^M].
    #[test]
    fn vector_exp_and_ln_are_within_the_errors_the_bound_assumes() {
        if !(std::arch::is_x86_feature_detected!("avx2") && super::has_fma()) {
            return;
        }
        let u = 1.0 / 16_777_216.0;
        let m = AVX2_LOGODDS_MAX;
        // SAFETY: the CPU has AVX2 and FMA (tested above).
        let exp = |x| unsafe { exp_avx2(x) };
        // SAFETY: as above.
        let ln = |x| unsafe { ln_avx2(x) };
        let e = worst((-m, m), 613, exp, f64::exp, |y, t| (y - t).abs() / t);
        let l = worst(((-m).exp(), m.exp()), 613, ln, f64::ln, |y, t| {
            (y - t).abs() / (1.0 + t.abs())
        });
        println!(
            "exp: {:.3}u relative, ln: {:.3}u·(1 + |ln x|)",
            e / u,
            l / u
        );
        assert!(e <= 2.0 * u, "exp off by {}u", e / u);
        assert!(l <= 2.0 * u, "ln off by {}u", l / u);
    }
}
