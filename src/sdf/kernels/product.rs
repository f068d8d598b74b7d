//! Matrix products on host memory through gemm (the kernels behind burn's Flex backend),
//! written into caller-owned buffers.
//!
//! [`product_into`] multiplies strided views (a transpose is a view, never a copy) straight
//! into a destination slice, overwriting or accumulating, on the calling thread: the building
//! block of the network passes in [`crate::sdf::kernels::passes`], which parallelise over chunks of points
//! themselves.

use crate::sdf::kernels::softplus::HostFloat;

/// A float type gemm multiplies (f32, f64).
pub trait GemmFloat: HostFloat {}

impl GemmFloat for f32 {}

impl GemmFloat for f64 {}

/// A strided matrix in a slice: element (i, j) is `data[start + i·row_stride + j·col_stride]`.
#[derive(Debug, Clone, Copy)]
pub struct View<'a, T> {
    /// The storage.
    pub data: &'a [T],
    /// Rows of the matrix.
    pub rows: usize,
    /// Columns of the matrix.
    pub cols: usize,
    /// Distance between consecutive rows.
    pub row_stride: isize,
    /// Distance between consecutive columns.
    pub col_stride: isize,
    /// Index of element (0, 0).
    pub start: usize,
}

impl<'a, T> View<'a, T> {
    /// A dense row-major `[rows, cols]` matrix.
    pub fn dense(data: &'a [T], rows: usize, cols: usize) -> Self {
        Self {
            data,
            rows,
            cols,
            row_stride: cols as isize,
            col_stride: 1,
            start: 0,
        }
    }

    /// The transposed matrix, as a view of the same storage.
    pub fn transposed(self) -> Self {
        Self {
            rows: self.cols,
            cols: self.rows,
            row_stride: self.col_stride,
            col_stride: self.row_stride,
            ..self
        }
    }

    /// Whether every element the view addresses lies inside `data` (the bound gemm's
    /// raw pointers rely on).
    fn in_bounds(&self) -> bool {
        if self.rows == 0 || self.cols == 0 {
            return true;
        }
        let reach = |extent: usize, stride: isize| -> Option<(isize, isize)> {
            let span = isize::try_from(extent - 1).ok()?.checked_mul(stride)?;
            Some(if span < 0 { (span, 0) } else { (0, span) })
        };
        let (Some((r_lo, r_hi)), Some((c_lo, c_hi)), Ok(start)) = (
            reach(self.rows, self.row_stride),
            reach(self.cols, self.col_stride),
            isize::try_from(self.start),
        ) else {
            return false;
        };
        let lowest = start.checked_add(r_lo).and_then(|v| v.checked_add(c_lo));
        let highest = start.checked_add(r_hi).and_then(|v| v.checked_add(c_hi));
        matches!((lowest, highest), (Some(lo), Some(hi)) if lo >= 0 && (hi as usize) < self.data.len())
    }
}

/// `dst = lhs · rhs`, or `dst += lhs · rhs` when `accumulate`, for a dense row-major
/// `dst` of `[lhs.rows, rhs.cols]`, on the calling thread.
///
/// # Panics
/// If the sizes do not fit or a view addresses elements outside its slice.
// gemm has no safe entry point; the views and the destination are bounds-checked before
// the call.
#[allow(unsafe_code)]
pub fn product_into<T: GemmFloat>(
    dst: &mut [T],
    lhs: View<'_, T>,
    rhs: View<'_, T>,
    accumulate: bool,
) {
    assert_eq!(lhs.cols, rhs.rows, "inner sizes of a product");
    assert!(
        lhs.in_bounds() && rhs.in_bounds(),
        "product operand outside its storage"
    );
    let (m, k, n) = (lhs.rows, lhs.cols, rhs.cols);
    assert_eq!(
        Some(dst.len()),
        m.checked_mul(n),
        "product destination size"
    );
    if dst.is_empty() {
        return;
    }
    if k == 0 {
        if !accumulate {
            dst.fill(T::ZERO);
        }
        return;
    }
    // SAFETY: both views were checked to address only elements of their slices, and
    // `dst` holds exactly m·n initialised elements, row-major (row stride n, column
    // stride 1); gemm writes only those (and reads them only when accumulating).
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst.as_mut_ptr(),
            1,
            n as isize,
            accumulate,
            lhs.data.as_ptr().add(lhs.start),
            lhs.col_stride,
            lhs.row_stride,
            rhs.data.as_ptr().add(rhs.start),
            rhs.col_stride,
            rhs.row_stride,
            T::ONE,
            T::ONE,
            false,
            false,
            false,
            gemm::Parallelism::None,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Deterministic values in [−1, 1).
    fn values(n: usize, seed: u64) -> Vec<f64> {
        (0..n)
            .map(|i| {
                let v = (i as u64 + 1)
                    .wrapping_mul(6_364_136_223_846_793_005)
                    .wrapping_add(seed);
                ((v >> 33) % 2000) as f64 / 1000.0 - 1.0
            })
            .collect()
    }

    /// `A·B` by an explicit triple loop, reading both through their views.
    fn brute_force(a: View<'_, f64>, b: View<'_, f64>) -> Vec<f64> {
        let at = |v: &View<'_, f64>, i: usize, j: usize| {
            v.data[(v.start as isize + i as isize * v.row_stride + j as isize * v.col_stride)
                as usize]
        };
        let mut c = vec![0.0; a.rows * b.cols];
        for i in 0..a.rows {
            for j in 0..b.cols {
                c[i * b.cols + j] = (0..a.cols).map(|p| at(&a, i, p) * at(&b, p, j)).sum();
            }
        }
        c
    }

    /// Products of dense, transposed and offset views equal a brute-force loop, written and
    /// accumulated, in f64 and f32, from a vector to a few hundred rows and columns.
    #[test]
    fn products_equal_a_brute_force_loop() {
        for [m, k, n] in [[5, 3, 4], [1, 7, 1], [300, 200, 150], [64, 3, 9]] {
            let a = values(m * k, 1);
            let b_t = values(n * k, 2);
            let tall = values((k + 2) * n, 3);
            for (variant, rhs) in [
                ("transposed", View::dense(&b_t, n, k).transposed()),
                (
                    "offset rows",
                    View {
                        start: 2 * n,
                        ..View::dense(&tall[..], k, n)
                    },
                ),
            ] {
                let lhs = View::dense(&a, m, k);
                let want = brute_force(lhs, rhs);
                let mut got = vec![0.0; m * n];
                product_into(&mut got, lhs, rhs, false);
                let start = values(m * n, 4);
                let mut acc = start.clone();
                product_into(&mut acc, lhs, rhs, true);
                let a32: Vec<f32> = a.iter().map(|&v| v as f32).collect();
                let rhs_data32: Vec<f32> = rhs.data.iter().map(|&v| v as f32).collect();
                let rhs32 = View {
                    data: &rhs_data32[..],
                    rows: rhs.rows,
                    cols: rhs.cols,
                    row_stride: rhs.row_stride,
                    col_stride: rhs.col_stride,
                    start: rhs.start,
                };
                let mut got32 = vec![7.0f32; m * n];
                product_into(&mut got32, View::dense(&a32, m, k), rhs32, false);
                for i in 0..m * n {
                    let label = format!("[{m},{k}]·[{k},{n}] {variant} [{i}]");
                    assert!(
                        (got[i] - want[i]).abs() <= 1e-12 * (1.0 + want[i].abs()),
                        "{label}"
                    );
                    let sum = start[i] + want[i];
                    assert!(
                        (acc[i] - sum).abs() <= 1e-12 * (1.0 + sum.abs()),
                        "{label} +="
                    );
                    let w = want[i] as f32;
                    assert!(
                        (got32[i] - w).abs() <= 1e-4 * (1.0 + w.abs()),
                        "{label} f32"
                    );
                }
            }
        }
    }

    #[test]
    #[should_panic(expected = "outside its storage")]
    fn a_view_beyond_its_slice_is_refused() {
        let a = vec![1.0f64; 6];
        let mut out = vec![0.0; 4];
        let bad = View::dense(&a[..], 3, 3);
        product_into(&mut out, View::dense(&a, 2, 3), bad.transposed(), false);
    }
}
