#![doc = include_str!("../README.md")]
//!
//! # Layering
//!
//! Layering rule: rgm-registration builds on rgm-geom only (clouds, transforms, kNN, Kabsch,
//! normals, FPFH, the unit-sphere frame); it knows nothing about tensors, gradients or networks,
//! and holds no tuned value of its own (the thresholds are configuration: rgm-model's
//! `policy::TUNED` gives them; this crate's tests use values of their own). Everything is f64, as in rgm-geom.
//!
//! The modules, bottom first, as a registration runs through them:
//! - [`error`] (what a method fails with), [`fit`] (what a method returns), [`prepared`] (a cloud with its tree and normals, made
//!   once per registration), [`thinning`] (a dense cloud at the density a method was tuned
//!   at), and [`registrar`] (the trait every method implements);
//! - [`methods`]: the estimators, global and local, each a [`Registrar`];
//! - [`refiner`]: the trait of a refinement that improves a given transform, for the local
//!   methods;
//! - [`check`]: how a result is judged without ground truth (overlap, coincidence, the judge);
//! - [`compose`]: the wrappers and composites that make one method of several;
//! - [`multiway`]: many scans put into one frame with any of those methods as the pairwise one
//!   (the pose graph, its loop checks and solver, multiway ICP).

// `!(x > 0.0)` is used on purpose: it also rejects NaN, which `x <= 0.0` would let through.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod check;
pub mod compose;
pub mod error;
pub mod fit;
pub mod methods;
pub mod multiway;
pub mod prepared;
pub mod refiner;
pub mod registrar;
pub mod thinning;

#[cfg(test)]
mod testing;

pub use error::{AllCandidatesFailed, RegistrationError};
pub use fit::Fit;
pub use prepared::Prepared;
pub use registrar::{DynRegistrar, MethodId, Registrar, Registration};
