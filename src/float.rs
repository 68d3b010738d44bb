//! The floating-point abstraction that lets one implementation of every formula run as `f32`
//! on the target and as `f64` on the host (the reference).
//!
//! Only operations whose results are identical on x86-64 (SSE) and on the Cortex-M4F FPU are
//! used: IEEE add, subtract, multiply, divide, the correctly rounded square root and fused
//! multiply-add ([`Float::mul_add`]: the FPU's `vfma.f32` on the target, `libm`'s `fmaf` on
//! the host; both round `a·b + c` once) and `libm`'s software `acos`, `exp`, `erfc` (built from
//! the same basic operations). The compiler never fuses a product and a sum by itself (Rust
//! does not contract floating-point expressions), so every fused operation is one written as
//! such, and the host's `f32` results equal the target's bit for bit.

use core::fmt::Debug;
use core::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub, SubAssign};

/// A real scalar: implemented for `f32` (target) and `f64` (host reference).
pub trait Float:
    Copy
    + Default
    + Debug
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
{
    /// 0
    const ZERO: Self;
    /// 1
    const ONE: Self;
    /// The machine epsilon of the type.
    const EPSILON: Self;
    /// A quiet NaN.
    const NAN: Self;
    /// Converts an `f64` (a constant, or a value computed in `f64`) to this type, rounding to
    /// nearest for `f32`; the inverse of [`to_f64`](Self::to_f64) where that is exact.
    fn from_f64(x: f64) -> Self;
    /// Widens to `f64` (exact).
    fn to_f64(self) -> f64;
    /// `x` as a pair `hi + lo` of this type: `hi` is `x` rounded, `lo` the rest rounded, so
    /// the pair holds about twice the mantissa of this type (`f64`: `(x, 0)`). Without `f64`
    /// arithmetic: the rest is taken from the bits (see the `f32` implementation).
    fn split_f64(x: f64) -> (Self, Self);
    /// Absolute value.
    fn abs(self) -> Self;
    /// Square root (`libm`, correctly rounded).
    fn sqrt(self) -> Self;
    /// `self·a + b` rounded once (IEEE 754 fusedMultiplyAdd): one `vfma.f32` on the
    /// Cortex-M4F, `libm`'s correctly rounded `fmaf`/`fma` on the host (the CPU's FMA
    /// instruction where it has one), so the same bits on both. The product is exact inside
    /// it: `x.mul_add(y, s)` with a small `s` is `x·y + s` to one rounding of the result.
    fn mul_add(self, a: Self, b: Self) -> Self;
    /// True unless NaN or ±∞.
    fn is_finite(self) -> bool;
    /// The larger of two values; a NaN operand yields the other one.
    fn max(self, other: Self) -> Self;
    /// The smaller of two values; a NaN operand yields the other one.
    fn min(self, other: Self) -> Self;
    /// Arc cosine \[rad\] (`libm`, software; identical on host and target).
    fn acos(self) -> Self;
    /// Exponential (`libm`, software; identical on host and target).
    fn exp(self) -> Self;
    /// Complementary error function `1 − erf(x)` (`libm`, software; identical on host and
    /// target).
    fn erfc(self) -> Self;
}

impl Float for f32 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    const EPSILON: Self = f32::EPSILON;
    const NAN: Self = f32::NAN;
    #[inline(always)]
    fn from_f64(x: f64) -> Self {
        x as f32
    }
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self as f64
    }
    /// `hi` is `x` rounded to `f32`; `lo` is `x − hi`, an integer multiple of `x`'s last
    /// place with at most 30 bits, from the two mantissas, rounded to `f32`: `hi + lo` is
    /// within 2⁻⁴⁷·|x| of `x`. For |x| below 2⁻⁷⁴ (or `hi` not a normal number) `lo` is 0:
    /// the rest is then below 2⁻⁹⁸. Load-time code: out of line, optimised for size.
    #[inline(never)]
    #[cfg_attr(unstable_target, optimize(size))]
    fn split_f64(x: f64) -> (f32, f32) {
        let hi = x as f32;
        let (xb, hb) = (x.to_bits(), hi.to_bits());
        let (ex, eh) = (((xb >> 52) & 0x7ff) as i32, ((hb >> 23) & 0xff) as i32);
        // x = mx·2^(ex − 1075), hi = mh·2^(eh − 150), of the same sign; hi's last place is 2^29
        // or 2^30 times x's (30 when the rounding carried into the next binade).
        let unit = ex - 1075;
        let shift = (eh - 150) - unit;
        if ex == 0 || eh == 0 || eh == 0xff || !(29..=30).contains(&shift) || unit < -126 {
            return (hi, 0.0);
        }
        let mx = ((xb & ((1 << 52) - 1)) | (1 << 52)) as i64;
        let mh = ((hb & 0x7f_ffff) | 0x80_0000) as i64;
        let rest = (mx - (mh << shift)) as i32 as f32;
        let lo = rest * f32::from_bits(((unit + 127) as u32) << 23);
        (hi, if xb >> 63 != 0 { -lo } else { lo })
    }
    #[inline(always)]
    fn abs(self) -> Self {
        libm::fabsf(self)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        // The FPU's square root where the compiler offers it (see `build.rs`); libm's is
        // correctly rounded too, so both give the same bits.
        #[cfg(unstable_target)]
        return core::f32::math::sqrt(self);
        #[cfg(not(unstable_target))]
        return libm::sqrtf(self);
    }
    #[inline(always)]
    fn mul_add(self, a: Self, b: Self) -> Self {
        // The FPU's fused multiply-add where the compiler offers it (see `build.rs`); libm's is
        // correctly rounded too, so both give the same bits.
        #[cfg(unstable_target)]
        return core::f32::math::mul_add(self, a, b);
        #[cfg(not(unstable_target))]
        return libm::fmaf(self, a, b);
    }
    #[inline(always)]
    fn is_finite(self) -> bool {
        f32::is_finite(self)
    }
    #[inline(always)]
    fn max(self, other: Self) -> Self {
        libm::fmaxf(self, other)
    }
    #[inline(always)]
    fn min(self, other: Self) -> Self {
        libm::fminf(self, other)
    }
    #[inline(always)]
    fn acos(self) -> Self {
        libm::acosf(self)
    }
    #[inline(always)]
    fn exp(self) -> Self {
        libm::expf(self)
    }
    #[inline(always)]
    fn erfc(self) -> Self {
        libm::erfcf(self)
    }
}

impl Float for f64 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    const EPSILON: Self = f64::EPSILON;
    const NAN: Self = f64::NAN;
    #[inline(always)]
    fn from_f64(x: f64) -> Self {
        x
    }
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self
    }
    #[inline(always)]
    fn split_f64(x: f64) -> (f64, f64) {
        (x, 0.0)
    }
    #[inline(always)]
    fn abs(self) -> Self {
        libm::fabs(self)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        libm::sqrt(self)
    }
    #[inline(always)]
    fn mul_add(self, a: Self, b: Self) -> Self {
        libm::fma(self, a, b)
    }
    #[inline(always)]
    fn is_finite(self) -> bool {
        f64::is_finite(self)
    }
    #[inline(always)]
    fn max(self, other: Self) -> Self {
        libm::fmax(self, other)
    }
    #[inline(always)]
    fn min(self, other: Self) -> Self {
        libm::fmin(self, other)
    }
    #[inline(always)]
    fn acos(self) -> Self {
        libm::acos(self)
    }
    #[inline(always)]
    fn exp(self) -> Self {
        libm::exp(self)
    }
    #[inline(always)]
    fn erfc(self) -> Self {
        libm::erfc(self)
    }
}

/// `1/x` without a division in the working precision: the `f32` quotient refined by two
/// Newton steps `r ← r + r·(1 − x·r)` (each squares the relative error: 2⁻²⁴ → 2⁻⁴⁸ → the
/// rounding of the last step), within 2 ulp of the correctly rounded `1/x` for `|x|` in the
/// normal range of `f32` (NaN outside it). For the load-time `f64` code on the target, which
/// has an `f32` divider but no `f64` one: the soft-float `f64` division would cost 0.9 KB of
/// flash for four divisions at boot.
#[inline(never)]
#[cfg_attr(unstable_target, optimize(size))]
pub fn recip<F: Float>(x: F) -> F {
    let r0 = F::from_f64((1.0f32 / x.to_f64() as f32) as f64);
    let r1 = r0 + r0 * (F::ONE - x * r0);
    r1 + r1 * (F::ONE - x * r1)
}

/// `f64` comparisons by the bits, for the load-time checks: the target has no `f64`
/// arithmetic, and the soft-float comparison routines would cost it flash for a few tests at
/// boot. Each is the IEEE comparison (−0 equal to +0, false when either side is NaN), here
/// and on the host alike.
pub mod cmp_f64 {
    use core::cmp::Ordering;

    /// An integer in the order of the values: the magnitude's bits, negated for a negative
    /// sign (−0 and +0 both 0; NaN orders beyond ±∞, which is why the tests below exclude it).
    #[inline(always)]
    fn key(x: f64) -> i64 {
        let b = x.to_bits() as i64;
        if b < 0 { -(b & i64::MAX) } else { b }
    }

    /// Not NaN.
    #[inline(always)]
    fn ordered(x: f64) -> bool {
        x.to_bits() & !(1 << 63) <= 0x7ff0_0000_0000_0000
    }

    /// `a.partial_cmp(&b)`: one out-of-line copy for the tests below.
    #[inline(never)]
    #[cfg_attr(unstable_target, optimize(size))]
    fn order(a: f64, b: f64) -> Option<Ordering> {
        if ordered(a) && ordered(b) { Some(key(a).cmp(&key(b))) } else { None }
    }

    /// `a < b`.
    #[inline(always)]
    pub fn lt(a: f64, b: f64) -> bool {
        order(a, b) == Some(Ordering::Less)
    }

    /// `a <= b`.
    #[inline(always)]
    pub fn le(a: f64, b: f64) -> bool {
        matches!(order(a, b), Some(Ordering::Less | Ordering::Equal))
    }

    /// `a == b`.
    #[inline(always)]
    pub fn eq(a: f64, b: f64) -> bool {
        order(a, b) == Some(Ordering::Equal)
    }
}

/// Knuth's TwoSum: `s + e = a + b` exactly, `s = fl(a + b)`.
#[inline(always)]
pub fn two_sum<F: Float>(a: F, b: F) -> (F, F) {
    let s = a + b;
    let bb = s - a;
    let e = (a - (s - bb)) + (b - bb);
    (s, e)
}

/// Dekker's Fast2Sum: `s + e = a + b` exactly, `s = fl(a + b)`, provided `|a| ≥ |b|` (or
/// `a = 0`).
#[inline(always)]
pub fn fast_two_sum<F: Float>(a: F, b: F) -> (F, F) {
    let s = a + b;
    (s, b - (s - a))
}
