//! Small dense kernels on row-major `f64` slices, used by the block-sparse solver.
//!
//! Matrices are stored row-major: entry `(r, c)` of an `m × n` matrix lives at `r * n + c`.
//! None of these functions allocate; they are meant for the small blocks (dimension 1..=6
//! typically) of the multibody Newton matrix. The LU factorisation uses partial (row)
//! pivoting and stores its pivots LAPACK-style: at step `c`, row `c` was swapped with
//! row `piv[c] >= c`, so that `P A = L U` with `L` unit lower triangular.

/// Evaluate `$call` with the size variable `$n` bound to a literal when it is one of the block
/// sizes of the Newton matrix (1 to 8: bodies 6, joints 1-5, contacts 2 or 8, limits 4), so
/// that the kernel inlined into each arm is compiled for that size (unrolled loops, no bounds
/// checks) and runs the same floating-point operations in the same order as the generic one.
/// Measured on the shared A1: the kernels ran ~9 instructions per flop with runtime sizes.
macro_rules! sized {
    ($n:ident => $call:expr) => {
        match $n {
            1 => {
                let $n = 1;
                $call
            }
            2 => {
                let $n = 2;
                $call
            }
            3 => {
                let $n = 3;
                $call
            }
            4 => {
                let $n = 4;
                $call
            }
            5 => {
                let $n = 5;
                $call
            }
            6 => {
                let $n = 6;
                $call
            }
            7 => {
                let $n = 7;
                $call
            }
            8 => {
                let $n = 8;
                $call
            }
            _ => $call,
        }
    };
}

/// `dst[..n] = src[..n]` for a block's `n` entries, inlined for the block sizes (a
/// `copy_from_slice` of a runtime length is a `memcpy` call: 2% of the A1's steps went into
/// those calls for 1-8 entries in the block solves).
#[inline]
pub fn copy_small(dst: &mut [f64], src: &[f64], n: usize) {
    sized!(n => dst[..n].copy_from_slice(&src[..n]))
}

/// In-place LU factorisation with partial pivoting of the `n × n` row-major matrix `a`.
///
/// On return `a` holds `L` (strictly below the diagonal, unit diagonal implied) and `U`
/// (on and above the diagonal), and `piv[c]` is the row swapped with row `c` at step `c`.
/// Returns `false` (leaving `a` partially factored) if a pivot is exactly zero or not finite.
pub fn lu_factor(a: &mut [f64], n: usize, piv: &mut [usize]) -> bool {
    sized!(n => lu_factor_sized(a, n, piv))
}

#[inline(always)]
fn lu_factor_sized(a: &mut [f64], n: usize, piv: &mut [usize]) -> bool {
    debug_assert!(a.len() >= n * n && piv.len() >= n);
    let a = &mut a[..n * n];
    if n > 8 {
        return (0..n).all(|c| lu_column(a, n, c, piv));
    }
    // the column loop unrolled as well, so that with `n` a literal every row operation has a
    // literal length (the 8×8 contact blocks took ~2800 instructions with the loop)
    macro_rules! columns {
        ($($c:literal)*) => {
            $(if $c < n && !lu_column(a, n, $c, piv) {
                return false;
            })*
        };
    }
    columns!(0 1 2 3 4 5 6 7);
    true
}

/// Elimination step `c` of [`lu_factor`]: pivot, swap, update the rows below.
#[inline(always)]
fn lu_column(a: &mut [f64], n: usize, c: usize, piv: &mut [usize]) -> bool {
    let p = pivot_row(a, n, c);
    let pivot = a[p * n + c];
    if pivot == 0.0 || !pivot.is_finite() {
        return false;
    }
    piv[c] = p;
    swap_rows(a, n, c, p);
    let (top, bottom) = a.split_at_mut((c + 1) * n);
    let row_c = &top[c * n..];
    // (one division a column: multiplying by the reciprocal, the rows' multipliers need none)
    let inv = 1.0 / pivot;
    for row_r in bottom[..(n - c - 1) * n].chunks_exact_mut(n) {
        // l_rc = a_rc / u_cc;  a_r,c+1.. -= l_rc * u_c,c+1..
        let l = row_r[c] * inv;
        row_r[c] = l;
        if l != 0.0 {
            axpy_neg(&mut row_r[c + 1..], l, &row_c[c + 1..n]);
        }
    }
    true
}

/// Row index `>= c` of the largest `|a[r][c]|` (a NaN entry is always selected).
#[inline(always)]
fn pivot_row(a: &[f64], n: usize, c: usize) -> usize {
    let mut best = c;
    let mut best_abs = a[c * n + c].abs();
    for r in c + 1..n {
        let v = a[r * n + c].abs();
        if v > best_abs || v.is_nan() {
            best = r;
            best_abs = v;
        }
    }
    best
}

/// Swap rows `i` and `j` (each `ncols` long) of a row-major matrix.
#[inline(always)]
fn swap_rows(a: &mut [f64], ncols: usize, i: usize, j: usize) {
    if i == j {
        return;
    }
    let (lo, hi) = (i.min(j), i.max(j));
    let (top, bottom) = a.split_at_mut(hi * ncols);
    top[lo * ncols..(lo + 1) * ncols].swap_with_slice(&mut bottom[..ncols]);
}

/// `y -= alpha * x`, elementwise over the common length.
#[inline(always)]
fn axpy_neg(y: &mut [f64], alpha: f64, x: &[f64]) {
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi -= alpha * xi;
    }
}

/// Solve `A x = b` in place, given the output of [`lu_factor`] for `A`.
pub fn lu_solve(lu: &[f64], n: usize, piv: &[usize], b: &mut [f64]) {
    sized!(n => lu_solve_sized(lu, n, piv, b))
}

#[inline(always)]
fn lu_solve_sized(lu: &[f64], n: usize, piv: &[usize], b: &mut [f64]) {
    let (lu, b) = (&lu[..n * n], &mut b[..n]);
    // b := P b
    for (c, &r) in piv[..n].iter().enumerate() {
        b.swap(c, r);
    }
    // L y = P b (forward, unit diagonal)
    for i in 1..n {
        let s: f64 = (0..i).map(|k| lu[i * n + k] * b[k]).sum();
        b[i] -= s;
    }
    // U x = y (backward; the pivots' reciprocals depend on `lu` alone, so their divisions
    // stay off the substitution's chain of dependent operations)
    for i in (0..n).rev() {
        let inv = 1.0 / lu[i * n + i];
        let s: f64 = (i + 1..n).map(|k| lu[i * n + k] * b[k]).sum();
        b[i] = (b[i] - s) * inv;
    }
}

/// Solve `Aᵀ x = b` in place, given the output of [`lu_factor`] for `A`.
pub fn lu_solve_transpose(lu: &[f64], n: usize, piv: &[usize], b: &mut [f64]) {
    sized!(n => lu_solve_transpose_sized(lu, n, piv, b))
}

#[inline(always)]
fn lu_solve_transpose_sized(lu: &[f64], n: usize, piv: &[usize], b: &mut [f64]) {
    let (lu, b) = (&lu[..n * n], &mut b[..n]);
    // Aᵀ = Uᵀ Lᵀ P;  Uᵀ w = b (forward)
    for i in 0..n {
        let inv = 1.0 / lu[i * n + i];
        let s: f64 = (0..i).map(|k| lu[k * n + i] * b[k]).sum();
        b[i] = (b[i] - s) * inv;
    }
    // Lᵀ v = w (backward, unit diagonal)
    for i in (0..n).rev() {
        let s: f64 = (i + 1..n).map(|k| lu[k * n + i] * b[k]).sum();
        b[i] -= s;
    }
    // x = Pᵀ v (undo the swaps in reverse order)
    for c in (0..n).rev() {
        b.swap(c, piv[c]);
    }
}

/// Overwrite the `n × ncols` row-major matrix `x` with `A⁻ᵀ X`, given the output of
/// [`lu_factor`] for `A`: [`lu_solve_transpose`] for all right-hand sides at once, on whole
/// (contiguous) rows of `X`. (The Jacobians' transposed back-substitution solves ~50 of them
/// per diagonal block; one column at a time, gathered and scattered, it was half of that
/// solve's time on the shared humanoid.)
pub fn lu_solve_transpose_left_matrix(
    lu: &[f64],
    n: usize,
    piv: &[usize],
    x: &mut [f64],
    ncols: usize,
) {
    sized!(n => lu_solve_transpose_left_matrix_sized(lu, n, piv, x, ncols))
}

#[inline(always)]
fn lu_solve_transpose_left_matrix_sized(
    lu: &[f64],
    n: usize,
    piv: &[usize],
    x: &mut [f64],
    ncols: usize,
) {
    let (lu, x) = (&lu[..n * n], &mut x[..n * ncols]);
    // Each column gets exactly `lu_solve_transpose`'s operations (a dot product summed in
    // order from -0.0, as `Iterator::sum` does, then subtracted), so that both give the same
    // bits; columns go in chunks of `W`, the running sums on the stack.
    const W: usize = 8;
    let mut start = 0;
    while start < ncols {
        let w = W.min(ncols - start);
        let col = |r: usize| r * ncols + start..r * ncols + start + w;
        // Aᵀ = Uᵀ Lᵀ P;  Uᵀ W = X (forward): x_i = (x_i - Σ_{k<i} u_ki x_k) / u_ii
        for i in 0..n {
            let mut acc = [-0.0f64; W];
            for k in 0..i {
                let u = lu[k * n + i];
                for (a, v) in acc[..w].iter_mut().zip(&x[col(k)]) {
                    *a += u * v;
                }
            }
            let inv = 1.0 / lu[i * n + i];
            for (v, a) in x[col(i)].iter_mut().zip(&acc) {
                *v = (*v - a) * inv;
            }
        }
        // Lᵀ V = W (backward, unit diagonal): x_i -= Σ_{k>i} l_ki x_k
        for i in (0..n).rev() {
            let mut acc = [-0.0f64; W];
            for k in i + 1..n {
                let l = lu[k * n + i];
                for (a, v) in acc[..w].iter_mut().zip(&x[col(k)]) {
                    *a += l * v;
                }
            }
            for (v, a) in x[col(i)].iter_mut().zip(&acc) {
                *v -= a;
            }
        }
        start += w;
    }
    // X = Pᵀ V (undo the swaps in reverse order)
    for c in (0..n).rev() {
        swap_rows(x, ncols, c, piv[c]);
    }
}

/// Overwrite the `m × n` row-major matrix `x` with `X A⁻¹` (i.e. solve `Y A = X`).
///
/// Each row `y` of `Y` satisfies `Aᵀ yᵀ = xᵀ`, so this is a transposed solve per row.
pub fn lu_solve_right(lu: &[f64], n: usize, piv: &[usize], x: &mut [f64], m: usize) {
    if n == 0 {
        return;
    }
    for row in x[..m * n].chunks_exact_mut(n) {
        lu_solve_transpose(lu, n, piv, row);
    }
}

/// Overwrite the `n × ncols` row-major matrix `x` with `A⁻¹ X`.
///
/// Works on whole (contiguous) rows of `X`, i.e. all right-hand sides at once.
pub fn lu_solve_left_matrix(lu: &[f64], n: usize, piv: &[usize], x: &mut [f64], ncols: usize) {
    // pivots of contacts (8) and bodies (6) are the common ones: both sizes literal there
    match n {
        8 => sized!(ncols => lu_solve_left_matrix_sized(lu, 8, piv, x, ncols)),
        6 => sized!(ncols => lu_solve_left_matrix_sized(lu, 6, piv, x, ncols)),
        _ => sized!(ncols => lu_solve_left_matrix_sized(lu, n, piv, x, ncols)),
    }
}

#[inline(always)]
fn lu_solve_left_matrix_sized(lu: &[f64], n: usize, piv: &[usize], x: &mut [f64], ncols: usize) {
    let (lu, x) = (&lu[..n * n], &mut x[..n * ncols]);
    // X := P X
    for (c, &r) in piv[..n].iter().enumerate() {
        swap_rows(x, ncols, c, r);
    }
    // (each row is updated in a local copy when it fits one: the same operations in the same
    // order, without storing the row after each update)
    let mut acc = [0.0f64; 8];
    let local = ncols <= acc.len();
    // L Y = P X: row_i -= l_ik row_k for k < i
    for i in 1..n {
        let (top, bottom) = x.split_at_mut(i * ncols);
        let row_i = &mut bottom[..ncols];
        let target: &mut [f64] = if local {
            acc[..ncols].copy_from_slice(row_i);
            &mut acc[..ncols]
        } else {
            row_i
        };
        for (k, row_k) in top.chunks_exact(ncols).enumerate() {
            let l = lu[i * n + k];
            if l != 0.0 {
                axpy_neg(target, l, row_k);
            }
        }
        if local {
            bottom[..ncols].copy_from_slice(&acc[..ncols]);
        }
    }
    // U Z = Y: row_i = (row_i - Σ_{k>i} u_ik row_k) / u_ii
    for i in (0..n).rev() {
        let (top, bottom) = x.split_at_mut((i + 1) * ncols);
        let row_i = &mut top[i * ncols..];
        let target: &mut [f64] = if local {
            acc[..ncols].copy_from_slice(row_i);
            &mut acc[..ncols]
        } else {
            row_i
        };
        for (j, row_k) in bottom[..(n - i - 1) * ncols]
            .chunks_exact(ncols)
            .enumerate()
        {
            let u = lu[i * n + i + 1 + j];
            if u != 0.0 {
                axpy_neg(target, u, row_k);
            }
        }
        let inv = 1.0 / lu[i * n + i];
        target.iter_mut().for_each(|v| *v *= inv);
        if local {
            top[i * ncols..(i + 1) * ncols].copy_from_slice(&acc[..ncols]);
        }
    }
}

/// `C -= A · B` with `C` `m × n`, `A` `m × k`, `B` `k × n` (all row-major).
pub fn gemm_sub(c: &mut [f64], a: &[f64], b: &[f64], m: usize, k: usize, n: usize) {
    // updates through contacts (8) and bodies (6) are the common ones: both sizes literal
    match k {
        8 => sized!(n => gemm_sub_sized(c, a, b, m, 8, n)),
        6 => sized!(n => gemm_sub_sized(c, a, b, m, 6, n)),
        _ => sized!(n => gemm_sub_sized(c, a, b, m, k, n)),
    }
}

#[inline(always)]
fn gemm_sub_sized(c: &mut [f64], a: &[f64], b: &[f64], m: usize, k: usize, n: usize) {
    if n == 0 || k == 0 {
        return;
    }
    // c_i,: -= Σ_p a_ip b_p,:
    let update = |row: &mut [f64], a_row: &[f64]| {
        for (&a_ip, b_row) in a_row.iter().zip(b.chunks_exact(n)) {
            // a contact's coupling to a body has 3 nonzero columns of 8: skip the zero ones
            // (their products are zeros; only a zero's sign or a NaN in `b` could differ)
            if a_ip != 0.0 {
                axpy_neg(row, a_ip, b_row);
            }
        }
    };
    let rows = c[..m * n].chunks_exact_mut(n).zip(a.chunks_exact(k));
    if n > 8 {
        rows.for_each(|(c_row, a_row)| update(c_row, a_row));
        return;
    }
    // (each row accumulated in a local copy: the same operations in the same order, without
    // storing `c_i,:` after each `p`)
    let mut acc = [0.0f64; 8];
    for (c_row, a_row) in rows {
        acc[..n].copy_from_slice(c_row);
        update(&mut acc[..n], a_row);
        c_row.copy_from_slice(&acc[..n]);
    }
}

/// `y -= A x` with `A` `m × n` row-major, `y` of length `m`, `x` of length `n`.
pub fn gemv_sub(y: &mut [f64], a: &[f64], x: &[f64], m: usize, n: usize) {
    sized!(n => gemv_sub_sized(y, a, x, m, n))
}

#[inline(always)]
fn gemv_sub_sized(y: &mut [f64], a: &[f64], x: &[f64], m: usize, n: usize) {
    if n == 0 {
        return;
    }
    let x = &x[..n];
    for (yi, a_row) in y[..m].iter_mut().zip(a.chunks_exact(n)) {
        *yi -= dot(a_row, x);
    }
}

/// `y += A x` with `A` `m × n` row-major, `y` of length `m`, `x` of length `n`.
pub fn gemv_add(y: &mut [f64], a: &[f64], x: &[f64], m: usize, n: usize) {
    sized!(n => gemv_add_sized(y, a, x, m, n))
}

#[inline(always)]
fn gemv_add_sized(y: &mut [f64], a: &[f64], x: &[f64], m: usize, n: usize) {
    if n == 0 {
        return;
    }
    let x = &x[..n];
    for (yi, a_row) in y[..m].iter_mut().zip(a.chunks_exact(n)) {
        *yi += dot(a_row, x);
    }
}

/// `y -= Aᵀ x` with `A` `m × n` row-major, `y` of length `n`, `x` of length `m`.
pub fn gemv_t_sub(y: &mut [f64], a: &[f64], x: &[f64], m: usize, n: usize) {
    sized!(n => gemv_t_sub_sized(y, a, x, m, n))
}

#[inline(always)]
fn gemv_t_sub_sized(y: &mut [f64], a: &[f64], x: &[f64], m: usize, n: usize) {
    if n == 0 {
        return;
    }
    for (&xi, a_row) in x[..m].iter().zip(a.chunks_exact(n)) {
        // y -= x_i a_i,:
        axpy_neg(&mut y[..n], xi, a_row);
    }
}

/// Dot product over the common length.
#[inline(always)]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector};

    use crate::solver::test_rng::Rng;

    fn assert_close(a: &[f64], b: &[f64], tol: f64) {
        assert_eq!(a.len(), b.len());
        let scale = b.iter().fold(1.0f64, |m, v| m.max(v.abs()));
        for (x, y) in a.iter().zip(b) {
            assert!((x - y).abs() <= tol * scale, "{x} vs {y}");
        }
    }

    fn factored(rng: &mut Rng, n: usize) -> (Vec<f64>, Vec<f64>, Vec<usize>) {
        let a = rng.vec(n * n);
        let mut lu = a.clone();
        let mut piv = vec![0; n];
        assert!(lu_factor(&mut lu, n, &mut piv));
        (a, lu, piv)
    }

    #[test]
    fn solves_match_nalgebra() {
        let mut rng = Rng(7);
        for n in 1..=8 {
            for _ in 0..20 {
                let (a, lu, piv) = factored(&mut rng, n);
                let am = DMatrix::from_row_slice(n, n, &a);
                let nlu = am.clone().lu();
                let b = rng.vec(n);
                let mut x = b.clone();
                lu_solve(&lu, n, &piv, &mut x);
                let xr = nlu
                    .solve(&DVector::from_column_slice(&b))
                    .unwrap_or_default();
                assert_close(&x, xr.as_slice(), 1e-9);
                let mut xt = b.clone();
                lu_solve_transpose(&lu, n, &piv, &mut xt);
                let xtr = am.transpose().lu().solve(&DVector::from_column_slice(&b));
                assert_close(&xt, xtr.unwrap_or_default().as_slice(), 1e-9);
            }
        }
    }

    #[test]
    fn matrix_solves_match_nalgebra() {
        let mut rng = Rng(11);
        for n in 1..=9 {
            for m in 1..=5 {
                let (a, lu, piv) = factored(&mut rng, n);
                let am = DMatrix::from_row_slice(n, n, &a);
                let inv = am.try_inverse().unwrap_or_default();
                // Right: X (m×n) A⁻¹
                let x = rng.vec(m * n);
                let mut y = x.clone();
                lu_solve_right(&lu, n, &piv, &mut y, m);
                let yr = DMatrix::from_row_slice(m, n, &x) * &inv;
                assert_close(&y, yr.transpose().as_slice(), 1e-8);
                // Left: A⁻¹ X (n×m)
                let x = rng.vec(n * m);
                let mut y = x.clone();
                lu_solve_left_matrix(&lu, n, &piv, &mut y, m);
                let yr = &inv * DMatrix::from_row_slice(n, m, &x);
                assert_close(&y, yr.transpose().as_slice(), 1e-8);
                // Left, transposed: A⁻ᵀ X (n×m)
                let mut y = x.clone();
                lu_solve_transpose_left_matrix(&lu, n, &piv, &mut y, m);
                let yr = inv.transpose() * DMatrix::from_row_slice(n, m, &x);
                assert_close(&y, yr.transpose().as_slice(), 1e-8);
            }
        }
    }

    #[test]
    fn products_match_nalgebra() {
        let mut rng = Rng(3);
        for (m, k, n) in [(1, 1, 1), (2, 3, 4), (6, 6, 6), (5, 1, 3), (3, 6, 1)] {
            let (a, b, c) = (rng.vec(m * k), rng.vec(k * n), rng.vec(m * n));
            let mut c2 = c.clone();
            gemm_sub(&mut c2, &a, &b, m, k, n);
            let r = DMatrix::from_row_slice(m, n, &c)
                - DMatrix::from_row_slice(m, k, &a) * DMatrix::from_row_slice(k, n, &b);
            assert_close(&c2, r.transpose().as_slice(), 1e-12);

            let am = DMatrix::from_row_slice(m, k, &a);
            let (x, y) = (rng.vec(k), rng.vec(m));
            let mut y2 = y.clone();
            gemv_sub(&mut y2, &a, &x, m, k);
            let r = DVector::from_column_slice(&y) - &am * DVector::from_column_slice(&x);
            assert_close(&y2, r.as_slice(), 1e-12);
            let mut y3 = y.clone();
            gemv_add(&mut y3, &a, &x, m, k);
            let r = DVector::from_column_slice(&y) + &am * DVector::from_column_slice(&x);
            assert_close(&y3, r.as_slice(), 1e-12);

            let (x, y) = (rng.vec(m), rng.vec(k));
            let mut y2 = y.clone();
            gemv_t_sub(&mut y2, &a, &x, m, k);
            let r =
                DVector::from_column_slice(&y) - am.transpose() * DVector::from_column_slice(&x);
            assert_close(&y2, r.as_slice(), 1e-12);
        }
    }

    #[test]
    fn singular_and_non_finite_are_rejected() {
        let mut piv = [0; 3];
        let mut a = [1.0, 2.0, 3.0, 2.0, 4.0, 6.0, 0.0, 0.0, 1.0];
        assert!(!lu_factor(&mut a, 3, &mut piv));
        let mut z = [0.0; 4];
        assert!(!lu_factor(&mut z, 2, &mut piv));
        let mut nan = [1.0, f64::NAN, 0.5, 1.0];
        assert!(!lu_factor(&mut nan, 2, &mut piv));
        let mut inf = [f64::INFINITY, 0.0, 0.0, 1.0];
        assert!(!lu_factor(&mut inf, 2, &mut piv));
    }

    #[test]
    fn pivoting_handles_zero_leading_entry() {
        let a = [0.0, 1.0, 1.0, 0.0];
        let mut lu = a;
        let mut piv = [0; 2];
        assert!(lu_factor(&mut lu, 2, &mut piv));
        let mut b = [2.0, 3.0];
        lu_solve(&lu, 2, &piv, &mut b);
        assert_eq!(b, [3.0, 2.0]);
    }
}
