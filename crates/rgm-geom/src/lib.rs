#![doc = include_str!("../README.md")]
//!
//! # Layering and conventions
//!
//! Layering rule: rgm-geom depends on no other rgm crate and knows nothing about tensors,
//! gradients or networks. Everything is f64; callers convert at their boundary.
//!
//! Conventions: a transform `t_target_source` maps source coordinates into the target frame,
//! `y = R x + t`.

// `!(x > 0.0)` is used on purpose: it also rejects NaN, which `x <= 0.0` would let through.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod best_of;
pub mod cloud;
pub mod coincidence;
pub mod error;
pub mod euler;
pub mod feature_matches;
pub mod fgr;
pub mod fpfh;
pub mod frame;
pub mod icp;
pub mod kabsch;
pub mod knn;
pub mod lockstep;
pub mod metrics;
pub mod normals;
pub mod prepared;
pub mod ransac;
pub mod refine;
pub mod refiner;
pub mod registrar;
pub mod registration;
pub mod sc2;
pub mod thinning;
pub mod transform;
pub mod triplets;

#[cfg(test)]
mod testing;

pub use cloud::{length, PointCloud};
pub use error::{GeomError, Result};
pub use kabsch::kabsch;
pub use knn::{knn_graph, KnnIndex, Neighbourhoods};
pub use metrics::{MetricsSummary, PairMetrics};
pub use prepared::Prepared;
pub use registrar::{DynRegistrar, MethodId, Registrar, Registration};
pub use registration::Fit;
pub use transform::RigidTransform;

pub use nalgebra::{Matrix3, Matrix4, Point3, Vector3};
