#![doc = include_str!("../README.md")]
//!
//! # Layering and conventions
//!
//! Layering rule: rgm-geom depends on no other rgm crate (it is the bottom layer, with rgm-nn)
//! and knows nothing about registration methods, tensors, gradients or networks: the methods and
//! their composition are rgm-registration's, on top of it. Everything is f64; callers convert at
//! their boundary.
//!
//! Conventions: a transform `t_target_source` maps source coordinates into the target frame,
//! `y = R x + t`.

// `!(x > 0.0)` is used on purpose: it also rejects NaN, which `x <= 0.0` would let through.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod cloud;
pub mod error;
pub mod euler;
pub mod fpfh;
pub mod frame;
pub mod kabsch;
pub mod knn;
pub mod lockstep;
pub mod metrics;
pub mod normals;
pub mod transform;

#[cfg(any(test, feature = "testing"))]
pub mod testing;

pub use cloud::{length, PointCloud, Strays};
pub use error::{GeomError, Result};
pub use kabsch::kabsch;
pub use knn::{knn_graph, nearest_among, KnnIndex, Neighbourhoods};
pub use metrics::{MetricsSummary, PairMetrics};
pub use transform::RigidTransform;

pub use nalgebra::{Matrix3, Matrix4, Point3, Vector3};
