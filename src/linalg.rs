//! Fixed-size linear algebra for the 3×3 metrological model: products, a checked inverse and
//! the conditioning measure that decides whether a matrix may be inverted at all.

use crate::float::Float;

/// A 3-vector, one element per unit axis x, y, z.
pub type Vec3<F> = [F; 3];
/// A 3×3 matrix, row-major: `m[i][j]` is row i, column j.
pub type Mat3<F> = [[F; 3]; 3];

/// Smallest accepted Hadamard ratio `|det K| / (‖k₁‖·‖k₂‖·‖k₃‖)` of a matrix to be inverted.
///
/// The ratio is 1 for orthogonal rows and 0 for singular ones, independent of scale. A real
/// triaxial unit sits near 1 (its cross-sensitivities are a few per cent of its scale factors);
/// 1e-3 rejects only matrices whose rows are nearly dependent, where an `f32` inverse would lose
/// more than half its digits.
pub const MIN_HADAMARD_RATIO: f64 = 1e-3;

/// `m · v`.
#[inline(always)]
pub fn mat_vec<F: Float>(m: &Mat3<F>, v: &Vec3<F>) -> Vec3<F> {
    [
        m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2],
        m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
        m[2][0] * v[0] + m[2][1] * v[1] + m[2][2] * v[2],
    ]
}

/// `a · b`.
pub fn mat_mul<F: Float>(a: &Mat3<F>, b: &Mat3<F>) -> Mat3<F> {
    let mut c = [[F::ZERO; 3]; 3];
    for (i, row) in c.iter_mut().enumerate() {
        for (j, cell) in row.iter_mut().enumerate() {
            *cell = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
        }
    }
    c
}

/// `a · b` with fused multiply-adds ([`Float::mul_add`]): each element rounded about once.
/// Written out element by element (constant indices: no bounds check in any build).
#[inline(always)]
pub fn mat_mul_fused<F: Float>(a: &Mat3<F>, b: &Mat3<F>) -> Mat3<F> {
    let e = |r: &Vec3<F>, j: usize| r[2].mul_add(b[2][j], r[1].mul_add(b[1][j], r[0] * b[0][j]));
    let row = |r: &Vec3<F>| [e(r, 0), e(r, 1), e(r, 2)];
    [row(&a[0]), row(&a[1]), row(&a[2])]
}

/// `c − a · b` with fused multiply-adds ([`Float::mul_add`]), element by element.
#[inline(always)]
pub fn mat_mul_sub<F: Float>(a: &Mat3<F>, b: &Mat3<F>, c: &Mat3<F>) -> Mat3<F> {
    let e =
        |r: &Vec3<F>, j: usize, x: F| (-r[2]).mul_add(b[2][j], (-r[1]).mul_add(b[1][j], (-r[0]).mul_add(b[0][j], x)));
    let row = |r: &Vec3<F>, x: &Vec3<F>| [e(r, 0, x[0]), e(r, 1, x[1]), e(r, 2, x[2])];
    [row(&a[0], &c[0]), row(&a[1], &c[1]), row(&a[2], &c[2])]
}

/// `m · v` with fused multiply-adds ([`Float::mul_add`]).
#[inline(always)]
pub fn mat_vec_fused<F: Float>(m: &Mat3<F>, v: &Vec3<F>) -> Vec3<F> {
    let e = |r: &Vec3<F>| r[2].mul_add(v[2], r[1].mul_add(v[1], r[0] * v[0]));
    [e(&m[0]), e(&m[1]), e(&m[2])]
}

/// `a + b` element-wise.
#[inline(always)]
pub fn vec_add<F: Float>(a: &Vec3<F>, b: &Vec3<F>) -> Vec3<F> {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// `a − b` element-wise.
#[inline(always)]
pub fn mat_sub<F: Float>(a: &Mat3<F>, b: &Mat3<F>) -> Mat3<F> {
    let row = |x: &Vec3<F>, y: &Vec3<F>| [x[0] - y[0], x[1] - y[1], x[2] - y[2]];
    [row(&a[0], &b[0]), row(&a[1], &b[1]), row(&a[2], &b[2])]
}

/// `a − b` element-wise.
#[inline(always)]
pub fn vec_sub<F: Float>(a: &Vec3<F>, b: &Vec3<F>) -> Vec3<F> {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// Euclidean norm.
#[inline(always)]
pub fn norm<F: Float>(v: &Vec3<F>) -> F {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// Largest absolute element.
pub fn max_abs<F: Float>(v: &Vec3<F>) -> F {
    v[0].abs().max(v[1].abs()).max(v[2].abs())
}

/// Induced ∞-norm (largest absolute row sum).
pub fn norm_inf<F: Float>(m: &Mat3<F>) -> F {
    let row = |r: &[F; 3]| r[0].abs() + r[1].abs() + r[2].abs();
    row(&m[0]).max(row(&m[1])).max(row(&m[2]))
}

/// Determinant.
#[inline(always)]
pub fn det<F: Float>(m: &Mat3<F>) -> F {
    m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
}

/// Hadamard ratio `|det m| / Π‖row‖` in [0, 1]; 0 for a zero row or non-finite input.
pub fn hadamard_ratio<F: Float>(m: &Mat3<F>) -> F {
    let p = norm(&m[0]) * norm(&m[1]) * norm(&m[2]);
    let d = det(m).abs();
    if !(p > F::ZERO) || !p.is_finite() || !d.is_finite() {
        return F::ZERO;
    }
    d / p
}

/// Inverse by the adjugate, or `None` when the matrix is not finite or its Hadamard ratio is
/// below `min_ratio` (so no division by a vanishing determinant can happen).
#[inline(always)]
pub fn inverse_checked<F: Float>(m: &Mat3<F>, min_ratio: F) -> Option<Mat3<F>> {
    let (c0, d) = first_row_cofactors(m);
    let p = norm(&m[0]) * norm(&m[1]) * norm(&m[2]);
    // `!(x >= y)` is also true for NaN, so a non-finite matrix is rejected here too.
    if !(d.abs() >= min_ratio * p) || !(p > F::ZERO) || !d.is_finite() || !p.is_finite() {
        return None;
    }
    Some(adjugate_times(m, c0, F::ONE / d))
}

/// Inverse by the adjugate, or `None` when the determinant is zero or not finite (or outside
/// the normal range of `f32`). No conditioning check: for a matrix whose conditioning is
/// checked elsewhere (the load-time `f64` inverse, whose `f32` image [`inverse_checked`] has
/// accepted). The reciprocal of the determinant is [`float::recip`](crate::float::recip)'s (no
/// `f64` division on the target): within 2 ulp of `1/det`.
#[inline(always)]
pub fn inverse_unchecked<F: Float>(m: &Mat3<F>) -> Option<Mat3<F>> {
    let (c0, d) = first_row_cofactors(m);
    if !(d.abs() > F::ZERO) || !d.is_finite() {
        return None;
    }
    let r = crate::float::recip(d);
    if !r.is_finite() {
        return None;
    }
    Some(adjugate_times(m, c0, r))
}

/// The cofactors of the first row and the determinant expanded along it.
#[inline(always)]
fn first_row_cofactors<F: Float>(m: &Mat3<F>) -> ([F; 3], F) {
    let c00 = m[1][1] * m[2][2] - m[1][2] * m[2][1];
    let c01 = m[1][2] * m[2][0] - m[1][0] * m[2][2];
    let c02 = m[1][0] * m[2][1] - m[1][1] * m[2][0];
    ([c00, c01, c02], m[0][0] * c00 + m[0][1] * c01 + m[0][2] * c02)
}

/// The adjugate of `m` times `r`, the reciprocal of its determinant (`c0`: the first row's
/// cofactors).
#[inline(always)]
fn adjugate_times<F: Float>(m: &Mat3<F>, c0: [F; 3], r: F) -> Mat3<F> {
    let [c00, c01, c02] = c0;
    [
        [c00 * r, (m[0][2] * m[2][1] - m[0][1] * m[2][2]) * r, (m[0][1] * m[1][2] - m[0][2] * m[1][1]) * r],
        [c01 * r, (m[0][0] * m[2][2] - m[0][2] * m[2][0]) * r, (m[0][2] * m[1][0] - m[0][0] * m[1][2]) * r],
        [c02 * r, (m[0][1] * m[2][0] - m[0][0] * m[2][1]) * r, (m[0][0] * m[1][1] - m[0][1] * m[1][0]) * r],
    ]
}

/// Converts every element between float types (through `f64`).
#[cfg_attr(unstable_target, optimize(size))]
pub fn cast_mat<A: Float, B: Float>(m: &Mat3<A>) -> Mat3<B> {
    let mut out = [[B::ZERO; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            out[i][j] = B::from_f64(m[i][j].to_f64());
        }
    }
    out
}

/// Converts every element between float types (through `f64`).
#[cfg_attr(unstable_target, optimize(size))]
pub fn cast_vec<A: Float, B: Float>(v: &Vec3<A>) -> Vec3<B> {
    [B::from_f64(v[0].to_f64()), B::from_f64(v[1].to_f64()), B::from_f64(v[2].to_f64())]
}

/// Solves the small dense `N`×`N` system `a·x = b` by Gaussian elimination with partial
/// pivoting; `None` when a pivot vanishes relative to the largest element of `a` (or `N` is 0).
///
/// A system smaller than the arrays at hand is solved by putting it in the top-left corner and
/// an identity below and to the right of it (zeros elsewhere, zeros in `b`): its unknowns come
/// out exactly as if it were solved alone (the identity's rows are never chosen as pivots and
/// never change), the others as 0; the tolerance is the same as long as the system's largest
/// element is at least 1.
///
/// ```
/// use bins_comp::linalg::solve;
/// // 2x + y = 3, x + 3y = 5: x = 0.8, y = 1.4.
/// let alone: [f64; 2] = solve([[2.0, 1.0], [1.0, 3.0]], [3.0, 5.0]).unwrap();
/// assert!((alone[0] - 0.8).abs() < 1e-15 && (alone[1] - 1.4).abs() < 1e-15);
/// // The same system in 4×4 arrays, an identity in the unused corner: the same bits.
/// let a = [[2.0, 1.0, 0.0, 0.0], [1.0, 3.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];
/// let embedded = solve(a, [3.0, 5.0, 0.0, 0.0]).unwrap();
/// assert_eq!(embedded, [alone[0], alone[1], 0.0, 0.0]);
/// // A singular system has no solution.
/// assert_eq!(solve([[1.0, 2.0], [2.0, 4.0]], [1.0, 2.0]), None);
/// ```
pub fn solve<F: Float, const N: usize>(mut a: [[F; N]; N], mut b: [F; N]) -> Option<[F; N]> {
    let n = N;
    if n == 0 {
        return None;
    }
    let mut scale = F::ZERO;
    for row in a.iter() {
        for &x in row.iter() {
            scale = scale.max(x.abs());
        }
    }
    if !(scale > F::ZERO) || !scale.is_finite() {
        return None;
    }
    let tiny = scale * F::EPSILON * F::from_f64(16.0);
    for col in 0..n {
        let mut piv = col;
        for r in col + 1..n {
            if a[r][col].abs() > a[piv][col].abs() {
                piv = r;
            }
        }
        if !(a[piv][col].abs() > tiny) {
            return None;
        }
        a.swap(col, piv);
        b.swap(col, piv);
        for r in col + 1..n {
            let f = a[r][col] / a[col][col];
            for c in col..n {
                let v = a[col][c];
                a[r][c] -= f * v;
            }
            let v = b[col];
            b[r] -= f * v;
        }
    }
    let mut x = [F::ZERO; N];
    for col in (0..n).rev() {
        let mut s = b[col];
        for c in col + 1..n {
            s -= a[col][c] * x[c];
        }
        x[col] = s / a[col][col];
    }
    if x.iter().all(|v| v.is_finite()) { Some(x) } else { None }
}
