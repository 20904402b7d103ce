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
    if !a.transposed && m >= 2 * BLOCK {
        matmul_rows_with(dst, dst_stride, a, b, accumulate, |_, _| {}, |_, _| {});
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

/// Rows per task of the row-parallel products.
const BLOCK: usize = 2048;

/// [`matmul`] of a non-transposed `a` by blocks of rows, with `before(first_row, rows)`
/// run on each block of `dst` just before its product and `after(first_row, rows)` just
/// after, while the block is in cache (a bias written before an accumulating product, an
/// activation or mask after it: one pass over memory instead of three). `rows` holds the
/// block's rows of `dst` (row stride `dst_stride`). The products are those of `matmul`,
/// block for block, so the values are the same bit for bit.
pub fn matmul_rows_with<T: Real>(
    dst: &mut [T],
    dst_stride: usize,
    a: View<'_, T>,
    b: View<'_, T>,
    accumulate: bool,
    before: impl Fn(usize, &mut [T]) + Sync,
    after: impl Fn(usize, &mut [T]) + Sync,
) {
    use rayon::prelude::*;
    assert!(!a.transposed, "matmul_rows_with: a must not be transposed");
    let (m, k) = a.shape();
    let (k2, n) = b.shape();
    assert_eq!(k, k2, "matmul inner dimensions");
    if m == 0 || n == 0 {
        return;
    }
    let used = (m - 1) * dst_stride + n;
    assert!(dst.len() >= used);
    // `rows` rows of dst from row `r0`: before, the product, after.
    let run = |r0: usize, rows: usize, d: &mut [T]| {
        before(r0, d);
        if k > 0 {
            let sub = View::new(&a.data[r0 * a.stride..], rows, a.cols, a.stride);
            gemm_raw(d, dst_stride, sub, b, accumulate);
        } else if !accumulate {
            for r in 0..rows {
                d[r * dst_stride..r * dst_stride + n].fill(T::ZERO);
            }
        }
        after(r0, d);
    };
    if m >= 2 * BLOCK {
        // rayon over row blocks of a (and dst), one single-threaded gemm each
        dst[..used]
            .par_chunks_mut(BLOCK * dst_stride)
            .enumerate()
            .for_each(|(blk, d)| run(blk * BLOCK, BLOCK.min(m - blk * BLOCK), d));
    } else {
        // one block, as `matmul` computes it
        run(0, m, &mut dst[..used]);
    }
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

#[cfg(test)]
mod hook_tests {
    use super::*;

    /// `matmul_rows_with` runs `before` on each block of rows ahead of its product and
    /// `after` behind it, with the block's first row: a bias written before an
    /// accumulating product and a ReLU after it give `max(bias + a·b, 0)` on every row, on
    /// the row-block path (5 000 rows) and the single-block one (300), bit for bit what
    /// `matmul` gives with the bias and ReLU as passes of their own.
    #[test]
    fn hooks_see_each_block_and_the_product_is_matmuls() {
        let (k, n) = (5, 4);
        let bias = [0.25f32, -0.5, 0.0, 1.0];
        for m in [300usize, 5000] {
            let a: Vec<f32> = (0..m * k)
                .map(|i| ((i * 37 % 101) as f32) * 0.01 - 0.5)
                .collect();
            let b: Vec<f32> = (0..k * n).map(|i| (i as f32) * 0.1 - 1.0).collect();
            let (va, vb) = (View::new(&a, m, k, k), View::new(&b, k, n, n));
            let mut want: Vec<f32> = (0..m).flat_map(|_| bias).collect();
            matmul(&mut want, n, va, vb, true);
            want.iter_mut().for_each(|v| *v = v.max(0.0));
            let firsts = std::sync::Mutex::new(Vec::new());
            let mut got = vec![f32::NAN; m * n];
            matmul_rows_with(
                &mut got,
                n,
                va,
                vb,
                true,
                |_, rows| rows.chunks_mut(n).for_each(|r| r.copy_from_slice(&bias)),
                |r0, rows| {
                    firsts.lock().unwrap().push((r0, rows.len() / n));
                    rows.iter_mut().for_each(|v| *v = v.max(0.0));
                },
            );
            assert_eq!(got, want, "m = {m}");
            let mut blocks = firsts.into_inner().unwrap();
            blocks.sort_unstable();
            let expect: Vec<(usize, usize)> = if m >= 2 * BLOCK {
                (0..m.div_ceil(BLOCK))
                    .map(|b| (b * BLOCK, BLOCK.min(m - b * BLOCK)))
                    .collect()
            } else {
                vec![(0, m)]
            };
            assert_eq!(blocks, expect, "m = {m}");
            // …and the bias and ReLU did something: some zeros, some positive values
            assert!(got.contains(&0.0) && got.iter().any(|&v| v > 0.0));
        }
    }
}
