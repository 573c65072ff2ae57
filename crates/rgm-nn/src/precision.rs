//! The precision of the f32 matrix products: f32 (the default) or bf16 inputs with f32
//! accumulation on the processor's AMX tile units or AVX-512 BF16 dot products
//! ([`crate::gemm`]).
//!
//! The setting is per thread and scoped: a caller enters it around the work it covers
//! (`let _bf16 = precision::enter(Precision::Bf16);`) and the previous setting comes back when
//! the guard drops. Every matrix product of the ops reads it ([`crate::gemm::mat_mul`]), so op
//! signatures stay as they are, and a thread that never enters a scope (a gradient check, a
//! rayon worker) computes in f32. Only the products change: reductions (softmax, norms, sums)
//! and f64 products are never affected.

use std::cell::Cell;
use std::fmt;
use std::str::FromStr;

/// How an f32 matrix product is computed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Precision {
    /// f32 inputs, f32 products (on AVX-512 where the processor has it, BLAS elsewhere).
    #[default]
    F32,
    /// Inputs rounded to bfloat16 (round to nearest even), products accumulated in f32, on AMX
    /// or AVX-512 BF16 where the processor has either; f32 elsewhere.
    Bf16,
}

impl Precision {
    /// The names `--precision` accepts.
    pub const NAMES: [&'static str; 2] = ["f32", "bf16"];

    pub fn name(self) -> &'static str {
        match self {
            Precision::F32 => "f32",
            Precision::Bf16 => "bf16",
        }
    }
}

impl fmt::Display for Precision {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Precision {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "f32" => Ok(Precision::F32),
            "bf16" => Ok(Precision::Bf16),
            _ => Err(format!(
                "unknown precision {s:?} (expected one of {})",
                Precision::NAMES.join(", ")
            )),
        }
    }
}

thread_local! {
    static CURRENT: Cell<Precision> = const { Cell::new(Precision::F32) };
}

/// The calling thread's precision.
pub fn current() -> Precision {
    CURRENT.with(Cell::get)
}

/// `a` and `b` side by side on rayon's pool (`rayon::join`), each in the caller's precision:
/// the pool's threads have their own.
pub fn join<A, B, RA, RB>(a: A, b: B) -> (RA, RB)
where
    A: FnOnce() -> RA + Send,
    B: FnOnce() -> RB + Send,
    RA: Send,
    RB: Send,
{
    let precision = current();
    rayon::join(
        || {
            let _precision = enter(precision);
            a()
        },
        || {
            let _precision = enter(precision);
            b()
        },
    )
}

/// Sets the calling thread's precision until the returned guard drops (scopes nest).
#[must_use = "the precision reverts when the guard drops"]
pub fn enter(precision: Precision) -> Scope {
    Scope {
        previous: CURRENT.with(|c| c.replace(precision)),
        _not_send: std::marker::PhantomData,
    }
}

/// The guard of [`enter`]: restores the previous precision of its thread on drop (it cannot
/// leave the thread, hence not `Send`).
pub struct Scope {
    previous: Precision,
    _not_send: std::marker::PhantomData<*const ()>,
}

impl Drop for Scope {
    fn drop(&mut self) {
        CURRENT.with(|c| c.set(self.previous));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scopes_nest_and_restore_and_stay_on_their_thread() {
        assert_eq!(current(), Precision::F32);
        {
            let _outer = enter(Precision::Bf16);
            assert_eq!(current(), Precision::Bf16);
            std::thread::spawn(|| assert_eq!(current(), Precision::F32))
                .join()
                .unwrap();
            {
                let _inner = enter(Precision::F32);
                assert_eq!(current(), Precision::F32);
            }
            assert_eq!(current(), Precision::Bf16);
        }
        assert_eq!(current(), Precision::F32);
    }

    #[test]
    fn names_round_trip_and_bad_names_are_named() {
        for p in [Precision::F32, Precision::Bf16] {
            assert_eq!(p.name().parse::<Precision>(), Ok(p));
        }
        let err = "fp16".parse::<Precision>().unwrap_err();
        assert!(
            err.contains("\"fp16\"") && err.contains("f32, bf16"),
            "{err}"
        );
    }
}
