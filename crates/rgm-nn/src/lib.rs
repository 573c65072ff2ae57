//! rgm-nn — hand-written tensor operations for RGM, each a forward and a backward pass, with
//! no autograd framework: the network's graph is fixed, so the model calls the backward passes
//! explicitly, in reverse order.
//!
//! Layering rule: rgm-nn depends on no other rgm crate and knows nothing of geometry, point
//! clouds or matching. It owns the numeric engine: BLAS-backed matrix products, the ops, their
//! parameters, initialisation, optimisers and weight files.

// Links the statically built OpenBLAS that ndarray's `blas` feature calls into.
extern crate openblas_src;

pub mod scalar;

pub use scalar::Scalar;
