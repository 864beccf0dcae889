//! The horizontal prefix sums of four rows at once (`Dispatch::prefix_rows4`, used by
//! `crate::ambient`'s fast path): the row's serial chain of additions runs across SIMD lanes,
//! one row per lane, instead of along the row.
//!
//! For each block of four columns `x..x+4` the four rows' values are transposed (4 × 4 f64,
//! eight shuffles) into column vectors `v0..v3` (lane k = row k); the block's local prefix
//! `t0 = v0, t1 = t0 + v1, t2 = t1 + v2, t3 = t2 + v3` does not depend on the carry, so the
//! loop-carried chain is one add per block (`q_j = carry + t_j`, `carry = q3`); the `q_j` are
//! transposed back and stored as the four rows' prefixes. The portable version performs the
//! same IEEE additions in the same order, so both give the same bits.
//!
//! Compared with the one-row prefix (`kernels::prefix_sum`) the additions are grouped
//! differently, so the results differ in the last bits; both are sums of the same terms, each
//! prefix a summation of at most `n` terms, so both stay within `(n − 1)·u·Σ|terms|` of the exact
//! prefix (u = 2⁻⁵³, any order of summation; Higham, *Accuracy and Stability of Numerical
//! Algorithms*, §4.2) and within twice that of each other.

/// `out[k][i] = Σ cols[k][..i]` for the four rows k (each `out[k]` one longer than `cols[k]`,
/// all `cols[k]` of one length). Portable instantiation (also the reference for the AVX2 one).
pub(crate) fn prefix_rows4_portable(cols: [&[f64]; 4], out: [&mut [f64]; 4]) {
    let n = check(&cols, &out);
    let blocks = n / 4;
    for (c, o) in cols.iter().zip(out) {
        o[0] = 0.0;
        let mut carry = 0.0f64;
        for b in 0..blocks {
            let x = 4 * b;
            let t1 = c[x] + c[x + 1];
            let t2 = t1 + c[x + 2];
            let t3 = t2 + c[x + 3];
            o[x + 1] = carry + c[x];
            o[x + 2] = carry + t1;
            o[x + 3] = carry + t2;
            o[x + 4] = carry + t3;
            carry = o[x + 4];
        }
        tail(c, o, 4 * blocks, carry);
    }
}

/// The columns after the last full block: a plain running sum from `carry`.
#[inline(always)]
fn tail(c: &[f64], o: &mut [f64], from: usize, mut carry: f64) {
    for i in from..c.len() {
        carry += c[i];
        o[i + 1] = carry;
    }
}

fn check(cols: &[&[f64]; 4], out: &[&mut [f64]; 4]) -> usize {
    let n = cols[0].len();
    for (c, o) in cols.iter().zip(out) {
        assert!(
            c.len() == n && o.len() == n + 1,
            "prefix_rows4: row lengths"
        );
    }
    n
}

/// As [`prefix_rows4_portable`], AVX2 instantiation (same bits).
///
/// # Safety
/// The CPU must have AVX2 (`Dispatch` checks it before calling).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[allow(unsafe_code)]
pub(crate) unsafe fn prefix_rows4_avx2(cols: [&[f64]; 4], out: [&mut [f64]; 4]) {
    use std::arch::x86_64::{_mm256_add_pd, _mm256_loadu_pd, _mm256_setzero_pd, _mm256_storeu_pd};
    let n = check(&cols, &out);
    let blocks = n / 4;
    let [o0, o1, o2, o3] = out;
    let outs = [o0, o1, o2, o3];
    let src = [
        cols[0].as_ptr(),
        cols[1].as_ptr(),
        cols[2].as_ptr(),
        cols[3].as_ptr(),
    ];
    let dst = [
        outs[0].as_mut_ptr(),
        outs[1].as_mut_ptr(),
        outs[2].as_mut_ptr(),
        outs[3].as_mut_ptr(),
    ];
    let mut carry = _mm256_setzero_pd();
    for b in 0..blocks {
        let x = 4 * b;
        // SAFETY: `check` asserted every `cols[k]` has `n` elements and every `out[k]` has
        // `n + 1`; `x + 4 <= 4·blocks <= n`, so the loads read `cols[k][x..x + 4]` and the
        // stores write `out[k][x + 1..x + 5]`, all in bounds; the four `out[k]` are distinct
        // `&mut` slices, so the stores alias nothing else. AVX2 is enabled on this function and
        // the caller guarantees the CPU has it. Unaligned loads/stores need no alignment.
        unsafe {
            let r0 = _mm256_loadu_pd(src[0].add(x));
            let r1 = _mm256_loadu_pd(src[1].add(x));
            let r2 = _mm256_loadu_pd(src[2].add(x));
            let r3 = _mm256_loadu_pd(src[3].add(x));
            let [v0, v1, v2, v3] = transpose(r0, r1, r2, r3);
            let t1 = _mm256_add_pd(v0, v1);
            let t2 = _mm256_add_pd(t1, v2);
            let t3 = _mm256_add_pd(t2, v3);
            let q0 = _mm256_add_pd(carry, v0);
            let q1 = _mm256_add_pd(carry, t1);
            let q2 = _mm256_add_pd(carry, t2);
            let q3 = _mm256_add_pd(carry, t3);
            carry = q3;
            let [p0, p1, p2, p3] = transpose(q0, q1, q2, q3);
            _mm256_storeu_pd(dst[0].add(x + 1), p0);
            _mm256_storeu_pd(dst[1].add(x + 1), p1);
            _mm256_storeu_pd(dst[2].add(x + 1), p2);
            _mm256_storeu_pd(dst[3].add(x + 1), p3);
        }
    }
    // The scalar tail of each row from its last block's prefix (= that row's carry).
    for (c, o) in cols.iter().zip(outs) {
        o[0] = 0.0;
        let carry = o[4 * blocks];
        tail(c, o, 4 * blocks, carry);
    }
}

/// 4 × 4 transpose of f64 rows (its own inverse).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn transpose(
    r0: std::arch::x86_64::__m256d,
    r1: std::arch::x86_64::__m256d,
    r2: std::arch::x86_64::__m256d,
    r3: std::arch::x86_64::__m256d,
) -> [std::arch::x86_64::__m256d; 4] {
    use std::arch::x86_64::{_mm256_permute2f128_pd, _mm256_unpackhi_pd, _mm256_unpacklo_pd};
    let t0 = _mm256_unpacklo_pd(r0, r1); // r0[0] r1[0] r0[2] r1[2]
    let t1 = _mm256_unpackhi_pd(r0, r1); // r0[1] r1[1] r0[3] r1[3]
    let t2 = _mm256_unpacklo_pd(r2, r3); // r2[0] r3[0] r2[2] r3[2]
    let t3 = _mm256_unpackhi_pd(r2, r3); // r2[1] r3[1] r2[3] r3[3]
    [
        _mm256_permute2f128_pd::<0x20>(t0, t2),
        _mm256_permute2f128_pd::<0x20>(t1, t3),
        _mm256_permute2f128_pd::<0x31>(t0, t2),
        _mm256_permute2f128_pd::<0x31>(t1, t3),
    ]
}
