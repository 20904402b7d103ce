//! Scalar trait and a strided GEMM wrapper over the `gemm` crate (f32 for training,
//! f64 for the finite-difference tests).

/// The scalar the MLP is generic over: the workspace's float trait.
pub use scene::real::Real;

/// A row-major matrix view: `rows × cols`, element (r, c) at `r * stride + c`, or the
/// transpose of one when `transposed`.
#[derive(Clone, Copy)]
pub struct View<'a, T> {
    pub data: &'a [T],
    pub rows: usize,
    pub cols: usize,
    pub stride: usize,
    pub transposed: bool,
}

impl<'a, T> View<'a, T> {
    pub fn new(data: &'a [T], rows: usize, cols: usize, stride: usize) -> Self {
        assert!(rows == 0 || data.len() >= (rows - 1) * stride + cols);
        View {
            data,
            rows,
            cols,
            stride,
            transposed: false,
        }
    }
    pub fn t(self) -> Self {
        View {
            transposed: !self.transposed,
            ..self
        }
    }
    /// (rows, cols) of the logical matrix.
    fn shape(&self) -> (usize, usize) {
        if self.transposed {
            (self.cols, self.rows)
        } else {
            (self.rows, self.cols)
        }
    }
    /// (column stride, row stride) of the logical matrix.
    fn strides(&self) -> (isize, isize) {
        if self.transposed {
            (self.stride as isize, 1)
        } else {
            (1, self.stride as isize)
        }
    }
}

/// `dst[m × n] (row stride dst_stride) = (accumulate ? dst : 0) + a · b`.
pub fn matmul<T: Real>(
    dst: &mut [T],
    dst_stride: usize,
    a: View<'_, T>,
    b: View<'_, T>,
    accumulate: bool,
) {
    let (m, k) = a.shape();
    let (k2, n) = b.shape();
    assert_eq!(k, k2, "matmul inner dimensions");
    if m == 0 || n == 0 {
        return;
    }
    assert!(dst.len() >= (m - 1) * dst_stride + n);
    if k == 0 {
        if !accumulate {
            for r in 0..m {
                dst[r * dst_stride..r * dst_stride + n].fill(T::ZERO);
            }
        }
        return;
    }
    use rayon::prelude::*;
    const BLOCK: usize = 2048;
    if !a.transposed && m >= 2 * BLOCK {
        // rayon over row blocks of a (and dst), one single-threaded gemm each
        dst[..(m - 1) * dst_stride + n]
            .par_chunks_mut(BLOCK * dst_stride)
            .enumerate()
            .for_each(|(blk, d)| {
                let r0 = blk * BLOCK;
                let rows = BLOCK.min(m - r0);
                let sub = View::new(&a.data[r0 * a.stride..], rows, a.cols, a.stride);
                gemm_raw(d, dst_stride, sub, b, accumulate);
            });
        return;
    }
    if a.transposed && !b.transposed && k >= 2 * BLOCK {
        // aᵀ·b is a sum over the shared rows: partial products per row block, then add
        let partial = (0..k.div_ceil(BLOCK))
            .into_par_iter()
            .map(|blk| {
                let r0 = blk * BLOCK;
                let rows = BLOCK.min(k - r0);
                let sa = View::new(&a.data[r0 * a.stride..], rows, a.cols, a.stride).t();
                let sb = View::new(&b.data[r0 * b.stride..], rows, b.cols, b.stride);
                let mut p = vec![T::ZERO; m * n];
                gemm_raw(&mut p, n, sa, sb, false);
                p
            })
            .reduce_with(|mut x, y| {
                for (u, v) in x.iter_mut().zip(y) {
                    *u += v;
                }
                x
            })
            .expect("non-empty");
        for r in 0..m {
            let d = &mut dst[r * dst_stride..r * dst_stride + n];
            let p = &partial[r * n..(r + 1) * n];
            for (u, &v) in d.iter_mut().zip(p) {
                *u = if accumulate { *u + v } else { v };
            }
        }
        return;
    }
    gemm_raw(dst, dst_stride, a, b, accumulate);
}

/// Single-threaded gemm call on views whose shapes were checked by the caller.
fn gemm_raw<T: Real>(
    dst: &mut [T],
    dst_stride: usize,
    a: View<'_, T>,
    b: View<'_, T>,
    accumulate: bool,
) {
    let (m, k) = a.shape();
    let (_, n) = b.shape();
    assert!(dst.len() >= (m - 1) * dst_stride + n);
    let (a_cs, a_rs) = a.strides();
    let (b_cs, b_rs) = b.strides();
    let par = gemm::Parallelism::None;
    // SAFETY: the asserts above and in `View::new` keep every accessed element in
    // bounds; dst does not alias a or b (distinct borrows).
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst.as_mut_ptr(),
            1,
            dst_stride as isize,
            accumulate,
            a.data.as_ptr(),
            a_cs,
            a_rs,
            b.data.as_ptr(),
            b_cs,
            b_rs,
            T::ONE,
            T::ONE,
            false,
            false,
            false,
            par,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matmul_matches_naive_with_transposes() {
        let a: Vec<f64> = (0..12).map(|i| i as f64 * 0.5 - 2.0).collect(); // 3×4
        let b: Vec<f64> = (0..8).map(|i| (i * i) as f64 * 0.1).collect(); // 4×2
        let mut c = vec![1.0; 6];
        matmul(
            &mut c,
            2,
            View::new(&a, 3, 4, 4),
            View::new(&b, 4, 2, 2),
            true,
        );
        for r in 0..3 {
            for j in 0..2 {
                let want: f64 = 1.0 + (0..4).map(|k| a[r * 4 + k] * b[k * 2 + j]).sum::<f64>();
                assert!((c[r * 2 + j] - want).abs() < 1e-12);
            }
        }
        // aᵀ (4×3) · a (3×4)
        let mut g = vec![0.0; 16];
        let va = View::new(&a, 3, 4, 4);
        matmul(&mut g, 4, va.t(), va, false);
        for i in 0..4 {
            for j in 0..4 {
                let want: f64 = (0..3).map(|r| a[r * 4 + i] * a[r * 4 + j]).sum();
                assert!((g[i * 4 + j] - want).abs() < 1e-12);
            }
        }
    }
}

#[cfg(test)]
mod block_tests {
    use super::*;

    /// Row-block and reduction paths agree with the naive product.
    #[test]
    fn blocked_paths_match_naive() {
        let (m, k, n) = (5000, 7, 3);
        let a: Vec<f64> = (0..m * k)
            .map(|i| ((i * 37 % 101) as f64) * 0.01 - 0.5)
            .collect();
        let b: Vec<f64> = (0..k * n).map(|i| (i as f64) * 0.1 - 1.0).collect();
        let mut c = vec![0.5; m * n];
        matmul(
            &mut c,
            n,
            View::new(&a, m, k, k),
            View::new(&b, k, n, n),
            true,
        );
        for r in [0, 2047, 2048, 4999] {
            for j in 0..n {
                let want: f64 = 0.5 + (0..k).map(|q| a[r * k + q] * b[q * n + j]).sum::<f64>();
                assert!((c[r * n + j] - want).abs() < 1e-9);
            }
        }
        // aᵀ (k×m) · c (m×n): reduction over 5000 rows
        let mut g = vec![1.0; k * n];
        matmul(
            &mut g,
            n,
            View::new(&a, m, k, k).t(),
            View::new(&c, m, n, n),
            true,
        );
        for i in 0..k {
            for j in 0..n {
                let want: f64 = 1.0 + (0..m).map(|r| a[r * k + i] * c[r * n + j]).sum::<f64>();
                assert!((g[i * n + j] - want).abs() < 1e-6 * want.abs().max(1.0));
            }
        }
    }
}
