//! What the global estimators on scene-scale pairs ([`crate::methods::ransac`], [`crate::methods::sc2`]) share: the
//! pair's FPFH matches at its own scale, and the last step from an estimate to a [`Fit`].
//!
//! 1. Thinning: both clouds voxel-averaged with one voxel, the finest that leaves at most
//!    [`MatchingConfig::max_points`] in each (features of the two clouds compare only at one
//!    density); the spacing is the thinned pair's median nearest-neighbour distance.
//! 2. Features: PCA normals and FPFH ([`rgm_geom::fpfh::features`]) at radii in spacings.
//! 3. Matching: each source point's nearest target point in feature space
//!    ([`crate::methods::fgr::nearest_matches`]), or only the mutual ones ([`MatchingConfig::mutual`]).
//! 4. The estimator's transform, refined point-to-plane on the thinned pair
//!    ([`MatchingConfig::refinement`]) and scored there at the inlier distance.

use std::time::Instant;

use nalgebra::Point3;
use rgm_geom::fpfh::{features, FpfhConfig};
use rgm_geom::normals::NormalsConfig;
use rgm_geom::{kabsch, GeomError, PointCloud, Result, RigidTransform};

use crate::fit::{score, Fit};
use crate::methods::fgr::{mutual_matches, nearest_matches};
use crate::methods::icp::check_clouds;
use crate::methods::refine::{median_spacing, refine_at_resolution, ResolutionConfig};
use crate::prepared::{Prepared, SPACING_SAMPLE};
use crate::registrar::{MethodId, Registration};
use crate::thinning::STRAYS;

/// Steps 1–4 of the module. Lengths are in point spacings of the thinned pair. The defaults are
/// Open3D's tutorial lengths (normals at 2 voxels, FPFH at 5, inliers within 1.5) with its
/// voxel read as 5/3 spacings: voxel-averaging leaves points about 0.6 of a voxel apart, so
/// these are Open3D's radii at the voxel that thins the pair as much.
#[derive(Clone, Debug, PartialEq)]
pub struct MatchingConfig {
    /// Each cloud is thinned to at most this many points (default 5,000).
    pub max_points: usize,
    /// Normals' neighbourhood radius, in spacings (default 10/3), at most 30 neighbours.
    pub normal_spacings: f64,
    /// FPFH's neighbourhood radius, in spacings (default 25/3), at most 100 neighbours.
    pub feature_spacings: f64,
    /// A match is an inlier of a transform that brings it within this many spacings
    /// (default 2.5).
    pub inlier_spacings: f64,
    /// Match only mutual nearest features (default false: each source point's nearest target
    /// feature, as Open3D's tutorial; the mutual filter leaves too few right matches on rooms).
    pub mutual: bool,
    /// The final point-to-plane stages on the thinned pair, from the estimate
    /// ([`refine_at_resolution`], in the thinned target's spacings; default 4, 2).
    pub refinement: ResolutionConfig,
}

impl Default for MatchingConfig {
    fn default() -> Self {
        Self {
            max_points: 5000,
            normal_spacings: 10.0 / 3.0,
            feature_spacings: 25.0 / 3.0,
            inlier_spacings: 2.5,
            mutual: false,
            refinement: ResolutionConfig::default(),
        }
    }
}

impl MatchingConfig {
    /// An estimator's [`Registration`] of what `estimate` fits: timed, with no correspondences
    /// of its own (the caller's scoring finds them).
    pub(crate) fn registration<E: From<GeomError>>(
        estimate: impl FnOnce() -> Result<Fit>,
    ) -> std::result::Result<Registration, E> {
        let start = Instant::now();
        let result = estimate()?;
        Ok(Registration::single(result, Vec::new(), start))
    }

    /// The name of an estimator on these matches: `base+refine`, its last step being
    /// point-to-plane ICP ([`MatchingConfig::refinement`]), unless that has no stage.
    pub fn method_id(&self, base: &'static str) -> MethodId {
        MethodId {
            base,
            refiner: (!self.refinement.spacings.is_empty()).then_some(crate::methods::refine::NAME),
        }
    }
}

/// A pair's feature matches, as the estimators see them.
pub struct Matched<'a> {
    /// The thinned pair (or the pair as given, when small enough).
    pub source: &'a Prepared<'a>,
    pub target: &'a Prepared<'a>,
    /// Match `c` pairs `from[c]` (a source point) with `to[c]` (a target point).
    pub from: Vec<Point3<f64>>, // (C,)
    pub to: Vec<Point3<f64>>, // (C,)
    /// The inlier distance.
    pub distance: f64,
}

impl Matched<'_> {
    /// The share of the thinned source that `t` brings within the inlier distance of the
    /// thinned target: what tells a right pose from a wrong one that many matches agree with
    /// (on a scene the right matches are few, and a wrong pose that look-alike floor agrees
    /// with lays little of one room on the other).
    pub fn fitness(&self, t: &RigidTransform) -> f64 {
        score(
            &self.source.points,
            self.target.index(),
            t,
            self.distance,
            None,
        )
        .fitness
    }
}

/// What an estimator found: the transform, the matches within the inlier distance of it, and
/// the hypotheses it weighed.
#[derive(Clone, Debug, PartialEq)]
pub struct Consensus {
    pub t_target_source: RigidTransform,
    /// Indices into the matches given.
    pub inliers: Vec<usize>,
    pub hypotheses: usize,
}

/// Steps 1–3 on the pair, `estimate` on the matches, then step 4. `op` names the method in
/// errors.
pub(crate) fn register_matched(
    op: &'static str,
    source: &Prepared,
    target: &Prepared,
    config: &MatchingConfig,
    estimate: impl FnOnce(&Matched) -> Result<Consensus>,
) -> Result<Fit> {
    check_clouds(op, source, target)?;
    let thinned = thinned_pair(source, target, config.max_points)
        .map(|(s, t)| (Prepared::new(s), Prepared::new(t)));
    let (small_source, small_target) = match &thinned {
        Some((s, t)) => (s, t),
        None => (source, target),
    };
    let (source_index, target_index) =
        rayon::join(|| small_source.index(), || small_target.index());
    let target_spacing = median_spacing(&small_target.points, target_index, SPACING_SAMPLE);
    let spacing =
        median_spacing(&small_source.points, source_index, SPACING_SAMPLE).max(target_spacing);
    if !(spacing > 0.0) {
        return Err(GeomError::Degenerate {
            op,
            why: "the clouds' points coincide: no spacing to measure lengths by".into(),
        });
    }
    let normals = NormalsConfig {
        radius: config.normal_spacings * spacing,
        max_nn: 30,
    };
    let fpfh = FpfhConfig {
        radius: config.feature_spacings * spacing,
        max_nn: 100,
    };
    let (source_features, target_features) = rayon::join(
        || features(&small_source.points, source_index, &normals, &fpfh), // (N', 33)
        || features(&small_target.points, target_index, &normals, &fpfh), // (M', 33)
    );
    let matches = if config.mutual {
        mutual_matches(&source_features, &target_features)
    } else {
        nearest_matches(&source_features, &target_features)
    };
    if matches.len() < 3 {
        return Err(GeomError::TooFewPoints {
            op,
            needed: 3,
            got: matches.len(),
        });
    }
    let matched = Matched {
        source: small_source,
        target: small_target,
        from: matches
            .iter()
            .map(|&(i, _)| small_source.points[i])
            .collect(),
        to: matches
            .iter()
            .map(|&(_, j)| small_target.points[j])
            .collect(),
        distance: config.inlier_spacings * spacing,
    };
    let found = estimate(&matched)?;
    let (transform, iterations) = refine_at_resolution(
        small_source,
        small_target,
        target_index,
        target_spacing,
        &found.t_target_source,
        f64::INFINITY,
        &config.refinement,
    )?;
    let scored = score(
        &small_source.points,
        target_index,
        &transform,
        matched.distance,
        None,
    );
    Ok(Fit::scored(
        transform,
        found.hypotheses + iterations,
        true,
        scored,
    ))
}

/// `transform` refitted (Kabsch) on the matches within √`squared` of it, at most `refits`
/// times, while they do not shrink.
pub(crate) fn refitted(
    from: &[Point3<f64>],
    to: &[Point3<f64>],
    mut transform: RigidTransform,
    squared: f64,
    refits: usize,
    hypotheses: usize,
) -> Consensus {
    let mut inliers: Vec<usize> = inliers_of(from, to, &transform, squared).collect();
    for _ in 0..refits {
        let a: Vec<Point3<f64>> = inliers.iter().map(|&c| from[c]).collect(); // (I, 3)
        let b: Vec<Point3<f64>> = inliers.iter().map(|&c| to[c]).collect(); // (I, 3)
        let Ok(refit) = kabsch(&a, &b, &vec![1.0; a.len()]) else {
            break;
        };
        let next: Vec<usize> = inliers_of(from, to, &refit, squared).collect();
        if next.len() < inliers.len() {
            break;
        }
        transform = refit;
        if next == inliers {
            break;
        }
        inliers = next;
    }
    Consensus {
        t_target_source: transform,
        inliers,
        hypotheses,
    }
}

/// The indices of the matches that `t` brings within √`squared` of their partners.
pub(crate) fn inliers_of<'a>(
    from: &'a [Point3<f64>],
    to: &'a [Point3<f64>],
    t: &'a RigidTransform,
    squared: f64,
) -> impl Iterator<Item = usize> + 'a {
    (0..from.len()).filter(move |&c| (t.apply(&from[c]) - to[c]).norm_squared() < squared)
}

/// Both clouds voxel-averaged with one voxel, the finest of a ladder that leaves at most
/// `max_points` in each, without their strays ([`STRAYS`]: a scanner's spurious returns would
/// take cubes, and features, of their own); `None` for a pair already that small.
fn thinned_pair(
    source: &PointCloud,
    target: &PointCloud,
    max_points: usize,
) -> Option<(PointCloud, PointCloud)> {
    let max_points = max_points.max(8);
    if source.len() <= max_points && target.len() <= max_points {
        return None;
    }
    let (lo, hi) = rgm_geom::cloud::bounds(source.points.iter().chain(&target.points).copied());
    let extent = (hi - lo).max();
    if !(extent > 0.0) {
        return Some((
            PointCloud::new(vec![source.points[0]]),
            PointCloud::new(vec![target.points[0]]),
        ));
    }
    // A surface of side `extent` fills about (extent / voxel)² cubes: start finer than that and
    // grow the voxel by the square root of how many times too many points are left.
    let mut voxel = extent / (max_points as f64).sqrt() / 1.25;
    loop {
        let (s, t) = rayon::join(
            || source.voxel_downsampled_without_strays(voxel, &STRAYS),
            || target.voxel_downsampled_without_strays(voxel, &STRAYS),
        );
        let most = s.len().max(t.len());
        if most <= max_points {
            return Some((s, t));
        }
        voxel *= (most as f64 / max_points as f64).sqrt().max(1.05);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::square_with_strays;

    #[test]
    fn the_pair_is_thinned_without_the_strays_scattered_through_its_box() {
        // A square of 200 × 200 points in z = 0, and 5 % as many strays through its box.
        let cloud = square_with_strays(1.0, 200, 2000, 5);
        let (source, target) = thinned_pair(&cloud, &cloud, 2000).unwrap();
        assert_eq!(source, target);
        assert!(
            source.len() > 1000 && source.len() <= 2000,
            "{}",
            source.len()
        );
        // Only strays beside the square's cubes may stay, within a few voxels of it.
        let off = source.points.iter().filter(|p| p.z.abs() > 0.1).count();
        assert_eq!(off, 0);
    }
}
