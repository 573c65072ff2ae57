//! Local methods that improve a rough transform: what [`crate::compose::Refined`] runs after
//! a global method, and [`crate::compose::AtResolution`] after a composite on a dense pair.
//!
//! A refiner is a value of one trait, so that a new refinement is one type and one line where
//! methods are composed (`Refined::new(FgrConfig::default(), MyRefiner)`), and its name is
//! what the composed method's name ends with (`fgr+refine`).

use std::time::Instant;

use rgm_geom::{Result, RigidTransform};

use crate::fit::{score, Fit};
use crate::methods::icp::{self, IcpConfig};
use crate::methods::refine::{self, RefineConfig, ResolutionConfig};
use crate::registrar::Registration;
use crate::Prepared;

/// A local method: from a transform near the truth to a better one.
pub trait Refiner: Send + Sync {
    /// What a method refined by it is called after its `+` (`refine` in `fgr+refine`).
    fn name(&self) -> &'static str;

    /// `initial` (a `t_target_source`) improved so that `source` lies on `target`, with the
    /// refinement's own iterations, inlier statistics and correspondences (the pairs behind its
    /// inlier count); `candidates` empty. The clouds' trees and normals are the stages' before
    /// it, and stay for the stages after it.
    fn refine(
        &self,
        source: &Prepared,
        target: &Prepared,
        initial: &RigidTransform,
    ) -> Result<Registration>;
}

impl<F: Refiner + ?Sized> Refiner for &F {
    fn name(&self) -> &'static str {
        (**self).name()
    }

    fn refine(
        &self,
        source: &Prepared,
        target: &Prepared,
        initial: &RigidTransform,
    ) -> Result<Registration> {
        (**self).refine(source, target, initial)
    }
}

/// Trimmed point-to-plane ICP, coarse to fine ([`refine::refine`]), scored at its finest
/// distance: the refinement of every `+refine` method.
impl Refiner for RefineConfig {
    fn name(&self) -> &'static str {
        refine::NAME
    }

    fn refine(
        &self,
        source: &Prepared,
        target: &Prepared,
        initial: &RigidTransform,
    ) -> Result<Registration> {
        let start = Instant::now();
        let result = refine::refine_prepared(source, target, initial, self)?;
        Ok(Registration::scored_within(
            result,
            source,
            target,
            self.finest_distance(),
            start,
        ))
    }
}

/// What [`IcpConfig`] is called as a refiner (`fgr+p2p`): point-to-point ICP as Open3D runs
/// it, from the transform it is given rather than its own `initial`.
pub const POINT_TO_POINT: &str = "p2p";

impl Refiner for IcpConfig {
    fn name(&self) -> &'static str {
        POINT_TO_POINT
    }

    fn refine(
        &self,
        source: &Prepared,
        target: &Prepared,
        initial: &RigidTransform,
    ) -> Result<Registration> {
        let start = Instant::now();
        let config = IcpConfig {
            initial: *initial,
            ..*self
        };
        let result = icp::register_prepared(source, target, &config)?;
        Ok(Registration::scored_within(
            result,
            source,
            target,
            self.max_correspondence_distance,
            start,
        ))
    }
}

/// Point-to-plane stages at the clouds' own point spacing ([`refine::refine_at_resolution`]),
/// finer than `coarser_than` (the finest distance a coarser refinement already ran at), scored
/// at `scoring_distance`. It does not tell convergence: its result says `converged`. Its results
/// are kept with the clouds ([`Prepared::refinement`]): a transform it reached is not refined
/// again in the same registration.
#[derive(Clone, Debug, PartialEq)]
pub struct AtSpacing {
    pub coarser_than: f64,
    pub scoring_distance: f64,
    pub config: ResolutionConfig,
}

/// What [`AtSpacing`] is called.
pub const AT_SPACING: &str = "spacing";

impl Refiner for AtSpacing {
    fn name(&self) -> &'static str {
        AT_SPACING
    }

    fn refine(
        &self,
        source: &Prepared,
        target: &Prepared,
        initial: &RigidTransform,
    ) -> Result<Registration> {
        let start = Instant::now();
        let (result, correspondences) =
            source.refinement(target, initial, self.scoring_distance, || {
                let index = target.index();
                let (transform, iterations) = refine::refine_at_resolution(
                    source,
                    target,
                    index,
                    target.spacings().0,
                    initial,
                    self.coarser_than,
                    &self.config,
                )?;
                let mut correspondences = Vec::new();
                let scored = score(
                    &source.points,
                    index,
                    &transform,
                    self.scoring_distance,
                    Some(&mut correspondences),
                );
                let result = Fit::scored(transform, iterations, true, scored);
                Ok::<_, rgm_geom::GeomError>((result, correspondences))
            })?;
        Ok(Registration::single(result, correspondences, start))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rgm_geom::testing::airplane;
    use rgm_geom::Vector3;

    /// Every refiner brings the airplane back from 6° and 0.03 off, in both directions, and
    /// its correspondences are the pairs behind its inlier count.
    #[test]
    fn every_refiner_recovers_a_small_offset_both_ways() {
        let shape = airplane();
        let pose = RigidTransform::new(
            rgm_geom::euler::rotation_xyz_intrinsic(0.02, -0.01, 4f64.to_radians()),
            Vector3::new(0.01, 0.0, -0.01),
        );
        let moved = shape.transformed(&pose);
        let off = RigidTransform::new(
            rgm_geom::euler::rotation_xyz_intrinsic(0.0, 6f64.to_radians(), 0.0),
            Vector3::new(0.03, 0.0, 0.0),
        );
        let refiners: [(&dyn Refiner, f64); 2] = [
            (&RefineConfig::default(), 0.3),
            (&IcpConfig::default(), 1.0),
        ];
        for (refiner, within_deg) in refiners {
            for (source, target, truth) in
                [(&shape, &moved, pose), (&moved, &shape, pose.inverse())]
            {
                let start = truth.compose(&off);
                let (source, target) = (Prepared::new(source), Prepared::new(target));
                let found = refiner.refine(&source, &target, &start).unwrap();
                let t = found.result.t_target_source;
                let angle = t.inverse().compose(&truth).rotation_angle_deg();
                let name = refiner.name();
                assert!(angle < within_deg, "{name}: {angle}° off");
                assert!((t.translation - truth.translation).norm() < 0.01, "{name}");
                assert_eq!(
                    found.correspondences.len(),
                    found.result.inlier_count,
                    "{name}"
                );
                assert!(found.result.inlier_count > 900, "{name}");
            }
        }
    }

    #[test]
    fn at_spacing_leaves_a_sparse_pair_as_it_was() {
        // ModelNet40's spacing (≈ 0.05) times 4 and 2 is no finer than the coarse refinement's
        // 0.03: no stage runs, and the transform comes back unchanged.
        let shape = airplane();
        let start = RigidTransform::new(
            rgm_geom::euler::rotation_xyz_intrinsic(0.0, 0.0, 0.1),
            Vector3::new(0.0, 0.02, 0.0),
        );
        let refiner = AtSpacing {
            coarser_than: 0.03,
            scoring_distance: 0.03,
            config: ResolutionConfig::default(),
        };
        let shape = Prepared::new(&shape);
        let found = refiner.refine(&shape, &shape, &start).unwrap();
        assert_eq!(found.result.t_target_source, start);
        assert_eq!(found.result.iterations, 0);
    }
}
