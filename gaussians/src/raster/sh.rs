//! Real spherical harmonics up to degree 3 with the constants and signs 3DGS uses:
//! colour = Σ_k coeff_k · Y_k(dir) + 0.5, `dir` the unit vector from the camera centre
//! to the Gaussian in world space. Coefficient k = 0 is the DC term (`sh_dc`); k ≥ 1 are
//! `sh_rest[(k − 1)·3 + channel]` (coefficient-major).

use super::simd::Lanes;

pub const C0: f64 = 0.282_094_791_773_878_14;
pub const C1: f64 = 0.488_602_511_902_919_9;
pub const C2: [f64; 5] = [
    1.092_548_430_592_079_2,
    -1.092_548_430_592_079_2,
    0.315_391_565_252_520_05,
    -1.092_548_430_592_079_2,
    0.546_274_215_296_039_6,
];
pub(crate) const C3: [f64; 7] = [
    -0.590_043_589_926_643_5,
    2.890_611_442_640_554,
    -0.457_045_799_464_465_8,
    0.373_176_332_590_115_4,
    -0.457_045_799_464_465_8,
    1.445_305_721_320_277,
    -0.590_043_589_926_643_5,
];

/// Number of SH coefficients per channel at `degree` (clamped to 3).
pub(crate) fn num_coeffs(degree: u32) -> usize {
    let d = degree.min(3) as usize;
    (d + 1) * (d + 1)
}

macro_rules! sh_impl {
    ($t:ty, $basis:ident, $grad:ident) => {
        /// Basis values `Y_k(d)` for a unit direction `d`; entries above `degree` are 0.
        #[inline]
        pub fn $basis(d: [$t; 3], degree: u32) -> [$t; 16] {
            let [x, y, z] = d;
            let mut b = [0.0 as $t; 16];
            b[0] = C0 as $t;
            if degree >= 1 {
                b[1] = -(C1 as $t) * y;
                b[2] = (C1 as $t) * z;
                b[3] = -(C1 as $t) * x;
            }
            if degree >= 2 {
                let (xx, yy, zz) = (x * x, y * y, z * z);
                b[4] = (C2[0] as $t) * x * y;
                b[5] = (C2[1] as $t) * y * z;
                b[6] = (C2[2] as $t) * (2.0 * zz - xx - yy);
                b[7] = (C2[3] as $t) * x * z;
                b[8] = (C2[4] as $t) * (xx - yy);
                if degree >= 3 {
                    b[9] = (C3[0] as $t) * y * (3.0 * xx - yy);
                    b[10] = (C3[1] as $t) * x * y * z;
                    b[11] = (C3[2] as $t) * y * (4.0 * zz - xx - yy);
                    b[12] = (C3[3] as $t) * z * (2.0 * zz - 3.0 * xx - 3.0 * yy);
                    b[13] = (C3[4] as $t) * x * (4.0 * zz - xx - yy);
                    b[14] = (C3[5] as $t) * z * (xx - yy);
                    b[15] = (C3[6] as $t) * x * (xx - 3.0 * yy);
                }
            }
            b
        }

        /// Backward of the basis: `g[k] = ∂L/∂Y_k` → `∂L/∂d` (d as a free 3-vector).
        #[inline]
        pub fn $grad(d: [$t; 3], degree: u32, g: &[$t; 16]) -> [$t; 3] {
            let [x, y, z] = d;
            let (mut gx, mut gy, mut gz) = (0.0 as $t, 0.0 as $t, 0.0 as $t);
            if degree >= 1 {
                let c1 = C1 as $t;
                gy -= c1 * g[1];
                gz += c1 * g[2];
                gx -= c1 * g[3];
            }
            if degree >= 2 {
                let c = C2.map(|v| v as $t);
                let (xx, yy, zz) = (x * x, y * y, z * z);
                gx += c[0] * y * g[4];
                gy += c[0] * x * g[4];
                gy += c[1] * z * g[5];
                gz += c[1] * y * g[5];
                gx -= 2.0 * c[2] * x * g[6];
                gy -= 2.0 * c[2] * y * g[6];
                gz += 4.0 * c[2] * z * g[6];
                gx += c[3] * z * g[7];
                gz += c[3] * x * g[7];
                gx += 2.0 * c[4] * x * g[8];
                gy -= 2.0 * c[4] * y * g[8];
                if degree >= 3 {
                    let c = C3.map(|v| v as $t);
                    gx += c[0] * 6.0 * x * y * g[9];
                    gy += c[0] * 3.0 * (xx - yy) * g[9];
                    gx += c[1] * y * z * g[10];
                    gy += c[1] * x * z * g[10];
                    gz += c[1] * x * y * g[10];
                    gx -= c[2] * 2.0 * x * y * g[11];
                    gy += c[2] * (4.0 * zz - xx - 3.0 * yy) * g[11];
                    gz += c[2] * 8.0 * y * z * g[11];
                    gx -= c[3] * 6.0 * x * z * g[12];
                    gy -= c[3] * 6.0 * y * z * g[12];
                    gz += c[3] * (6.0 * zz - 3.0 * xx - 3.0 * yy) * g[12];
                    gx += c[4] * (4.0 * zz - 3.0 * xx - yy) * g[13];
                    gy -= c[4] * 2.0 * x * y * g[13];
                    gz += c[4] * 8.0 * x * z * g[13];
                    gx += c[5] * 2.0 * x * z * g[14];
                    gy -= c[5] * 2.0 * y * z * g[14];
                    gz += c[5] * (xx - yy) * g[14];
                    gx += c[6] * 3.0 * (xx - yy) * g[15];
                    gy -= c[6] * 6.0 * x * y * g[15];
                }
            }
            [gx, gy, gz]
        }
    };
}

sh_impl!(f32, basis_f32, basis_grad_f32);
sh_impl!(f64, basis_f64, basis_grad_f64);

/// [`basis_f32`] in lanes (`d` a unit direction per lane); entries above `degree` are 0.
#[inline(always)]
pub(crate) fn basis_lanes<V: Lanes>(d: [V; 3], degree: u32) -> [V; 16] {
    let [x, y, z] = d;
    // `c` is a function, not a closure: a closure would not inherit the caller's
    // target features.
    #[inline(always)]
    fn c<V: Lanes>(v: f64) -> V {
        V::splat(v as f32)
    }
    let mut b = [V::splat(0.0); 16];
    b[0] = c::<V>(C0);
    if degree >= 1 {
        b[1] = c::<V>(-C1) * y;
        b[2] = c::<V>(C1) * z;
        b[3] = c::<V>(-C1) * x;
    }
    if degree >= 2 {
        let (xx, yy, zz) = (x * x, y * y, z * z);
        b[4] = c::<V>(C2[0]) * x * y;
        b[5] = c::<V>(C2[1]) * y * z;
        b[6] = c::<V>(C2[2]) * (c::<V>(2.0) * zz - xx - yy);
        b[7] = c::<V>(C2[3]) * x * z;
        b[8] = c::<V>(C2[4]) * (xx - yy);
        if degree >= 3 {
            b[9] = c::<V>(C3[0]) * y * (c::<V>(3.0) * xx - yy);
            b[10] = c::<V>(C3[1]) * x * y * z;
            b[11] = c::<V>(C3[2]) * y * (c::<V>(4.0) * zz - xx - yy);
            b[12] = c::<V>(C3[3]) * z * (c::<V>(2.0) * zz - c::<V>(3.0) * xx - c::<V>(3.0) * yy);
            b[13] = c::<V>(C3[4]) * x * (c::<V>(4.0) * zz - xx - yy);
            b[14] = c::<V>(C3[5]) * z * (xx - yy);
            b[15] = c::<V>(C3[6]) * x * (xx - c::<V>(3.0) * yy);
        }
    }
    b
}

/// [`basis_grad_f32`] in lanes.
#[inline(always)]
pub(crate) fn basis_grad_lanes<V: Lanes>(d: [V; 3], degree: u32, g: &[V; 16]) -> [V; 3] {
    #[inline(always)]
    fn c<V: Lanes>(v: f64) -> V {
        V::splat(v as f32)
    }
    let [x, y, z] = d;
    let zero = V::splat(0.0);
    let (mut gx, mut gy, mut gz) = (zero, zero, zero);
    if degree >= 1 {
        gy = gy - c::<V>(C1) * g[1];
        gz = gz + c::<V>(C1) * g[2];
        gx = gx - c::<V>(C1) * g[3];
    }
    if degree >= 2 {
        let (xx, yy, zz) = (x * x, y * y, z * z);
        gx = gx + c::<V>(C2[0]) * y * g[4];
        gy = gy + c::<V>(C2[0]) * x * g[4];
        gy = gy + c::<V>(C2[1]) * z * g[5];
        gz = gz + c::<V>(C2[1]) * y * g[5];
        gx = gx - c::<V>(2.0 * C2[2]) * x * g[6];
        gy = gy - c::<V>(2.0 * C2[2]) * y * g[6];
        gz = gz + c::<V>(4.0 * C2[2]) * z * g[6];
        gx = gx + c::<V>(C2[3]) * z * g[7];
        gz = gz + c::<V>(C2[3]) * x * g[7];
        gx = gx + c::<V>(2.0 * C2[4]) * x * g[8];
        gy = gy - c::<V>(2.0 * C2[4]) * y * g[8];
        if degree >= 3 {
            let k = C3;
            gx = gx + c::<V>(6.0 * k[0]) * x * y * g[9];
            gy = gy + c::<V>(3.0 * k[0]) * (xx - yy) * g[9];
            gx = gx + c::<V>(k[1]) * y * z * g[10];
            gy = gy + c::<V>(k[1]) * x * z * g[10];
            gz = gz + c::<V>(k[1]) * x * y * g[10];
            gx = gx - c::<V>(2.0 * k[2]) * x * y * g[11];
            gy = gy + c::<V>(k[2]) * (c::<V>(4.0) * zz - xx - c::<V>(3.0) * yy) * g[11];
            gz = gz + c::<V>(8.0 * k[2]) * y * z * g[11];
            gx = gx - c::<V>(6.0 * k[3]) * x * z * g[12];
            gy = gy - c::<V>(6.0 * k[3]) * y * z * g[12];
            gz = gz
                + c::<V>(k[3]) * (c::<V>(6.0) * zz - c::<V>(3.0) * xx - c::<V>(3.0) * yy) * g[12];
            gx = gx + c::<V>(k[4]) * (c::<V>(4.0) * zz - c::<V>(3.0) * xx - yy) * g[13];
            gy = gy - c::<V>(2.0 * k[4]) * x * y * g[13];
            gz = gz + c::<V>(8.0 * k[4]) * x * z * g[13];
            gx = gx + c::<V>(2.0 * k[5]) * x * z * g[14];
            gy = gy - c::<V>(2.0 * k[5]) * y * z * g[14];
            gz = gz + c::<V>(k[5]) * (xx - yy) * g[14];
            gx = gx + c::<V>(3.0 * k[6]) * (xx - yy) * g[15];
            gy = gy - c::<V>(6.0 * k[6]) * x * y * g[15];
        }
    }
    [gx, gy, gz]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The 16 basis functions are orthonormal over the sphere (∫ Y_i Y_j dΩ = δ_ij),
    /// which pins every constant (up to its sign) independently of 3DGS.
    #[test]
    fn basis_is_orthonormal() {
        let (nt, np) = (200, 400);
        let mut gram = [[0.0f64; 16]; 16];
        for i in 0..nt {
            // Midpoint rule in cos(theta) (uniform area), and in phi.
            let ct = -1.0 + (i as f64 + 0.5) * 2.0 / nt as f64;
            let st = (1.0 - ct * ct).sqrt();
            for j in 0..np {
                let ph = (j as f64 + 0.5) * std::f64::consts::TAU / np as f64;
                let b = basis_f64([st * ph.cos(), st * ph.sin(), ct], 3);
                let w = 2.0 / nt as f64 * std::f64::consts::TAU / np as f64;
                for a in 0..16 {
                    for c in 0..16 {
                        gram[a][c] += w * b[a] * b[c];
                    }
                }
            }
        }
        for a in 0..16 {
            for c in 0..16 {
                let want = if a == c { 1.0 } else { 0.0 };
                assert!(
                    (gram[a][c] - want).abs() < 1e-3,
                    "gram[{a}][{c}] = {}",
                    gram[a][c]
                );
            }
        }
    }

    #[test]
    fn basis_grad_matches_finite_differences() {
        let d = [0.3, -0.5, 0.81];
        let g: [f64; 16] = std::array::from_fn(|k| ((k * 7 % 5) as f64 - 2.0) * 0.3 + 0.1);
        let f = |d: [f64; 3]| -> f64 { basis_f64(d, 3).iter().zip(&g).map(|(a, b)| a * b).sum() };
        let an = basis_grad_f64(d, 3, &g);
        for k in 0..3 {
            let (mut p, mut m) = (d, d);
            p[k] += 1e-6;
            m[k] -= 1e-6;
            let fd = (f(p) - f(m)) / 2e-6;
            assert!(
                (fd - an[k]).abs() < 1e-7,
                "component {k}: {fd} vs {}",
                an[k]
            );
        }
        assert_eq!(basis_f32([0.0, 0.0, 1.0], 0)[1], 0.0);
        assert!((basis_f32([0.0, 0.0, 1.0], 1)[2] - C1 as f32).abs() < 1e-7);
    }
}
