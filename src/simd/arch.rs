//! The choice of instruction set at run time.

#[cfg(target_arch = "x86_64")]
use super::avx2::Avx2;
#[cfg(target_arch = "x86_64")]
use super::avx512::Avx512;
use super::lanes::{Simd, WithSimd};

/// The instruction sets a kernel may run with on this CPU, best first.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Arch {
    #[cfg(target_arch = "x86_64")]
    Avx512(Avx512),
    #[cfg(target_arch = "x86_64")]
    Avx2(Avx2),
}

impl Arch {
    /// The best set of this CPU: AVX-512 (with BMI2) unless `DEPTHPOSE_NO_AVX512` is
    /// set ([`crate::cpu::avx512`]), else AVX2; None without either.
    pub fn new() -> Option<Arch> {
        Self::available().into_iter().next()
    }

    /// Every set this CPU has (AVX-512 only if allowed, see [`Self::new`]), best first.
    pub fn available() -> Vec<Arch> {
        let mut sets = Vec::new();
        #[cfg(target_arch = "x86_64")]
        {
            if let Some(s) = Avx512::try_new() {
                sets.push(Arch::Avx512(s));
            }
            if let Some(s) = Avx2::try_new() {
                sets.push(Arch::Avx2(s));
            }
        }
        sets
    }

    /// Every set this CPU has, whatever the environment says (for tests that compare
    /// the sets).
    #[cfg(test)]
    pub fn supported() -> Vec<Arch> {
        let mut sets = Vec::new();
        #[cfg(target_arch = "x86_64")]
        {
            if let Some(s) = Avx512::detected() {
                sets.push(Arch::Avx512(s));
            }
            if let Some(s) = Avx2::try_new() {
                sets.push(Arch::Avx2(s));
            }
        }
        sets
    }

    /// Runs `op` with this set.
    #[inline]
    pub fn dispatch<Op: WithSimd>(self, op: Op) -> Op::Output {
        match self {
            #[cfg(target_arch = "x86_64")]
            Arch::Avx512(s) => s.vectorize(op),
            #[cfg(target_arch = "x86_64")]
            Arch::Avx2(s) => s.vectorize(op),
        }
    }
}
