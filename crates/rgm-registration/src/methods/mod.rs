//! The registration methods, each a [`crate::Registrar`]: the global estimators (FGR on FPFH
//! features; RANSAC and SC² on the FPFH matches of a scene-scale pair, which share
//! `feature_matches`; a whole search of a few markers' triplets) and the local ones (Open3D's
//! point-to-point ICP, and the refinement after a global method: trimmed point-to-plane ICP,
//! coarse to fine).

pub mod feature_matches;
pub mod fgr;
pub mod icp;
pub mod ransac;
pub mod refine;
pub mod sc2;
pub mod triplets;
