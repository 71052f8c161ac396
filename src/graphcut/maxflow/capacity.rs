//! The capacity types of the graph: `f64` and exact `i64`.

use std::fmt::Debug;
use std::ops::{Add, AddAssign, Neg, Sub, SubAssign};

/// A capacity type: `f64` or `i64` (integers give exact answers).
pub trait Capacity:
    Copy
    + PartialOrd
    + Debug
    + Default
    + Send
    + Sync
    + 'static
    + Add<Output = Self>
    + Sub<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
{
    /// Zero.
    const ZERO: Self;
    /// Integers: sums are exact but wrap past the type's range, so callers bound them
    /// (floats round instead, and overflow only to a non-finite value).
    const EXACT: bool;
    /// Exact types: the largest sum of magnitudes a graph may hold (the type's maximum).
    const EXACT_LIMIT: u128;
    /// True for a usable capacity or cost: finite (floats) and not NaN.
    fn is_finite_value(self) -> bool;
    /// Lossy conversion for reporting.
    fn to_f64(self) -> f64;
    /// Conversion from a count or small constant.
    fn from_i32(v: i32) -> Self;
    /// Addition that reports overflow (integers) or a non-finite result (floats).
    fn checked_add(self, other: Self) -> Option<Self>;
    /// Multiplication that reports overflow (integers) or a non-finite result (floats).
    fn checked_mul(self, other: Self) -> Option<Self>;
    /// |self| as a wide integer for the overflow budget of exact types (0 for floats).
    fn exact_magnitude(self) -> u128;
    /// The smaller of two values.
    #[inline(always)]
    fn min_of(self, other: Self) -> Self {
        if other < self {
            other
        } else {
            self
        }
    }
}

impl Capacity for f64 {
    const ZERO: Self = 0.0;
    const EXACT: bool = false;
    const EXACT_LIMIT: u128 = u128::MAX;
    #[inline(always)]
    fn is_finite_value(self) -> bool {
        self.is_finite()
    }
    fn to_f64(self) -> f64 {
        self
    }
    fn from_i32(v: i32) -> Self {
        v as f64
    }
    fn checked_add(self, other: Self) -> Option<Self> {
        let s = self + other;
        s.is_finite().then_some(s)
    }
    fn checked_mul(self, other: Self) -> Option<Self> {
        let s = self * other;
        s.is_finite().then_some(s)
    }
    fn exact_magnitude(self) -> u128 {
        0
    }
}

impl Capacity for i64 {
    const ZERO: Self = 0;
    const EXACT: bool = true;
    const EXACT_LIMIT: u128 = i64::MAX as u128;
    #[inline(always)]
    fn is_finite_value(self) -> bool {
        true
    }
    fn to_f64(self) -> f64 {
        self as f64
    }
    fn from_i32(v: i32) -> Self {
        v as i64
    }
    fn checked_add(self, other: Self) -> Option<Self> {
        i64::checked_add(self, other)
    }
    fn checked_mul(self, other: Self) -> Option<Self> {
        i64::checked_mul(self, other)
    }
    fn exact_magnitude(self) -> u128 {
        self.unsigned_abs() as u128
    }
}
