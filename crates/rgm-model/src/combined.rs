//! `rgm register`'s default: RGM and FGR on the same pair, each refined, and the result that
//! scores better by a measure that needs no ground truth.
//!
//! The two fail on different pairs: RGM's network is robust to partial overlap but reads
//! rotationally symmetric shapes (bottles, vases, bowls) ambiguously; FGR's FPFH features pin
//! those down on full clouds but fail wildly on many partial ones. The score that picks between
//! them, [`SCORE_DISTANCE`]'s two-way overlap, was chosen on validation pairs
//! (`docs/training/README.md`, session 6: `cargo run --release -p rgm-benches --example
//! default_study`).
//!
//! Both run in one frame: the pair centred and scaled as the network expects
//! ([`Normalisation`]) and thinned to the training clouds' density ([`thinned`]), so that FGR's
//! radii and the refinement's distances, set for unit-sphere shapes, fit inputs of any size and
//! density. A pair denser than the training clouds can be thinned many ways, none of them the
//! sampling the benchmark's pairs share; both methods run on two thinnings of it
//! ([`Thinning`]), four candidates scored alike on the dense clouds — unless the two agree on
//! the first thinning ([`agree`]), which leaves nothing for the second to fix. The transform is
//! reported for the clouds as given.

use std::borrow::Cow;

use rgm_geom::fgr::{self, FgrConfig};
use rgm_geom::refine::{self, RefineConfig, ResolutionConfig};
use rgm_geom::registration::{score, Score};
use rgm_geom::{KnnIndex, PointCloud, RegistrationResult, RigidTransform};

use crate::error::MethodError;
use crate::pipeline::{near, Normalisation, RgmRegistrar, DENSITY_POINTS};

/// Distance (unit-sphere units) within which a moved point counts as overlapping the other
/// cloud in the score.
pub const SCORE_DISTANCE: f64 = 0.02;

/// The least [`overlap_score`] of a credible result: below it, fewer than one point in twenty of
/// each cloud lies on the other after the best transform, and the pair is reported as not
/// registered ([`CombinedRegistrar::doubt`]) rather than with a transform nothing supports.
pub const MIN_OVERLAP: f64 = 0.1;

/// One candidate's outcome on the last pair.
#[derive(Clone, Debug, PartialEq)]
pub struct Candidate {
    /// The method that made it (`rgm+icp`, `fgr+icp`; without `+icp` when unrefined; with
    /// `/cells` when it ran on the [`Thinning::Cells`] version of a dense pair).
    pub method: &'static str,
    /// Its transform, in the caller's frame.
    pub t_target_source: RigidTransform,
    /// Its score ([`overlap_score`]); the highest wins. `None` when the method failed.
    pub score: Option<f64>,
    /// Why the method failed, if it did.
    pub failure: Option<String>,
}

/// RGM and FGR side by side.
#[derive(Clone, Debug)]
pub struct CombinedRegistrar {
    /// RGM with its own refinement off: the candidates are refined alike, here.
    pub rgm: Box<RgmRegistrar>,
    /// FGR's settings (unit-sphere radii: it runs in the network's frame).
    pub fgr: FgrConfig,
    /// The refinement of both candidates; `None`: their transforms as found.
    pub refine: Option<RefineConfig>,
    candidates: Vec<Candidate>, // of the last registration: RGM's, FGR's, per thinning
    chosen: Option<usize>,      // the winner among them
    scoring_distance: f64,      // of the last result's fitness, in the caller's units
    pairs: Vec<(usize, usize)>, // behind the last result's fitness (source, target)
}

/// Voxel of the first thinning step of a cloud denser than [`DENSITY_POINTS`], in unit-sphere
/// units (the training clouds' median nearest-neighbour distance is 0.011–0.042).
pub const DENSITY_VOXEL: f64 = 0.035;

/// How a cloud denser than [`DENSITY_POINTS`] (in the unit-sphere frame) is thinned to
/// [`DENSITY_POINTS`] points for the candidates; a cloud of no more points is used as it is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Thinning {
    /// Averaged over voxels of [`DENSITY_VOXEL`] (merging duplicates and averaging their
    /// noise), then thinned by farthest-point sampling. On 100 partial validation pairs with
    /// each cloud made of 20,000 points (every point repeated, σ 0.005), farthest-point
    /// sampling alone registered 90 %, with the voxels first 94 %, the pairs as they are 96 %
    /// (`default_study --study robustness`).
    Voxels,
    /// Farthest-point seeds, each replaced by the mean of its Voronoi cell in the dense cloud
    /// ([`PointCloud::cell_means`]): as good as [`Thinning::Voxels`] alone on 200 validation
    /// pairs (`docs/training/default-study/thinning-200-validation.md`), and wrong on other
    /// pairs.
    Cells,
}

/// `cloud` as the candidates see it, thinned `how` if it has more than [`DENSITY_POINTS`].
pub fn thinned(cloud: &PointCloud, how: Thinning) -> Cow<'_, PointCloud> {
    if cloud.len() <= DENSITY_POINTS {
        return Cow::Borrowed(cloud);
    }
    Cow::Owned(match how {
        Thinning::Voxels => {
            let averaged = cloud.voxel_downsampled(DENSITY_VOXEL);
            averaged.select(&averaged.farthest_point_indices(DENSITY_POINTS))
        }
        Thinning::Cells => {
            let seeds = cloud.select(&cloud.farthest_point_indices(DENSITY_POINTS));
            cloud.cell_means(&seeds.points)
        }
    })
}

/// Two transforms (in the unit-sphere frame) within [`AGREEMENT`] of each other: rotations
/// less than its degrees apart, and moving the frame's centre to points less than its
/// distance apart.
pub fn agree(a: &RigidTransform, b: &RigidTransform) -> bool {
    let (degrees, distance) = AGREEMENT;
    a.inverse().compose(b).rotation_angle_deg() < degrees
        && (a.translation - b.translation).norm() < distance
}

/// How close RGM's and FGR's transforms on a dense pair's first thinning must be for the
/// second thinning to be skipped: (degrees, unit-sphere distance).
pub const AGREEMENT: (f64, f64) = (1.0, 0.02);

/// Share of the points of each cloud that the transform brings within [`SCORE_DISTANCE`] of
/// the other cloud, source → target plus target → source (0 to 2). Counting both ways rewards
/// an overlap that both clouds agree on, where a one-way fitness is fooled by a small cloud
/// lying anywhere on a large one.
pub fn overlap_score(
    source: (&PointCloud, &KnnIndex),
    target: (&PointCloud, &KnnIndex),
    transform: &RigidTransform,
) -> f64 {
    let there = score(&source.0.points, target.1, transform, SCORE_DISTANCE, None);
    let back = score(
        &target.0.points,
        source.1,
        &transform.inverse(),
        SCORE_DISTANCE,
        None,
    );
    there.fitness + back.fitness
}

impl CombinedRegistrar {
    /// RGM (`rgm`'s own refinement is turned off) and FGR with `fgr`, both refined with
    /// `refine` when given.
    pub fn new(mut rgm: RgmRegistrar, fgr: FgrConfig, refine: Option<RefineConfig>) -> Self {
        rgm.config.refine = None;
        Self {
            rgm: Box::new(rgm),
            fgr,
            refine,
            candidates: Vec::new(),
            chosen: None,
            scoring_distance: SCORE_DISTANCE,
            pairs: Vec::new(),
        }
    }

    /// The candidates of the last registration, RGM's first; empty before any.
    pub fn candidates(&self) -> &[Candidate] {
        &self.candidates
    }

    /// The name of a candidate: `base`, `+icp` when refined, `/cells` on that thinning.
    fn candidate_name(&self, rgm: bool, how: Thinning) -> &'static str {
        match (rgm, self.refine.is_some(), how) {
            (true, true, Thinning::Voxels) => "rgm+icp",
            (true, false, Thinning::Voxels) => "rgm",
            (false, true, Thinning::Voxels) => "fgr+icp",
            (false, false, Thinning::Voxels) => "fgr",
            (true, true, Thinning::Cells) => "rgm+icp/cells",
            (true, false, Thinning::Cells) => "rgm/cells",
            (false, true, Thinning::Cells) => "fgr+icp/cells",
            (false, false, Thinning::Cells) => "fgr/cells",
        }
    }

    /// The best-scoring candidate's transform (when the candidates are refined and the pair
    /// was thinned, refined further by [`refine::refine_at_resolution`] on the clouds as
    /// given), scored as Open3D scores ICP on the clouds as
    /// given (the refinement's finest distance, or [`SCORE_DISTANCE`], times the frame's
    /// scale); an error only when both candidates failed (naming both causes).
    pub fn register(
        &mut self,
        source: &PointCloud,
        target: &PointCloud,
    ) -> Result<RegistrationResult, MethodError> {
        self.candidates.clear();
        self.chosen = None;
        self.pairs.clear();
        let frame = Normalisation::of_pair(source, target);
        // (N, 3) and (M, 3) in the network's frame, at the caller's density, far outliers left
        // out: what every candidate runs on and is scored on.
        let fs = frame.source(&source.select(&near(source)));
        let ft = frame.target(&target.select(&near(target)));
        let (fsi, fti) = (KnnIndex::new(&fs.points), KnnIndex::new(&ft.points));
        let dense = fs.len().max(ft.len()) > DENSITY_POINTS;
        let thinnings: &[Thinning] = if dense {
            &[Thinning::Voxels, Thinning::Cells]
        } else {
            &[Thinning::Voxels] // leaves the clouds as they are
        };
        let mut best: Option<(f64, RigidTransform, usize)> = None; // score, transform, iterations
        for &how in thinnings {
            let (s, t) = (thinned(&fs, how), thinned(&ft, how));
            let mut found = Vec::with_capacity(2); // this thinning's transforms, in the frame
            let starts = [
                self.rgm.register(&s, &t).map(|r| r.t_target_source),
                fgr::register(&s, &t, &self.fgr)
                    .map(|r| r.t_target_source)
                    .map_err(MethodError::from),
            ];
            for (k, start) in starts.into_iter().enumerate() {
                let method = self.candidate_name(k == 0, how);
                let outcome = start.and_then(|start| match &self.refine {
                    Some(config) => {
                        let refined = refine::refine(&s, &t, &start, config)?;
                        Ok((refined.t_target_source, refined.iterations))
                    }
                    None => Ok((start, 0)),
                });
                match outcome {
                    Ok((transform, iterations)) => {
                        found.push(transform);
                        let value = overlap_score((&fs, &fsi), (&ft, &fti), &transform);
                        // Ties go to the earlier candidate: RGM, and the first thinning.
                        if best.is_none_or(|(b, _, _)| value > b) {
                            best = Some((value, transform, iterations));
                            self.chosen = Some(self.candidates.len());
                        }
                        self.candidates.push(Candidate {
                            method,
                            t_target_source: frame.undo(&transform),
                            score: Some(value),
                            failure: None,
                        });
                    }
                    Err(err) => self.candidates.push(Candidate {
                        method,
                        t_target_source: RigidTransform::identity(),
                        score: None,
                        failure: Some(err.to_string()),
                    }),
                }
            }
            // Two independent methods landing on one transform leave nothing for a second
            // thinning to fix: a dense pair is thinned the second way only when they disagree.
            if let [a, b] = found.as_slice() {
                if agree(a, b) {
                    break;
                }
            }
        }
        let Some((_, mut transform, mut iterations)) = best else {
            let why: Vec<String> = self
                .candidates
                .iter()
                .map(|c| format!("{}: {}", c.method, c.failure.as_deref().unwrap_or("?")))
                .collect();
            return Err(MethodError::AllCandidatesFailed(why.join("; ")));
        };
        if let (Some(config), true) = (&self.refine, dense) {
            // The candidates were refined on the thinned clouds; the winner is refined further
            // on the clouds as given, at their own point spacing. Clouds that were not thinned
            // had that refinement already (their noise, as ModelNet40's, may exceed their
            // spacing: stages finer than the coarse ones would fit noise).
            let (fine, more) = refine::refine_at_resolution(
                &fs,
                &ft,
                &fti,
                &transform,
                config.finest_distance(),
                &ResolutionConfig::default(),
            )?;
            transform = fine;
            iterations += more;
        }
        // Scored in the network's frame (squared distances at the caller's scale may overflow),
        // on every point given.
        let distance = self
            .refine
            .as_ref()
            .map_or(SCORE_DISTANCE, RefineConfig::finest_distance);
        self.scoring_distance = distance * frame.scale;
        let scored = score(
            &frame.source(source).points,
            &KnnIndex::new(&frame.target(target).points),
            &transform,
            distance,
            Some(&mut self.pairs),
        );
        let scored = Score {
            inlier_rmse: scored.inlier_rmse * frame.scale,
            ..scored
        };
        Ok(RegistrationResult::scored(
            frame.undo(&transform),
            iterations,
            true,
            scored,
        ))
    }

    /// The (source index, target index) pairs behind the last result's fitness: each source
    /// point moved within the scoring distance of its nearest target point.
    pub fn correspondences(&self) -> &[(usize, usize)] {
        &self.pairs
    }

    /// The distance at which the last result's fitness and inlier RMSE were scored, in the
    /// caller's units.
    pub fn scoring_distance(&self) -> f64 {
        self.scoring_distance
    }

    /// Why the last result is not credible, if it is not: its overlap score is below
    /// [`MIN_OVERLAP`].
    pub fn doubt(&self) -> Option<String> {
        let best = &self.candidates[self.chosen?];
        let score = best.score?;
        (score < MIN_OVERLAP).then(|| {
            format!(
                "the best candidate, {}, overlaps too little (score {score:.3} < {MIN_OVERLAP}): \
                 the clouds may not overlap, or every method failed on them",
                best.method
            )
        })
    }

    /// The index in [`CombinedRegistrar::candidates`] of the last registration's winner.
    pub fn chosen(&self) -> Option<usize> {
        self.chosen
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rgm_geom::{Point3, Vector3};

    #[test]
    fn transforms_agree_within_a_degree_and_a_fiftieth() {
        let turn = |deg: f64, shift: f64| {
            RigidTransform::new(
                rgm_geom::euler::rotation_xyz_intrinsic(0.0, 0.0, deg.to_radians()),
                Vector3::new(shift, 0.0, 0.0),
            )
        };
        let a = turn(10.0, 0.1);
        assert!(agree(&a, &turn(10.9, 0.1)));
        assert!(agree(&a, &turn(10.0, 0.119)));
        assert!(!agree(&a, &turn(11.1, 0.1)));
        assert!(!agree(&a, &turn(10.0, 0.121)));
    }

    #[test]
    fn overlap_counts_both_ways() {
        // 10 points 0.1 apart on a line, and its first 4 points.
        let line = PointCloud::new(
            (0..10)
                .map(|i| Point3::new(0.1 * i as f64, 0.0, 0.0))
                .collect(),
        );
        let part = PointCloud::new(line.points[..4].to_vec());
        let (li, pi) = (KnnIndex::new(&line.points), KnnIndex::new(&part.points));
        let identity = RigidTransform::identity();
        assert_eq!(overlap_score((&line, &li), (&line, &li), &identity), 2.0);
        // The part lies on the line (1.0), which it covers for 4 of 10 points (0.4).
        assert!((overlap_score((&part, &pi), (&line, &li), &identity) - 1.4).abs() < 1e-12);
        // Shifted by 0.05 every point is 0.05 from the other cloud: beyond 0.02.
        let shifted =
            RigidTransform::new(rgm_geom::Matrix3::identity(), Vector3::new(0.0, 0.05, 0.0));
        assert_eq!(overlap_score((&line, &li), (&line, &li), &shifted), 0.0);
    }
}
