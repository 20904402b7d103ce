//! Lane vectors for the tile kernels, written once against [`Lanes`]:
//! [`F4`] (SSE2 on x86_64, part of the baseline target; plain arrays elsewhere) and, on
//! x86_64 CPUs that have it (detected at run time, no `target-cpu` flag), [`F16`]
//! (AVX-512: one vector is one 16-pixel tile row).

use std::ops::{Add, Div, Mul, Sub};

pub use imp4::{F4, M4};
#[cfg(target_arch = "x86_64")]
pub use imp16::{F16, M16};

/// Per-lane boolean mask.
pub(crate) trait Mask: Copy {
    fn and(self, o: Self) -> Self;
    /// Lane k set ↔ bit k set.
    fn bits(self) -> u32;
    fn from_bits(b: u32) -> Self;
}

/// `N` f32 lanes.
pub(crate) trait Lanes:
    Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Div<Output = Self>
{
    const N: usize;
    type M: Mask;
    type I: Copy;
    fn splat(v: f32) -> Self;
    /// Loads `a[0..N]` (panics if shorter).
    fn load(a: &[f32]) -> Self;
    fn store(self, a: &mut [f32]);
    /// `base, base + 1, …`.
    fn iota(base: f32) -> Self;
    fn min(self, o: Self) -> Self;
    /// Lane-wise max; NaN in `self` gives `o`.
    fn max(self, o: Self) -> Self;
    fn le(self, o: Self) -> Self::M;
    fn lt(self, o: Self) -> Self::M;
    fn gt(self, o: Self) -> Self::M;
    /// `m ? self : 0`.
    fn and(self, m: Self::M) -> Self;
    /// `m ? a : b`.
    fn select(m: Self::M, a: Self, b: Self) -> Self;
    /// `(i, t − i)` with `i = trunc(t − ½)` (round to nearest for `t ≤ 0`).
    fn round_split(self) -> (Self::I, Self);
    /// `self · 2^i` by adding `i` to the exponent (no overflow handling).
    fn scale_pow2(self, i: Self::I) -> Self;
    fn sum(self) -> f32;
    fn sqrt(self) -> Self;
    /// `self · b + c` (one rounding where the lanes have a fused multiply-add).
    #[inline(always)]
    fn mul_add(self, b: Self, c: Self) -> Self {
        self * b + c
    }
    /// `1 / self` (≈ 1 ulp where the lanes use a reciprocal estimate and a Newton step).
    #[inline(always)]
    fn recip(self) -> Self {
        Self::splat(1.0) / self
    }
}

/// `exp(x)` for `x ≤ 0` per lane without libm: `2^t = 2^i · 2^f`, `i = round(t)`,
/// `|f| ≤ ½`, degree-6 Taylor polynomial for `2^f` (relative error < 5e-7 for
/// `x ≥ −5`). NaN lanes map to `exp(−80)`.
#[inline(always)]
pub(crate) fn fast_exp<V: Lanes>(x: V) -> V {
    const C: [f32; 6] = [
        std::f32::consts::LN_2,
        0.240_226_5,
        0.055_504_11,
        0.009_618_129,
        0.001_333_355_8,
        0.000_154_035_3,
    ];
    let s = V::splat;
    let t = x.max(s(-80.0)).min(s(0.0)) * s(std::f32::consts::LOG2_E);
    let (i, f) = t.round_split();
    let mut p = f.mul_add(s(C[5]), s(C[4]));
    for c in [C[3], C[2], C[1], C[0], 1.0] {
        p = p.mul_add(f, s(c));
    }
    p.scale_pow2(i)
}

macro_rules! arith {
    ($t:ident, $add:path, $sub:path, $mul:path, $div:path) => {
        impl Add for $t {
            type Output = $t;
            #[inline(always)]
            fn add(self, o: $t) -> $t {
                // SAFETY: see the module's note on target features.
                $t(unsafe { $add(self.0, o.0) })
            }
        }
        impl Sub for $t {
            type Output = $t;
            #[inline(always)]
            fn sub(self, o: $t) -> $t {
                // SAFETY: as above.
                $t(unsafe { $sub(self.0, o.0) })
            }
        }
        impl Mul for $t {
            type Output = $t;
            #[inline(always)]
            fn mul(self, o: $t) -> $t {
                // SAFETY: as above.
                $t(unsafe { $mul(self.0, o.0) })
            }
        }
        impl Div for $t {
            type Output = $t;
            #[inline(always)]
            fn div(self, o: $t) -> $t {
                // SAFETY: as above.
                $t(unsafe { $div(self.0, o.0) })
            }
        }
    };
}

#[cfg(target_arch = "x86_64")]
mod imp4 {
    //! SAFETY (every `unsafe` here): SSE and SSE2 are part of the x86_64 baseline, so
    //! their intrinsics are always available; loads/stores check their slice length.
    use super::{Lanes, Mask};
    use std::arch::x86_64::*;
    use std::ops::{Add, Div, Mul, Sub};

    #[derive(Clone, Copy)]
    pub struct F4(__m128);
    #[derive(Clone, Copy)]
    pub struct M4(__m128);

    impl Mask for M4 {
        #[inline(always)]
        fn and(self, o: M4) -> M4 {
            M4(unsafe { _mm_and_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn bits(self) -> u32 {
            unsafe { _mm_movemask_ps(self.0) as u32 }
        }
        #[inline(always)]
        fn from_bits(b: u32) -> M4 {
            let l = |k: u32| if b >> k & 1 == 1 { -1i32 } else { 0 };
            M4(unsafe { _mm_castsi128_ps(_mm_setr_epi32(l(0), l(1), l(2), l(3))) })
        }
    }

    impl Lanes for F4 {
        const N: usize = 4;
        type M = M4;
        type I = __m128i;
        #[inline(always)]
        fn splat(v: f32) -> F4 {
            F4(unsafe { _mm_set1_ps(v) })
        }
        #[inline(always)]
        fn load(a: &[f32]) -> F4 {
            assert!(a.len() >= 4);
            F4(unsafe { _mm_loadu_ps(a.as_ptr()) })
        }
        #[inline(always)]
        fn store(self, a: &mut [f32]) {
            assert!(a.len() >= 4);
            unsafe { _mm_storeu_ps(a.as_mut_ptr(), self.0) }
        }
        #[inline(always)]
        fn iota(base: f32) -> F4 {
            F4(unsafe { _mm_setr_ps(base, base + 1.0, base + 2.0, base + 3.0) })
        }
        #[inline(always)]
        fn min(self, o: F4) -> F4 {
            F4(unsafe { _mm_min_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn max(self, o: F4) -> F4 {
            // MAXPS returns its second operand when either is NaN.
            F4(unsafe { _mm_max_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn le(self, o: F4) -> M4 {
            M4(unsafe { _mm_cmple_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn lt(self, o: F4) -> M4 {
            M4(unsafe { _mm_cmplt_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn gt(self, o: F4) -> M4 {
            M4(unsafe { _mm_cmpgt_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn and(self, m: M4) -> F4 {
            F4(unsafe { _mm_and_ps(self.0, m.0) })
        }
        #[inline(always)]
        fn select(m: M4, a: F4, b: F4) -> F4 {
            F4(unsafe { _mm_or_ps(_mm_and_ps(m.0, a.0), _mm_andnot_ps(m.0, b.0)) })
        }
        #[inline(always)]
        fn round_split(self) -> (__m128i, F4) {
            unsafe {
                let i = _mm_cvttps_epi32(_mm_sub_ps(self.0, _mm_set1_ps(0.5)));
                (i, F4(_mm_sub_ps(self.0, _mm_cvtepi32_ps(i))))
            }
        }
        #[inline(always)]
        fn scale_pow2(self, i: __m128i) -> F4 {
            unsafe {
                let bits = _mm_add_epi32(_mm_castps_si128(self.0), _mm_slli_epi32::<23>(i));
                F4(_mm_castsi128_ps(bits))
            }
        }
        #[inline(always)]
        fn sum(self) -> f32 {
            let mut a = [0.0; 4];
            self.store(&mut a);
            a.iter().sum()
        }
        #[inline(always)]
        fn sqrt(self) -> F4 {
            F4(unsafe { _mm_sqrt_ps(self.0) })
        }
    }

    arith!(F4, _mm_add_ps, _mm_sub_ps, _mm_mul_ps, _mm_div_ps);
}

#[cfg(target_arch = "x86_64")]
mod imp16 {
    //! SAFETY (every `unsafe` here): these are AVX-512F intrinsics; the kernels that
    //! use [`F16`] run only inside `#[target_feature(enable = "avx512f")]` functions
    //! reached after `is_x86_feature_detected!("avx512f")`. Loads/stores check lengths.
    use super::{Lanes, Mask};
    use std::arch::x86_64::*;
    use std::ops::{Add, Div, Mul, Sub};

    #[derive(Clone, Copy)]
    pub struct F16(__m512);
    #[derive(Clone, Copy)]
    pub struct M16(__mmask16);

    impl Mask for M16 {
        #[inline(always)]
        fn and(self, o: M16) -> M16 {
            M16(self.0 & o.0)
        }
        #[inline(always)]
        fn bits(self) -> u32 {
            self.0 as u32
        }
        #[inline(always)]
        fn from_bits(b: u32) -> M16 {
            M16(b as u16)
        }
    }

    impl Lanes for F16 {
        const N: usize = 16;
        type M = M16;
        type I = __m512i;
        #[inline(always)]
        fn splat(v: f32) -> F16 {
            F16(unsafe { _mm512_set1_ps(v) })
        }
        #[inline(always)]
        fn load(a: &[f32]) -> F16 {
            assert!(a.len() >= 16);
            F16(unsafe { _mm512_loadu_ps(a.as_ptr()) })
        }
        #[inline(always)]
        fn store(self, a: &mut [f32]) {
            assert!(a.len() >= 16);
            unsafe { _mm512_storeu_ps(a.as_mut_ptr(), self.0) }
        }
        #[inline(always)]
        fn iota(base: f32) -> F16 {
            let a: [f32; 16] = std::array::from_fn(|k| base + k as f32);
            F16::load(&a)
        }
        #[inline(always)]
        fn min(self, o: F16) -> F16 {
            F16(unsafe { _mm512_min_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn max(self, o: F16) -> F16 {
            // VMAXPS returns its second operand when either is NaN.
            F16(unsafe { _mm512_max_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn le(self, o: F16) -> M16 {
            M16(unsafe { _mm512_cmp_ps_mask::<_CMP_LE_OQ>(self.0, o.0) })
        }
        #[inline(always)]
        fn lt(self, o: F16) -> M16 {
            M16(unsafe { _mm512_cmp_ps_mask::<_CMP_LT_OQ>(self.0, o.0) })
        }
        #[inline(always)]
        fn gt(self, o: F16) -> M16 {
            M16(unsafe { _mm512_cmp_ps_mask::<_CMP_GT_OQ>(self.0, o.0) })
        }
        #[inline(always)]
        fn and(self, m: M16) -> F16 {
            F16(unsafe { _mm512_maskz_mov_ps(m.0, self.0) })
        }
        #[inline(always)]
        fn select(m: M16, a: F16, b: F16) -> F16 {
            F16(unsafe { _mm512_mask_blend_ps(m.0, b.0, a.0) })
        }
        #[inline(always)]
        fn round_split(self) -> (__m512i, F16) {
            unsafe {
                let i = _mm512_cvttps_epi32(_mm512_sub_ps(self.0, _mm512_set1_ps(0.5)));
                (i, F16(_mm512_sub_ps(self.0, _mm512_cvtepi32_ps(i))))
            }
        }
        #[inline(always)]
        fn scale_pow2(self, i: __m512i) -> F16 {
            unsafe {
                let bits =
                    _mm512_add_epi32(_mm512_castps_si512(self.0), _mm512_slli_epi32::<23>(i));
                F16(_mm512_castsi512_ps(bits))
            }
        }
        /// A tree of shuffles and adds (four levels), not sixteen dependent scalar adds:
        /// a joint step 6.5 % faster at DAVIS346 size (BENCHMARKS.md).
        #[inline(always)]
        fn sum(self) -> f32 {
            unsafe { _mm512_reduce_add_ps(self.0) }
        }
        #[inline(always)]
        fn sqrt(self) -> F16 {
            F16(unsafe { _mm512_sqrt_ps(self.0) })
        }
        #[inline(always)]
        fn mul_add(self, b: F16, c: F16) -> F16 {
            F16(unsafe { _mm512_fmadd_ps(self.0, b.0, c.0) })
        }
        /// The 14-bit estimate and one Newton step `r·(2 − x·r)`: ≈ 1 ulp, a fraction
        /// of a division's cost.
        #[inline(always)]
        fn recip(self) -> F16 {
            unsafe {
                let r = _mm512_rcp14_ps(self.0);
                let e = _mm512_fnmadd_ps(self.0, r, _mm512_set1_ps(2.0));
                F16(_mm512_mul_ps(r, e))
            }
        }
    }

    arith!(
        F16,
        _mm512_add_ps,
        _mm512_sub_ps,
        _mm512_mul_ps,
        _mm512_div_ps
    );
}

#[cfg(not(target_arch = "x86_64"))]
mod imp4 {
    use super::{Lanes, Mask};
    use std::ops::{Add, Div, Mul, Sub};

    #[derive(Clone, Copy)]
    pub struct F4([f32; 4]);
    #[derive(Clone, Copy)]
    pub struct M4([bool; 4]);

    fn map(a: [f32; 4], f: impl Fn(usize, f32) -> f32) -> F4 {
        F4(std::array::from_fn(|k| f(k, a[k])))
    }

    impl Mask for M4 {
        fn and(self, o: M4) -> M4 {
            M4(std::array::from_fn(|k| self.0[k] & o.0[k]))
        }
        fn bits(self) -> u32 {
            (0..4).map(|k| (self.0[k] as u32) << k).sum()
        }
        fn from_bits(b: u32) -> M4 {
            M4(std::array::from_fn(|k| b >> k & 1 == 1))
        }
    }

    impl Lanes for F4 {
        const N: usize = 4;
        type M = M4;
        type I = [i32; 4];
        fn splat(v: f32) -> F4 {
            F4([v; 4])
        }
        fn load(a: &[f32]) -> F4 {
            F4([a[0], a[1], a[2], a[3]])
        }
        fn store(self, a: &mut [f32]) {
            a[..4].copy_from_slice(&self.0);
        }
        fn iota(base: f32) -> F4 {
            F4(std::array::from_fn(|k| base + k as f32))
        }
        fn min(self, o: F4) -> F4 {
            map(self.0, |k, v| if v < o.0[k] { v } else { o.0[k] })
        }
        fn max(self, o: F4) -> F4 {
            map(self.0, |k, v| if v > o.0[k] { v } else { o.0[k] })
        }
        fn le(self, o: F4) -> M4 {
            M4(std::array::from_fn(|k| self.0[k] <= o.0[k]))
        }
        fn lt(self, o: F4) -> M4 {
            M4(std::array::from_fn(|k| self.0[k] < o.0[k]))
        }
        fn gt(self, o: F4) -> M4 {
            M4(std::array::from_fn(|k| self.0[k] > o.0[k]))
        }
        fn and(self, m: M4) -> F4 {
            map(self.0, |k, v| if m.0[k] { v } else { 0.0 })
        }
        fn select(m: M4, a: F4, b: F4) -> F4 {
            F4(std::array::from_fn(
                |k| if m.0[k] { a.0[k] } else { b.0[k] },
            ))
        }
        fn round_split(self) -> ([i32; 4], F4) {
            let i: [i32; 4] = std::array::from_fn(|k| (self.0[k] - 0.5) as i32);
            (i, map(self.0, |k, v| v - i[k] as f32))
        }
        fn scale_pow2(self, i: [i32; 4]) -> F4 {
            map(self.0, |k, v| {
                f32::from_bits((v.to_bits() as i32 + (i[k] << 23)) as u32)
            })
        }
        fn sum(self) -> f32 {
            self.0.iter().sum()
        }
        fn sqrt(self) -> F4 {
            map(self.0, |_, v| v.sqrt())
        }
    }

    impl Add for F4 {
        type Output = F4;
        fn add(self, o: F4) -> F4 {
            map(self.0, |k, v| v + o.0[k])
        }
    }
    impl Sub for F4 {
        type Output = F4;
        fn sub(self, o: F4) -> F4 {
            map(self.0, |k, v| v - o.0[k])
        }
    }
    impl Mul for F4 {
        type Output = F4;
        fn mul(self, o: F4) -> F4 {
            map(self.0, |k, v| v * o.0[k])
        }
    }
    impl Div for F4 {
        type Output = F4;
        fn div(self, o: F4) -> F4 {
            map(self.0, |k, v| v / o.0[k])
        }
    }
}

/// Whether the 16-lane AVX-512 kernels run (can be switched off, e.g. to test the
/// portable path).
static WIDE: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(true);

/// Allow (default) or forbid the AVX-512 kernels; they run only where the CPU has
/// AVX-512F.
pub fn set_wide(enabled: bool) {
    WIDE.store(enabled, std::sync::atomic::Ordering::Relaxed);
}

/// Whether this CPU can run the 16-lane kernels (x86_64 with AVX-512F).
#[inline]
pub fn wide_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        is_x86_feature_detected!("avx512f")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// True when the 16-lane kernels should run: allowed ([`set_wide`]) and available.
#[inline]
pub fn use_wide() -> bool {
    WIDE.load(std::sync::atomic::Ordering::Relaxed) && wide_available()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn first<V: Lanes>(v: V) -> f32 {
        let mut a = vec![0.0; V::N];
        v.store(&mut a);
        a[0]
    }

    #[test]
    fn fast_exp_is_accurate() {
        let mut worst = 0.0f64;
        for k in 0..=100_000 {
            let x = -(k as f32) * 5.0 / 100_000.0;
            let e = (x as f64).exp();
            let got = first(fast_exp(F4::splat(x))) as f64;
            worst = worst.max((got - e).abs() / e);
        }
        assert!(worst < 6e-7, "relative error {worst:e}");
        let far = first(fast_exp(F4::splat(-60.0))) as f64;
        assert!((far / (-60.0f64).exp() - 1.0).abs() < 1e-5);
        assert_eq!(first(fast_exp(F4::splat(0.0))), 1.0);
        assert!(first(fast_exp(F4::splat(f32::NAN))).is_finite());
    }

    /// The 16-lane `fast_exp` (fused Horner steps) and `recip` (estimate + Newton step)
    /// against f64, where the CPU has AVX-512F.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn wide_exp_and_recip_are_accurate() {
        if !wide_available() {
            eprintln!("no AVX-512F here: the 16-lane functions are not tested");
            return;
        }
        #[target_feature(enable = "avx512f")]
        fn worst() -> (f64, f64) {
            let (mut e_worst, mut r_worst) = (0.0f64, 0.0f64);
            for k in 0..=100_000 {
                let x = -(k as f32) * 5.0 / 100_000.0;
                let got = first(fast_exp(F16::splat(x))) as f64;
                let e = (x as f64).exp();
                e_worst = e_worst.max((got - e).abs() / e);
                // 1 − α for α in [0, 0.99]: what the backward divides by.
                let y = 0.01 + 0.99 * k as f32 / 100_000.0;
                let r = first(F16::splat(y).recip()) as f64;
                r_worst = r_worst.max((r * y as f64 - 1.0).abs());
            }
            (e_worst, r_worst)
        }
        // SAFETY: AVX-512F was detected above.
        let (e, r) = unsafe { worst() };
        assert!(e < 6e-7, "exp: relative error {e:e}");
        assert!(r < 3e-7, "recip: relative error {r:e}");
    }

    /// The 16-lane horizontal sum against the f64 sum of its lanes.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn wide_sum_matches_f64() {
        if !wide_available() {
            eprintln!("no AVX-512F here: the 16-lane sum is not tested");
            return;
        }
        #[target_feature(enable = "avx512f")]
        fn check() {
            for seed in 0..200u32 {
                let a: [f32; 16] = std::array::from_fn(|k| {
                    let h = (seed * 16 + k as u32).wrapping_mul(2_654_435_761);
                    (h >> 8) as f32 / (1 << 24) as f32 * 2.0 - 1.0
                });
                let want: f64 = a.iter().map(|&v| v as f64).sum();
                let got = F16::load(&a).sum() as f64;
                assert!((got - want).abs() < 4e-6, "{got} against {want}");
            }
            assert_eq!(F16::iota(1.0).sum(), 136.0);
        }
        // SAFETY: AVX-512F was detected above.
        unsafe { check() }
    }

    #[test]
    fn masks_and_selects() {
        let a = F4::load(&[1.0, -2.0, 3.0, f32::NAN]);
        let m = a.gt(F4::splat(0.0));
        assert_eq!(m.bits(), 0b0101);
        let mut s = [0.0; 4];
        F4::select(m, a, F4::splat(9.0)).store(&mut s);
        assert_eq!(s, [1.0, 9.0, 3.0, 9.0]);
        assert_eq!(M4::from_bits(0b1010).and(m).bits(), 0);
        assert_eq!(a.max(F4::splat(0.0)).sum(), 4.0);
        assert_eq!(F4::iota(2.0).sum(), 14.0);
    }
}
