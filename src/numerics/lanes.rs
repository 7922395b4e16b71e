//! The element-wise row kernels of the engine's inner loops (the Joseph row update,
//! the gain composition, the prediction's row operations), in two builds: portable
//! loops ([`Scalar`]) and explicit 4-lane AVX2 ([`Avx2`], x86-64, chosen at run time
//! by `analysis`). LLVM vectorises the portable loops only for long rows — it
//! unrolls by 16 and leaves rows shorter than that (every row of a 30-state model's
//! triangle, on average) to scalar code — so the AVX2 build spells the chunks out and
//! finishes each row with one masked chunk.
//!
//! Each lane performs the same operations in the same order as the portable loop —
//! products and sums, never fused — so both builds give identical bits
//! (`server/tests/cli.rs::simd_builds_agree_bitwise`).

/// Row kernels; every slice argument is at least as long as `d`.
pub(crate) trait Lanes: Copy {
    /// d ← d − a·x + b·y, element-wise (the Joseph row update, [`crate::numerics::riccati`]).
    fn sub_add(d: &mut [f64], x: &[f64], a: f64, y: &[f64], b: f64);
    /// d ← d + a·x.
    fn add_scaled(d: &mut [f64], x: &[f64], a: f64);
    /// d ← d + x·y, element-wise (a diagonal of E times a shifted row of R, `linalg`).
    fn add_prod(d: &mut [f64], x: &[f64], y: &[f64]);
    /// d ← s + a·x (a copy of s fused with the first `add_scaled`).
    fn set_scaled(d: &mut [f64], s: &[f64], x: &[f64], a: f64);
    /// d ← d − a·x.
    fn sub_scaled(d: &mut [f64], x: &[f64], a: f64);
}

/// Portable loops (equal-length slices, so no bounds checks in the loop).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Scalar;

impl Lanes for Scalar {
    #[inline(always)]
    fn sub_add(d: &mut [f64], x: &[f64], a: f64, y: &[f64], b: f64) {
        let (x, y) = (&x[..d.len()], &y[..d.len()]);
        for i in 0..d.len() {
            d[i] = d[i] - a * x[i] + b * y[i];
        }
    }
    #[inline(always)]
    fn add_scaled(d: &mut [f64], x: &[f64], a: f64) {
        let x = &x[..d.len()];
        for (d, x) in d.iter_mut().zip(x) {
            *d += a * x;
        }
    }
    #[inline(always)]
    fn add_prod(d: &mut [f64], x: &[f64], y: &[f64]) {
        let (x, y) = (&x[..d.len()], &y[..d.len()]);
        for i in 0..d.len() {
            d[i] += x[i] * y[i];
        }
    }
    #[inline(always)]
    fn set_scaled(d: &mut [f64], s: &[f64], x: &[f64], a: f64) {
        let (s, x) = (&s[..d.len()], &x[..d.len()]);
        for i in 0..d.len() {
            d[i] = s[i] + a * x[i];
        }
    }
    #[inline(always)]
    fn sub_scaled(d: &mut [f64], x: &[f64], a: f64) {
        let x = &x[..d.len()];
        for (d, x) in d.iter_mut().zip(x) {
            *d -= a * x;
        }
    }
}

/// Explicit AVX2 lanes. Only code compiled with `avx2` enabled (the engine's
/// `run_avx2`, entered after run-time detection) may use this type.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy, Debug)]
pub(crate) struct Avx2;

#[cfg(target_arch = "x86_64")]
impl Lanes for Avx2 {
    #[inline(always)]
    fn sub_add(d: &mut [f64], x: &[f64], a: f64, y: &[f64], b: f64) {
        let n = d.len();
        let (x, y) = (&x[..n], &y[..n]);
        // SAFETY: the slices hold n elements (checked above); AVX2 is present (see
        // the type's contract).
        unsafe { avx2::sub_add(d.as_mut_ptr(), x.as_ptr(), a, y.as_ptr(), b, n) }
    }
    #[inline(always)]
    fn add_scaled(d: &mut [f64], x: &[f64], a: f64) {
        let n = d.len();
        let x = &x[..n];
        // SAFETY: as in `sub_add`.
        unsafe { avx2::axpy::<false>(d.as_mut_ptr(), d.as_ptr(), x.as_ptr(), a, n) }
    }
    #[inline(always)]
    fn add_prod(d: &mut [f64], x: &[f64], y: &[f64]) {
        let n = d.len();
        let (x, y) = (&x[..n], &y[..n]);
        // SAFETY: as in `sub_add`.
        unsafe { avx2::add_prod(d.as_mut_ptr(), x.as_ptr(), y.as_ptr(), n) }
    }
    #[inline(always)]
    fn set_scaled(d: &mut [f64], s: &[f64], x: &[f64], a: f64) {
        let n = d.len();
        let (s, x) = (&s[..n], &x[..n]);
        // SAFETY: as in `sub_add`.
        unsafe { avx2::axpy::<false>(d.as_mut_ptr(), s.as_ptr(), x.as_ptr(), a, n) }
    }
    #[inline(always)]
    fn sub_scaled(d: &mut [f64], x: &[f64], a: f64) {
        let n = d.len();
        let x = &x[..n];
        // SAFETY: as in `sub_add`.
        unsafe { avx2::axpy::<true>(d.as_mut_ptr(), d.as_ptr(), x.as_ptr(), a, n) }
    }
}

#[cfg(target_arch = "x86_64")]
mod avx2 {
    use std::arch::x86_64::*;

    /// Lanes 0..rem (rem < 4) selected.
    #[inline]
    #[target_feature(enable = "avx2")]
    fn tail_mask(rem: usize) -> __m256i {
        _mm256_cmpgt_epi64(
            _mm256_set1_epi64x(rem as i64),
            _mm256_setr_epi64x(0, 1, 2, 3),
        )
    }

    #[inline]
    #[target_feature(enable = "avx2")]
    fn add_or_sub<const SUB: bool>(d: __m256d, p: __m256d) -> __m256d {
        if SUB {
            _mm256_sub_pd(d, p)
        } else {
            _mm256_add_pd(d, p)
        }
    }

    /// d[i] = (d[i] − a·x[i]) + b·y[i] for i < n.
    ///
    /// # Safety
    /// The CPU has AVX2; d, x and y are valid for n elements.
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn sub_add(
        d: *mut f64,
        x: *const f64,
        a: f64,
        y: *const f64,
        b: f64,
        n: usize,
    ) {
        let (va, vb) = (_mm256_set1_pd(a), _mm256_set1_pd(b));
        let mut i = 0;
        // SAFETY: every access is below n (whole chunks, then the masked rest).
        unsafe {
            while i + 4 <= n {
                let r = _mm256_sub_pd(
                    _mm256_loadu_pd(d.add(i)),
                    _mm256_mul_pd(va, _mm256_loadu_pd(x.add(i))),
                );
                let r = _mm256_add_pd(r, _mm256_mul_pd(vb, _mm256_loadu_pd(y.add(i))));
                _mm256_storeu_pd(d.add(i), r);
                i += 4;
            }
            if i < n {
                let m = tail_mask(n - i);
                let r = _mm256_sub_pd(
                    _mm256_maskload_pd(d.add(i), m),
                    _mm256_mul_pd(va, _mm256_maskload_pd(x.add(i), m)),
                );
                let r = _mm256_add_pd(r, _mm256_mul_pd(vb, _mm256_maskload_pd(y.add(i), m)));
                _mm256_maskstore_pd(d.add(i), m, r);
            }
        }
    }

    /// d[i] = d[i] + x[i]·y[i] for i < n.
    ///
    /// # Safety
    /// As [`sub_add`].
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn add_prod(d: *mut f64, x: *const f64, y: *const f64, n: usize) {
        let mut i = 0;
        // SAFETY: every access is below n (whole chunks, then the masked rest).
        unsafe {
            while i + 4 <= n {
                let p = _mm256_mul_pd(_mm256_loadu_pd(x.add(i)), _mm256_loadu_pd(y.add(i)));
                _mm256_storeu_pd(d.add(i), _mm256_add_pd(_mm256_loadu_pd(d.add(i)), p));
                i += 4;
            }
            if i < n {
                let m = tail_mask(n - i);
                let p = _mm256_mul_pd(
                    _mm256_maskload_pd(x.add(i), m),
                    _mm256_maskload_pd(y.add(i), m),
                );
                let r = _mm256_add_pd(_mm256_maskload_pd(d.add(i), m), p);
                _mm256_maskstore_pd(d.add(i), m, r);
            }
        }
    }

    /// d[i] = s[i] ± a·x[i] for i < n (− when `SUB`); s may be d.
    ///
    /// # Safety
    /// As [`sub_add`], and s is valid for n elements.
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn axpy<const SUB: bool>(
        d: *mut f64,
        s: *const f64,
        x: *const f64,
        a: f64,
        n: usize,
    ) {
        let va = _mm256_set1_pd(a);
        let mut i = 0;
        // SAFETY: every access is below n (whole chunks, then the masked rest).
        unsafe {
            while i + 4 <= n {
                let p = _mm256_mul_pd(va, _mm256_loadu_pd(x.add(i)));
                _mm256_storeu_pd(d.add(i), add_or_sub::<SUB>(_mm256_loadu_pd(s.add(i)), p));
                i += 4;
            }
            if i < n {
                let m = tail_mask(n - i);
                let p = _mm256_mul_pd(va, _mm256_maskload_pd(x.add(i), m));
                let r = add_or_sub::<SUB>(_mm256_maskload_pd(s.add(i), m), p);
                _mm256_maskstore_pd(d.add(i), m, r);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The AVX2 kernels give the portable loops' bits for every length and offset.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx2_kernels_equal_the_portable_loops_bitwise() {
        if !(std::arch::is_x86_feature_detected!("avx2")) {
            eprintln!("no AVX2 on this CPU: nothing to compare");
            return;
        }
        let v = |n: usize, s: f64| -> Vec<f64> {
            (0..n)
                .map(|i| ((i as f64 + s) * 0.7318).sin() * 1e3)
                .collect()
        };
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        for n in 0..=13 {
            let (x, y) = (v(n, 1.0), v(n, 2.0));
            let mut a = v(n, 3.0);
            let mut b = a.clone();
            Scalar::sub_add(&mut a, &x, 0.37, &y, -1.9);
            Avx2::sub_add(&mut b, &x, 0.37, &y, -1.9);
            Scalar::add_scaled(&mut a, &x, 1.3);
            Avx2::add_scaled(&mut b, &x, 1.3);
            Scalar::add_prod(&mut a, &x, &y);
            Avx2::add_prod(&mut b, &x, &y);
            Scalar::sub_scaled(&mut a, &y, 0.11);
            Avx2::sub_scaled(&mut b, &y, 0.11);
            let (mut c, mut e) = (vec![0.0; n], vec![0.0; n]);
            Scalar::set_scaled(&mut c, &a, &x, -0.73);
            Avx2::set_scaled(&mut e, &b, &x, -0.73);
            assert_eq!(bits(&c), bits(&e), "set_scaled, n = {n}");
            assert_eq!(bits(&a), bits(&b), "n = {n}");
        }
        // A masked chunk writes nothing past the row.
        let mut d = vec![1.0; 8];
        Avx2::add_scaled(&mut d[..5], &[1.0; 5], 1.0);
        assert_eq!(d, [2.0, 2.0, 2.0, 2.0, 2.0, 1.0, 1.0, 1.0]);
    }
}
