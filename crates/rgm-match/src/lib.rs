#![doc = include_str!("../README.md")]
//!
//! # Layering and conventions
//!
//! Layering rule: rgm-match builds on rgm-nn (its `Scalar` element type, matrix products through
//! ndarray) and rgm-geom (the two-worker steps of [`rgm_geom::lockstep`] that the Sinkhorn runs
//! on), and knows nothing of networks' other layers, data sets or the pipeline above it.
//!
//! Conventions: those of rgm-nn (see its crate doc) — generic over `T: Scalar` (f32 compute, f64
//! gradient checks), outputs first then inputs and the compute settings ([`rgm_nn::Compute`])
//! last where an op runs rgm-nn's matrix products (the affinity), caller-owned caches holding
//! exactly what the backward needs, backward passes that *add* into `d<name>` buffers and
//! [`rgm_nn::Param`] gradients, layers with parameters as structs, parameterless ops as free
//! functions. One call handles one pair (N source points, M target points, Q feature width); a
//! batch is a loop whose parameter gradients accumulate.

pub mod affinity;
pub mod assign;
pub mod correspondences;
pub mod error;
pub mod inst_norm;
pub mod loss;
pub mod sinkhorn;
pub mod var1;

#[cfg(test)]
mod reference;

pub use affinity::{Affinity, AffinityCache, AffinityConfig};
pub use assign::{hard_match, max_score_assignment, select_inliers, MatchConfig};
pub use correspondences::Correspondences;
pub use error::{MatchError, Result};
pub use inst_norm::{InstNorm, InstNormCache, InstNormConfig};
pub use loss::{bce_backward, bce_forward};
pub use sinkhorn::{
    sinkhorn_backward, sinkhorn_forward, SinkhornCache, SinkhornConfig, SinkhornForm,
};
pub use var1::{var1_backward, var1_forward, Var1Config};
