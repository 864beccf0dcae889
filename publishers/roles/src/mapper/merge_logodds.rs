//! Seed 004's average of two occupancy log-odds (`average` rule, MODELS.md M4): the one-cell
//! reference [`average_logodds`] (σ per side, σ⁻¹ of the mean, libm's `exp` and `ln`) and the
//! same average eight lanes at a time with AVX2 (`average_logodds_avx2`), which computes it in
//! another form with vector polynomials and so differs from the reference by at most
//! [`average_logodds_bound`].
//!
//! # The eight-lane form
//!
//! With A = e⁻ᵃ and B = e⁻ᵇ, σ(a) = 1/(1 + A), and
//! σ⁻¹((σ(a) + σ(b))/2) = ln((2 + A + B) / (A + B + 2AB)):
//! two exponentials and one logarithm per cell, as the reference, but no σ, no 1 − q and every
//! sum one of positive terms (no cancellation anywhere). The exponentials and the logarithm are
//! Cephes' single-precision polynomials (range reduction by ln 2, degree 5 for exp, degree 8
//! for ln), with FMA. Equal inputs (`a == b`, before the clamp, as the reference tests them) are
//! returned clamped, as the reference returns them: those lanes are bit-identical.
//!
//! # The bound
//!
//! Write u = 2⁻²⁴ (round to nearest), a, b the clamped inputs (|a|, |b| ≤ M), a ≠ b, and
//! L* = σ⁻¹((σ(a) + σ(b))/2) the exact value (|L*| ≤ M, as it lies between a and b). To first
//! order in u:
//!
//! - The reference: libm's `expf` and `logf` are within 1 ulp (relative 2u). e = e⁻ᵃ(1 + η),
//!   |η| ≤ 2u; 1 + e rounded and its reciprocal rounded give σ(a)(1 + π) with
//!   |π| ≤ 2u(1 − σ(a)) + 2u ≤ 4u; the mean q of two such positive terms, rounded, is within
//!   5u·q* of q*. 1 − q is exact for q ≥ ½ (Sterbenz) and rounded (u) below, so relative to
//!   1 − q* it is off by at most 5u·q*/(1 − q*) + u = 5u·e^{L*} + u. The quotient rounded: 7u +
//!   5u·e^{L*}; `logf` adds 2u·|L*|. So |ref − L*| ≤ u(7 + 5e^M + 2M).
//! - The eight lanes: each exponential within ε_e (relative) of e⁻ᵃ; 2 + A + B (positive sums,
//!   two roundings) within ε_e + 2u; A·B within 2ε_e + u, doubled exactly, A + B + 2AB within
//!   2ε_e + 2u; the quotient within 3ε_e + 5u; the logarithm within ε_l (absolute) of the
//!   quotient's. So |fast − L*| ≤ 3ε_e + 5u + ε_l.
//!
//! The final clamp to ±M is 1-Lipschitz and L* lies inside it, so both bounds hold after it:
//! |fast − ref| ≤ u(12 + 5e^M + 2M) + 3ε_e + ε_l. Cephes' polynomials give ε_e ≤ 2u
//! (`merge_simd`'s tests measure the worst case over a dense grid of [−M_max, M_max]) and
//! ε_l ≤ 2u(1 + |ln x|) ≤ 2u(1 + M). [`average_logodds_bound`] is that sum doubled (the
//! doubling covers every second-order term: the first-order terms are at most 3·10⁻³ for
//! M ≤ [`AVX2_LOGODDS_MAX`]); at the default M = 4, 3.6·10⁻⁵ (a probability off by at most
//! 10⁻⁶ near ½). The eight-lane pass runs only for 0 < M ≤ [`AVX2_LOGODDS_MAX`]: then e^M and
//! e^{2M} stay far from f32's range, and the bound stays below 2·10⁻³ (beyond, the reference
//! itself loses its precision in 1 − q: at M ≈ 17, q rounds to 1).

/// The largest `logodds_max` the eight-lane pass serves; beyond it the one-cell pass runs.
pub(crate) const AVX2_LOGODDS_MAX: f32 = 8.0;

/// u = 2⁻²⁴, half an ulp of 1.
const U: f64 = 1.0 / 16_777_216.0;

/// The proven bound on |eight-lane average − [`average_logodds`]| for log-odds clamped to
/// ±`max` (module doc): 2·(u(12 + 5e^M + 2M) + 3ε_e + ε_l) with ε_e = 2u, ε_l = 2u(1 + M).
/// Infinite for a `max` the eight-lane pass does not serve (the one-cell pass runs: no error).
pub fn average_logodds_bound(max: f32) -> f64 {
    if !(max > 0.0 && max <= AVX2_LOGODDS_MAX) {
        return f64::INFINITY;
    }
    let m = max as f64;
    let (eps_e, eps_l) = (2.0 * U, 2.0 * U * (1.0 + m));
    2.0 * (U * (12.0 + 5.0 * m.exp() + 2.0 * m) + 3.0 * eps_e + eps_l)
}

/// Seed 004's average of two occupancy log-odds as probabilities: σ⁻¹((σ(a) + σ(b))/2), both
/// clamped to ±`max` first and the result clamped to ±`max` (so a finite input never gives
/// NaN or ±∞). Symmetric in a and b; equal inputs (two unknown cells: 0) are returned as they
/// are.
#[inline]
pub fn average_logodds(a: f32, b: f32, max: f32) -> f32 {
    if a == b {
        return a.clamp(-max, max);
    }
    let p = |l: f32| 1.0 / (1.0 + (-l.clamp(-max, max)).exp());
    let q = 0.5 * (p(a) + p(b));
    (q / (1.0 - q)).ln().clamp(-max, max)
}

#[cfg(target_arch = "x86_64")]
pub(crate) use avx2::average_logodds_avx2;

#[cfg(target_arch = "x86_64")]
pub(crate) mod avx2 {
    use std::arch::x86_64::*;

    /// [`super::average_logodds`] of eight lanes, within [`super::average_logodds_bound`] of
    /// it (bit-identical where `a == b`); `max` in (0, `AVX2_LOGODDS_MAX`] in every lane.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    pub(crate) fn average_logodds_avx2(a: __m256, b: __m256, max: __m256) -> __m256 {
        let neg_max = _mm256_sub_ps(_mm256_setzero_ps(), max);
        let clamp = |x: __m256| _mm256_min_ps(_mm256_max_ps(x, neg_max), max);
        let (ca, cb) = (clamp(a), clamp(b));
        let neg = |x: __m256| _mm256_sub_ps(_mm256_setzero_ps(), x);
        let (ea, eb) = (exp_avx2(neg(ca)), exp_avx2(neg(cb)));
        let sum = _mm256_add_ps(ea, eb);
        let two = _mm256_set1_ps(2.0);
        let num = _mm256_add_ps(two, sum);
        let den = _mm256_fmadd_ps(two, _mm256_mul_ps(ea, eb), sum);
        let l = clamp(ln_avx2(_mm256_div_ps(num, den)));
        _mm256_blendv_ps(l, ca, _mm256_cmp_ps::<_CMP_EQ_OQ>(a, b))
    }

    /// eˣ of eight lanes (Cephes' `expf`: x = n ln 2 + r, |r| ≤ ½ ln 2, a degree-5 polynomial
    /// in r, times 2ⁿ), for |x| ≤ 80.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    pub(crate) fn exp_avx2(x: __m256) -> __m256 {
        let set = |v: f32| _mm256_set1_ps(v);
        let n = _mm256_round_ps::<{ _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC }>(
            _mm256_mul_ps(x, set(std::f32::consts::LOG2_E)),
        );
        // ln 2 in two parts: 0.693359375 has 9 significant bits, so n·C1 is exact.
        let r = _mm256_fnmadd_ps(n, set(6.933594e-1), x);
        let r = _mm256_fnmadd_ps(n, set(-2.1219444e-4), r);
        let mut y = set(1.9875691e-4);
        for c in [1.3981999e-3, 8.333452e-3, 4.1665796e-2, 1.6666666e-1, 5e-1] {
            y = _mm256_fmadd_ps(y, r, set(c));
        }
        let y = _mm256_fmadd_ps(y, _mm256_mul_ps(r, r), r);
        let y = _mm256_add_ps(y, set(1.0));
        let pow2n = _mm256_slli_epi32::<23>(_mm256_add_epi32(
            _mm256_cvtps_epi32(n),
            _mm256_set1_epi32(127),
        ));
        _mm256_mul_ps(y, _mm256_castsi256_ps(pow2n))
    }

    /// ln x of eight lanes (Cephes' `logf`: x = m·2ᵉ, m in [√½, √2), a degree-8 polynomial in
    /// m − 1), for normal positive x.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    pub(crate) fn ln_avx2(x: __m256) -> __m256 {
        let set = |v: f32| _mm256_set1_ps(v);
        let bits = _mm256_castps_si256(x);
        // m in [½, 1): the mantissa with ½'s exponent; e the exponent that goes with it.
        let m = _mm256_or_ps(
            _mm256_and_ps(x, _mm256_castsi256_ps(_mm256_set1_epi32(0x007f_ffff))),
            set(0.5),
        );
        let e = _mm256_sub_epi32(_mm256_srli_epi32::<23>(bits), _mm256_set1_epi32(126));
        let e = _mm256_cvtepi32_ps(e);
        // Below √½: m ← 2m, e ← e − 1, so that m − 1 lies in [√½ − 1, √2 − 1).
        let low = _mm256_cmp_ps::<_CMP_LT_OQ>(m, set(std::f32::consts::FRAC_1_SQRT_2));
        let e = _mm256_sub_ps(e, _mm256_and_ps(low, set(1.0)));
        let t = _mm256_sub_ps(_mm256_add_ps(m, _mm256_and_ps(low, m)), set(1.0));
        let z = _mm256_mul_ps(t, t);
        let mut y = set(7.0376836e-2);
        for c in [
            -1.151461e-1,
            1.16769984e-1,
            -1.2420141e-1,
            1.4249323e-1,
            -1.6668057e-1,
            2.0000714e-1,
            -2.4999994e-1,
            3.333333e-1,
        ] {
            y = _mm256_fmadd_ps(y, t, set(c));
        }
        let y = _mm256_mul_ps(_mm256_mul_ps(y, t), z);
        let y = _mm256_fmadd_ps(e, set(-2.1219444e-4), y);
        let y = _mm256_fnmadd_ps(z, set(0.5), y);
        _mm256_fmadd_ps(e, set(6.933594e-1), _mm256_add_ps(t, y))
    }
}
