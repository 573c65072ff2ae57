//! The compute settings every op that runs a matrix product takes ([`Compute`]): the precision
//! of the f32 products, f32 (the default) or bf16 inputs with f32 accumulation on the
//! processor's AMX tile units or AVX-512 BF16 dot products ([`crate::gemm`]).
//!
//! The settings are a value passed down from the caller (the network holds its own) to the
//! products that choose a kernel, not a per-thread state: work spread over rayon's pool
//! computes as its caller asked without each worker being told again, and a setting no thread
//! can hold for the work (a device) has the same way down. Only the products read it:
//! reductions (softmax, norms, sums) and f64 products are never affected.

use std::fmt;
use std::str::FromStr;

/// How the ops compute: passed by value to every op that runs a matrix product, which hands it
/// on to [`crate::gemm::mat_mul`]. The default is f32, what a gradient check or any caller
/// that asks for nothing gets.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Compute {
    /// How the f32 matrix products run.
    pub precision: Precision,
}

impl Compute {
    /// The settings with `precision` and every other setting at its default.
    pub fn with_precision(precision: Precision) -> Self {
        Self { precision }
    }
}

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

#[cfg(test)]
mod tests {
    use super::*;

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
