#![doc = include_str!("../README.md")]
//!
//! # Layering
//!
//! Layering rule: rgm-data builds on rgm-geom only (point clouds, rigid transforms, kNN) and
//! knows nothing of tensors, networks or matching. It needs no BLAS.

pub mod correspondence;
pub mod durable;
pub mod error;
pub mod io;
pub mod memory;
pub mod modelnet;
pub mod multiway;
pub mod pack;
pub mod pair_list;
pub mod pairs;
pub mod scans;
pub mod scenes;

pub use correspondence::Correspondence;
pub use error::{DataError, Result};
pub use io::{
    read_point_cloud, read_point_cloud_warned, read_regular_file, write_point_cloud, Warning,
};
pub use modelnet::{ModelNet40, Shape, Split};
pub use pairs::{Pair, PairConfig, PairGenerator, Setting};
pub use scans::{ScanFolder, ScanPair, ScanPairConfig};
pub use scenes::{SceneFolder, ScenePair, Turn};
