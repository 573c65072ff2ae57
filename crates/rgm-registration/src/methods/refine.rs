//! Local refinement of a rough transform: trimmed point-to-plane ICP, coarse to fine.
//!
//! What a global method (FGR, the RGM network) hands over is usually within 5–20° of the truth
//! on partial scans. Open3D-style point-to-point ICP ([`crate::methods::icp`]) converges slowly from there
//! and is pulled off by the points outside the overlap. This refinement differs in three ways,
//! each shown to help on ModelNet40 partial pairs (docs/training/README.md, "a refinement that
//! suits partial scans"):
//! - **point-to-plane**: each moved source point `p` paired with its nearest target point `q`
//!   (normal `n`) contributes the residual `(q − p)·n`; the linearised step (small rotation
//!   `ω`, translation `τ`) solves the 6×6 normal equations of `Σ ((p × n)·ω + n·τ − (q − p)·n)²`;
//! - **trimmed**: only the closest `trim` fraction of the pairs found count, so points of the
//!   part one cloud lacks do not drag the fit;
//! - **coarse to fine**: stages with shrinking correspondence distances (0.2, 0.1, 0.05 for
//!   shapes in the unit sphere), a few iterations each.
//!
//! It ends with point-to-point stages ([`crate::methods::icp`], untrimmed, at 0.05 then 0.03): once the
//! clouds lie on each other, the nearest points are mostly the same surface points, and fitting
//! them point to point pins down the slide along the surface that point-to-plane leaves loose
//! (measured in docs/training/README.md, "a refinement that suits partial scans").
//!
//! Normals of the target are estimated once by PCA ([`rgm_geom::normals`]).
//!
//! The file is long because its unit tests sit beside the code they check (as everywhere in
//! rgm); the code itself is one job, kept in one place.

use std::borrow::Cow;
use std::cell::RefCell;
use std::ops::Range;

use nalgebra::{Matrix6, Point3, Rotation3, Vector3, Vector6};
use rayon::prelude::*;
use rgm_geom::normals::{normal_from_around, NormalsConfig, WithinConfig};
use rgm_geom::{nearest_among, GeomError, KnnIndex, PointCloud, Result, RigidTransform};

use crate::fit::{nearest_each_by, score, search_from, Fit};
use crate::methods::icp::{self, check_clouds, IcpConfig};
use crate::Prepared;

/// What a method refined by [`refine`] is called after its `+` (`fgr+refine`): the refinement
/// (ICP, point to plane and then point to point), named apart from `icp`, the method
/// ([`crate::methods::icp::NAME`]). Every composed name reads it; none spells it.
pub const NAME: &str = "refine";

/// What [`NAME`] was before issue 58 (`fgr+icp`, `auto+icp`): read back as [`NAME`] from an
/// older file or script by [`current_name`].
pub const OLD_NAME: &str = "icp";

/// `name` as this rgm spells it: a refined name of before issue 58 (`auto+icp`, `sc2+icp`,
/// `fgr+icp/cells`: the suffix `+icp` after a base, alone or before a `/`) with [`NAME`] in
/// place of [`OLD_NAME`]; any other name (`icp`, the method; `fgr+p2p`) as it is.
pub fn current_name(name: &str) -> Cow<'_, str> {
    let old = format!("+{OLD_NAME}");
    let (head, tail) = name.split_at(name.find('/').unwrap_or(name.len()));
    match head.strip_suffix(old.as_str()) {
        Some(base) if !base.is_empty() && !base.contains('+') => {
            Cow::Owned(format!("{base}+{NAME}{tail}"))
        }
        _ => Cow::Borrowed(name),
    }
}

/// Settings of [`refine`]. Distances are in the clouds' units; the defaults suit shapes scaled
/// into the unit sphere, like ModelNet40's.
#[derive(Clone, Debug, PartialEq)]
pub struct RefineConfig {
    /// Correspondence distance of each stage, coarse to fine (default 0.2, 0.1, 0.05).
    pub distances: Vec<f64>,
    /// Most iterations per stage (default 10); a stage ends early once a step moves no point
    /// of the unit sphere by more than 1e-9.
    pub iterations: usize,
    /// Fraction of the pairs found in an iteration that the step fits: the closest ones
    /// (default 0.8, in (0, 1]).
    pub trim: f64,
    /// Correspondence distance of each point-to-point stage run after the point-to-plane ones
    /// (Open3D's ICP loop and convergence test, at most 30 iterations; default 0.05, 0.03).
    pub point_distances: Vec<f64>,
    /// How the target's normals are estimated (default radius 0.2, at most 30 neighbours).
    pub normals: NormalsConfig,
}

impl Default for RefineConfig {
    fn default() -> Self {
        Self {
            distances: vec![0.2, 0.1, 0.05],
            iterations: 10,
            trim: 0.8,
            point_distances: vec![0.05, 0.03],
            normals: NormalsConfig::default(),
        }
    }
}

impl RefineConfig {
    /// The last (finest) stage's correspondence distance, at which the result is scored.
    pub fn finest_distance(&self) -> f64 {
        self.point_distances
            .last()
            .or(self.distances.last())
            .copied()
            .unwrap_or(0.0)
    }

    fn validate(&self, op: &'static str) -> Result<()> {
        let bad = |why: String| Err(GeomError::Degenerate { op, why });
        if self.distances.is_empty() || !self.distances.iter().all(|&d| d > 0.0 && d.is_finite()) {
            return bad(format!(
                "the stages' correspondence distances must be finite and > 0, got {:?}",
                self.distances
            ));
        }
        if !self
            .point_distances
            .iter()
            .all(|&d| d > 0.0 && d.is_finite())
        {
            return bad(format!(
                "the point-to-point stages' distances must be finite and > 0, got {:?}",
                self.point_distances
            ));
        }
        if !(self.trim > 0.0 && self.trim <= 1.0) {
            return bad(format!("trim must be in (0, 1], got {}", self.trim));
        }
        Ok(())
    }
}

/// Refines `initial` (a `t_target_source`) so that `source` lies on `target`. The result is
/// scored as Open3D scores ICP, at the last stage's distance. Errors on empty clouds, non-finite
/// points or an invalid configuration; when a step cannot be solved (fewer than 6 pairs) it
/// stops with the transform so far and `converged: false`.
pub fn refine(
    source: &PointCloud,
    target: &PointCloud,
    initial: &RigidTransform,
    config: &RefineConfig,
) -> Result<Fit> {
    refine_prepared(source, &Prepared::new(target), initial, config)
}

/// [`refine`] onto a prepared target: its tree and normals those of the stages before, kept for
/// the stages after.
pub fn refine_prepared(
    source: &PointCloud,
    target: &Prepared,
    initial: &RigidTransform,
    config: &RefineConfig,
) -> Result<Fit> {
    const OP: &str = "refine::refine";
    check_clouds(OP, source, target)?;
    config.validate(OP)?;
    let index = target.index();
    let normals = target.normals(&config.normals); // (M,)
    let mut transform = *initial;
    let mut scratch = PlaneScratch::default();
    let mut iterations = 0;
    let mut converged = false; // whether the last stage ended on a negligible step
    let plane = PlaneFit {
        source,
        target,
        index,
        normals: TargetNormals::Given(&normals),
    };
    for &max_distance in &config.distances {
        let stage = PlaneStage {
            max_distance,
            iterations: config.iterations,
            trim: config.trim,
            residual_gate: None,
            negligible: 1e-9,
        };
        let outcome = plane.run(&stage, &mut transform, &mut scratch);
        iterations += outcome.iterations;
        converged = outcome.converged;
        if !outcome.solvable {
            break;
        }
    }
    for &max_correspondence_distance in &config.point_distances {
        let stage = icp::register_with_index(
            source,
            target,
            index,
            &IcpConfig {
                max_correspondence_distance,
                initial: transform,
                ..IcpConfig::default()
            },
        );
        transform = stage.t_target_source;
        iterations += stage.iterations;
        converged = stage.converged;
    }
    let moved_score = score(
        &source.points,
        index,
        &transform,
        config.finest_distance(),
        None,
    );
    Ok(Fit::scored(transform, iterations, converged, moved_score))
}

/// The clouds a point-to-plane stage fits: the target indexed, with its normals.
struct PlaneFit<'a> {
    source: &'a PointCloud,
    target: &'a PointCloud,
    index: &'a KnnIndex,
    normals: TargetNormals<'a>,
}

/// The target's normals: all given, or each computed when first needed (a dense target's
/// points that no source point reaches need none, which bounds the cost by the source's size).
enum TargetNormals<'a> {
    Given(&'a [Vector3<f64>]), // (M,)
    Lazy {
        config: WithinConfig,
        cache: RefCell<Around>,
    },
}

/// What the lazy normals learnt of the target's points: each one's normal and its neighbours
/// within the normals' radius. A source point paired with a target point in one iteration is
/// paired near it in the next, so those neighbours answer its next search
/// ([`rgm_geom::nearest_among`]) without the tree.
struct Around {
    /// Each target point's normal and where its neighbours lie in `lists`, once computed.
    known: Vec<Option<(Vector3<f64>, Range<u32>)>>, // (M,)
    /// The neighbour lists, one after another. // (Σ neighbours,)
    lists: Vec<u32>,
}

/// The target normals known so far, which the threads share: all of them, or the lazy ones
/// computed ([`PlaneFit::compute_normals`]) before they are read.
#[derive(Clone, Copy)]
enum KnownNormals<'b> {
    Given(&'b [Vector3<f64>]), // (M,)
    Lazy(&'b Around),
}

impl KnownNormals<'_> {
    /// The normal of target point `j`, which must be known.
    fn get(self, j: usize) -> Vector3<f64> {
        match self {
            Self::Given(normals) => normals[j],
            Self::Lazy(around) => {
                let (normal, _) = around.known[j]
                    .as_ref()
                    .expect("computed before it is read");
                *normal
            }
        }
    }
}

/// The buffers of point-to-plane stages, reused from one iteration to the next.
#[derive(Default)]
struct PlaneScratch {
    moved: Vec<Point3<f64>>, // (N,) the source under the current transform
    nearest: Correspondences,
    pairs: Vec<(usize, usize, f64)>, // (P,) i, j, distance
}

/// What the last search of each source point found, to start the next from.
#[derive(Default)]
struct Correspondences {
    /// Each moved point's nearest target point. // (N,)
    found: Vec<Option<(usize, f64)>>,
    /// Where a point without one was last searched, and how far from there no target point
    /// lies. // (N,)
    clear: Vec<Option<(Point3<f64>, f64)>>,
}

/// One point-to-plane stage.
struct PlaneStage {
    /// Pairs farther apart than this are not found.
    max_distance: f64,
    /// Most iterations.
    iterations: usize,
    /// Share of the closest pairs fitted.
    trim: f64,
    /// When given, only pairs whose point-to-plane residual is within it are fitted.
    residual_gate: Option<f64>,
    /// The stage ends once a step moves no point within distance 1 of the origin by more than
    /// this.
    negligible: f64,
}

/// How a stage ended.
struct StageOutcome {
    iterations: usize,
    /// Whether it ended on a negligible step.
    converged: bool,
    /// False when an iteration found fewer than 6 pairs to fit.
    solvable: bool,
}

impl<'a> PlaneFit<'a> {
    /// The clouds with the target's normals estimated when first needed, from the neighbours
    /// within 3.6 point spacings (≈ 30 on a scan, as many as Open3D's tutorial takes; the
    /// radius chosen on the Stanford scans, docs/baselines.md); where those are sparse or lie
    /// along a line, from the 30 nearest within 8 spacings.
    fn at_spacing(
        source: &'a PointCloud,
        target: &'a PointCloud,
        index: &'a KnnIndex,
        spacing: f64,
    ) -> Self {
        Self {
            source,
            target,
            index,
            normals: TargetNormals::Lazy {
                config: WithinConfig {
                    radius: 3.6 * spacing,
                    sparse: NormalsConfig {
                        radius: 8.0 * spacing,
                        ..NormalsConfig::default()
                    },
                },
                cache: RefCell::new(Around {
                    known: vec![None; target.len()],
                    lists: Vec::new(),
                }),
            },
        }
    }

    /// Runs `read` on the target normals known so far.
    fn known<T>(&self, read: impl FnOnce(KnownNormals<'_>) -> T) -> T {
        match &self.normals {
            TargetNormals::Given(normals) => read(KnownNormals::Given(normals)),
            TargetNormals::Lazy { cache, .. } => read(KnownNormals::Lazy(&cache.borrow())),
        }
    }

    /// Each source point's nearest target point strictly within `max_distance` under
    /// `transform` ([`crate::fit::nearest_each`]'s answers): a point paired before searched
    /// among its earlier partner's neighbours where they prove the answer, and a point with no
    /// target point near where it was last searched answered "none" while it has not moved out
    /// of that clearance (most of a partial overlap's points, every iteration after the first).
    fn nearest_each(
        &self,
        transform: &RigidTransform,
        max_distance: f64,
        scratch: &mut Correspondences,
    ) {
        let Correspondences { found, clear } = scratch;
        if clear.len() != self.source.len() {
            found.clear();
            clear.clear();
            clear.resize(self.source.len(), None);
        }
        let borrowed = match &self.normals {
            TargetNormals::Lazy { config, cache } => Some((config.radius, cache.borrow())),
            TargetNormals::Given(_) => None,
        };
        // The borrow's contents, which the threads may share (the borrow itself stays here).
        let lazy = borrowed.as_ref().map(|(reach, around)| (*reach, &**around));
        let (points, index) = (&self.target.points, self.index);
        let among = |partner: usize, moved: &Point3<f64>| {
            let (reach, around) = lazy?;
            let (_, list) = around.known[partner].as_ref()?;
            let list = &around.lists[list.start as usize..list.end as usize];
            nearest_among(points, list, partner, reach, moved, max_distance)
        };
        let source = &self.source.points;
        nearest_each_by(source, transform, found, clear, |moved, earlier, clear| {
            if let Some((at, gap)) = *clear {
                // Nothing lies within `gap` of `at`, so nothing within `gap − |moved − at|` of
                // `moved` (a hair less, for rounding).
                if (gap - (moved - at).norm()) * (1.0 - 1e-9) >= max_distance {
                    return None;
                }
            }
            if let Some(answer) = earlier.and_then(|(partner, _)| among(partner, moved)) {
                return answer;
            }
            let answer = search_from(index, moved, max_distance, earlier);
            // A miss is searched again twice as far, so that the next iterations can tell it
            // from its clearance.
            *clear = answer.is_none().then(|| {
                let wide = 2.0 * max_distance;
                let gap = index.nearest_within(moved, wide).map_or(wide, |(_, d)| d);
                (*moved, gap)
            });
            answer
        });
    }

    /// Computes side by side the lazy normals (and neighbour lists) of the target points `js`
    /// that are not known yet.
    fn compute_normals(&self, js: impl ParallelIterator<Item = usize>) {
        let TargetNormals::Lazy { config, cache } = &self.normals else {
            return;
        };
        let mut around = cache.borrow_mut();
        let known = &around.known;
        let mut missing: Vec<usize> = js.filter(|&j| known[j].is_none()).collect();
        missing.par_sort_unstable();
        missing.dedup();
        // Pieces of a few hundred: enough for the threads, few enough to gather.
        const PIECE: usize = 256;
        let (points, index) = (&self.target.points, self.index);
        // Per piece: the normals, the neighbour lists one after another, where each ends.
        type Piece = (Vec<Vector3<f64>>, Vec<u32>, Vec<usize>);
        let pieces: Vec<Piece> = missing
            .par_chunks(PIECE)
            .map(|piece| {
                let mut lists = Vec::new();
                let mut ends = Vec::with_capacity(piece.len());
                let normals = piece
                    .iter()
                    .map(|&j| {
                        let start = lists.len();
                        index.for_each_within(&points[j], config.radius, |i, _| {
                            lists.push(i as u32)
                        });
                        ends.push(lists.len());
                        normal_from_around(points, index, j, &lists[start..], config)
                    })
                    .collect();
                (normals, lists, ends)
            })
            .collect();
        let mut missing = missing.into_iter();
        for (normals, lists, ends) in pieces {
            let base = around.lists.len();
            around.lists.extend_from_slice(&lists);
            let mut start = base;
            // The piece's own first: a zip that ends on it takes nothing more from `missing`.
            for ((normal, end), j) in normals.into_iter().zip(ends).zip(missing.by_ref()) {
                let range = start as u32..(base + end) as u32;
                around.known[j] = Some((normal, range));
                start = base + end;
            }
        }
    }

    /// Runs `stage` from `transform`, updating it; `scratch` holds its buffers.
    fn run(
        &self,
        stage: &PlaneStage,
        transform: &mut RigidTransform,
        scratch: &mut PlaneScratch,
    ) -> StageOutcome {
        let mut outcome = StageOutcome {
            iterations: 0,
            converged: false,
            solvable: true,
        };
        let PlaneScratch {
            moved,
            nearest,
            pairs,
        } = scratch;
        for _ in 0..stage.iterations {
            moved.clear();
            moved.par_extend(self.source.points.par_iter().map(|p| transform.apply(p)));
            self.nearest_each(transform, stage.max_distance, nearest);
            let nearest = &nearest.found;
            pairs.clear();
            if stage.residual_gate.is_some() {
                self.compute_normals(nearest.par_iter().filter_map(|&found| Some(found?.0)));
            }
            self.known(|normals| {
                let within = |i: usize, j: usize| {
                    stage.residual_gate.is_none_or(|gate| {
                        (self.target.points[j] - moved[i])
                            .dot(&normals.get(j))
                            .abs()
                            <= gate
                    })
                };
                pairs.par_extend(nearest.par_iter().enumerate().filter_map(|(i, &found)| {
                    let (j, d) = found?;
                    within(i, j).then_some((i, j, d))
                }));
            });
            let keep = ((pairs.len() as f64 * stage.trim).ceil() as usize).min(pairs.len());
            if keep < 6 {
                outcome.solvable = false;
                break;
            }
            if keep < pairs.len() {
                pairs.select_nth_unstable_by(keep - 1, |a, b| a.2.total_cmp(&b.2));
                pairs.truncate(keep);
            }
            self.compute_normals(pairs.par_iter().map(|&(_, j, _)| j));
            let step =
                self.known(|normals| point_to_plane_step(moved, self.target, normals, pairs));
            *transform = step.compose(transform);
            outcome.iterations += 1;
            let angle = step.rotation_angle_deg().to_radians();
            if angle + step.translation.norm() < stage.negligible {
                outcome.converged = true;
                break;
            }
        }
        outcome
    }

    /// The median absolute point-to-plane residual of the source's points under `transform`
    /// that have a target point within `max_distance`; `None` when none has. `scratch` holds
    /// the buffers of the stages run before (their last correspondences start the searches).
    fn median_residual(
        &self,
        transform: &RigidTransform,
        max_distance: f64,
        scratch: &mut PlaneScratch,
    ) -> Option<f64> {
        self.nearest_each(transform, max_distance, &mut scratch.nearest);
        let nearest = &scratch.nearest.found;
        self.compute_normals(nearest.par_iter().filter_map(|&found| Some(found?.0)));
        let mut residuals: Vec<f64> = self.known(|normals| {
            self.source
                .points
                .par_iter()
                .zip(nearest.par_iter())
                .filter_map(|(p, &found)| {
                    let (j, _) = found?;
                    Some(
                        (self.target.points[j] - transform.apply(p))
                            .dot(&normals.get(j))
                            .abs(),
                    )
                })
                .collect()
        });
        if residuals.is_empty() {
            return None;
        }
        let middle = residuals.len() / 2;
        Some(*residuals.select_nth_unstable_by(middle, f64::total_cmp).1)
    }
}

/// The median distance from a point of `points` to its nearest other point, over at most
/// `sample` points taken at an even stride; `index` must index `points`. Duplicates count as
/// distance 0.
pub fn median_spacing(points: &[Point3<f64>], index: &KnnIndex, sample: usize) -> f64 {
    let mut gaps: Vec<f64> = rgm_geom::cloud::evenly(points, sample)
        .filter_map(|p| index.k_nearest(p, 2).get(1).map(|&(_, d)| d))
        .collect();
    if gaps.is_empty() {
        return 0.0;
    }
    let middle = gaps.len() / 2;
    *gaps.select_nth_unstable_by(middle, f64::total_cmp).1
}

/// Settings of [`refine_at_resolution`]: every distance is a multiple of the clouds' own
/// point spacing (the target's median nearest-neighbour distance), so the stages fit a dense
/// scan as they fit a sparse synthetic cloud.
#[derive(Clone, Debug, PartialEq)]
pub struct ResolutionConfig {
    /// Correspondence distance of each point-to-plane stage, in point spacings (default 4, 2).
    pub spacings: Vec<f64>,
    /// The last stage, at the last of `spacings`, fits only the pairs whose point-to-plane
    /// residual is within this many times the noise, the noise being 1.4826 × the median
    /// absolute residual once the other stages are done (a robust σ; default 3).
    pub noise_sigmas: f64,
    /// Most iterations per stage (default 30).
    pub iterations: usize,
    /// A stage ends once a step moves no point by more than this share of a point spacing
    /// (default 5e-2, for a cloud within distance 1 of the origin; tried against 1e-2 on the
    /// scans, `docs/baselines.md`, "The cascade").
    pub negligible: f64,
    /// Most source points fitted, taken at an even stride (default 30,000: the fewest that kept
    /// the scans' median errors, `docs/baselines.md`, "The cascade").
    pub max_source_points: usize,
    /// Most source points fitted in the stages before the finest of `spacings`, taken at an
    /// even stride from the sampled ones (default 5,000): they only bring the pose within the
    /// finest stage's reach, and it and the stage at the noise fit every sampled point (the
    /// same errors on the scans and the LiDAR pair; fitting only the noise stage's so left the
    /// LiDAR pair 5–10 mm worse, `docs/speed.md`).
    pub max_coarse_points: usize,
}

impl Default for ResolutionConfig {
    fn default() -> Self {
        Self {
            spacings: vec![4.0, 2.0],
            noise_sigmas: 3.0,
            iterations: 30,
            negligible: 5e-2,
            max_source_points: 30_000,
            max_coarse_points: 5_000,
        }
    }
}

/// Refines `initial` on the clouds as given, at their own resolution: point-to-plane stages at
/// [`ResolutionConfig::spacings`] times the target's point spacing, the last one at the noise.
/// Only the stages finer than `coarser_than` run (a coarse refinement already ran down to that
/// distance; on clouds as sparse as ModelNet40's none is finer, and the transform is returned
/// unchanged). `index` must index `target`, and `spacing` be its point spacing (its
/// [`median_spacing`] over [`crate::prepared::SPACING_SAMPLE`] points, the first of
/// [`crate::Prepared::spacings`]).
/// Returns the transform and the iterations run.
pub fn refine_at_resolution(
    source: &PointCloud,
    target: &PointCloud,
    index: &KnnIndex,
    spacing: f64,
    initial: &RigidTransform,
    coarser_than: f64,
    config: &ResolutionConfig,
) -> Result<(RigidTransform, usize)> {
    const OP: &str = "refine::refine_at_resolution";
    check_clouds(OP, source, target)?;
    let distances: Vec<f64> = config
        .spacings
        .iter()
        .map(|k| k * spacing)
        .filter(|&d| d > 0.0 && d < coarser_than)
        .collect();
    let Some(&finest) = distances.last() else {
        return Ok((*initial, 0));
    };
    // At most `max_source_points` of the source, at an even stride: enough pairs to pin the
    // fit down, at a cost that does not grow with the clouds' density.
    let sampled = evenly_strided(source, config.max_source_points);
    let coarse = evenly_strided(&sampled, config.max_coarse_points);
    // The coarse stages and the finest share the target's normals as they are computed.
    let mut plane = PlaneFit::at_spacing(&coarse, target, index, spacing);
    let mut transform = *initial;
    let mut scratch = PlaneScratch::default();
    let mut iterations = 0;
    let mut stage = PlaneStage {
        max_distance: 0.0,
        iterations: config.iterations,
        trim: 1.0,
        residual_gate: None,
        negligible: config.negligible * spacing,
    };
    for (k, &max_distance) in distances.iter().enumerate() {
        if k + 1 == distances.len() {
            plane.source = &sampled;
        }
        stage.max_distance = max_distance;
        let outcome = plane.run(&stage, &mut transform, &mut scratch);
        iterations += outcome.iterations;
        if !outcome.solvable {
            return Ok((transform, iterations));
        }
    }
    if let Some(median) = plane.median_residual(&transform, finest, &mut scratch) {
        stage.residual_gate = Some(config.noise_sigmas * 1.4826 * median);
        iterations += plane.run(&stage, &mut transform, &mut scratch).iterations;
    }
    Ok((transform, iterations))
}

/// At most `most` points of `cloud`, at an even stride from its first.
fn evenly_strided(cloud: &PointCloud, most: usize) -> Cow<'_, PointCloud> {
    let stride = cloud.len().div_ceil(most.max(1));
    if stride > 1 {
        Cow::Owned(cloud.select(&(0..cloud.len()).step_by(stride).collect::<Vec<_>>()))
    } else {
        Cow::Borrowed(cloud)
    }
}

/// The median absolute point-to-plane residual of `source`'s points moved by `transform` that
/// have a point of `target` within `max_distance` (`index` indexes `target`), the normals
/// estimated from `spacing` as [`refine_at_resolution`] estimates them; `None` when no point
/// has. How well a refined scan lies on the others ([`crate::multiway`]).
pub fn median_plane_residual(
    source: &PointCloud,
    target: &PointCloud,
    index: &KnnIndex,
    transform: &RigidTransform,
    max_distance: f64,
    spacing: f64,
) -> Option<f64> {
    PlaneFit::at_spacing(source, target, index, spacing).median_residual(
        transform,
        max_distance,
        &mut PlaneScratch::default(),
    )
}

/// Pairs per block of [`point_to_plane_step`]'s sums: each block is summed in order and the
/// blocks' sums are added in order, so the step is the same on any number of threads (and, for
/// up to this many pairs, the plain sum in order).
const STEP_BLOCK: usize = 4096;

/// The rigid step minimising the linearised point-to-plane residuals of `pairs`
/// (moved source index, target index, distance), whose target normals must be known. The
/// normal equations are damped by 1e-9 of their mean diagonal, so that directions the pairs do
/// not constrain (a plane slides in itself) get no motion instead of a singular solve.
fn point_to_plane_step(
    moved: &[Point3<f64>],
    target: &PointCloud,
    normals: KnownNormals<'_>,
    pairs: &[(usize, usize, f64)],
) -> RigidTransform {
    let blocks: Vec<(Matrix6<f64>, Vector6<f64>)> = pairs
        .par_chunks(STEP_BLOCK)
        .map(|block| {
            let mut ata = Matrix6::<f64>::zeros(); // its upper triangle
            let mut atb = Vector6::<f64>::zeros();
            for &(i, j, _) in block {
                let p = moved[i];
                let n = normals.get(j);
                let c = p.coords.cross(&n);
                let row = Vector6::new(c.x, c.y, c.z, n.x, n.y, n.z);
                for col in 0..6 {
                    for r in 0..=col {
                        ata[(r, col)] += row[r] * row[col];
                    }
                }
                atb += row * (target.points[j] - p).dot(&n);
            }
            (ata, atb)
        })
        .collect();
    let (mut ata, atb) = blocks
        .into_iter()
        .reduce(|(ata, atb), (block_ata, block_atb)| (ata + block_ata, atb + block_atb))
        .unwrap_or_default();
    // The lower triangle mirrors the upper: the same products, summed in the same order.
    for col in 0..6 {
        for r in col + 1..6 {
            ata[(r, col)] = ata[(col, r)];
        }
    }
    let damping = 1e-9 * ata.trace() / 6.0 + f64::MIN_POSITIVE;
    for k in 0..6 {
        ata[(k, k)] += damping;
    }
    let x = ata
        .cholesky()
        .map_or_else(Vector6::zeros, |c| c.solve(&atb));
    let rotation = Rotation3::new(Vector3::new(x[0], x[1], x[2]));
    RigidTransform::new(rotation.into_inner(), Vector3::new(x[3], x[4], x[5]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::nearest_each;
    use rand::{rngs::StdRng, SeedableRng};
    use rand_distr::{Distribution, Normal};
    use rgm_geom::euler::rotation_xyz_intrinsic;
    use rgm_geom::testing::{airplane, box_surface};

    /// The error of `found` against `truth`: (rotation °, translation).
    fn error(found: &RigidTransform, truth: &RigidTransform) -> (f64, f64) {
        let residual = truth.inverse().compose(found);
        (residual.rotation_angle_deg(), residual.translation.norm())
    }

    /// The 70 % of `cloud` farthest along `direction`, jittered as the benchmark's partial
    /// protocol does (σ 0.01, clipped at 0.05).
    fn cropped_and_jittered(cloud: &PointCloud, direction: Vector3<f64>, seed: u64) -> PointCloud {
        let mut order: Vec<&Point3<f64>> = cloud.points.iter().collect();
        order.sort_by(|a, b| {
            b.coords
                .dot(&direction)
                .total_cmp(&a.coords.dot(&direction))
        });
        let mut rng = StdRng::seed_from_u64(seed);
        let noise = Normal::new(0.0f64, 0.01).expect("a valid σ");
        let mut jitter = || noise.sample(&mut rng).clamp(-0.05, 0.05);
        let keep = cloud.len() * 7 / 10;
        PointCloud::new(
            order[..keep]
                .iter()
                .map(|p| *p + Vector3::new(jitter(), jitter(), jitter()))
                .collect(),
        )
    }

    #[test]
    fn recovers_a_small_offset_exactly_on_identical_points() {
        let target = box_surface(500, 1);
        let truth = RigidTransform::new(
            rotation_xyz_intrinsic(0.05, -0.03, 0.04),
            Vector3::new(0.02, -0.01, 0.03),
        );
        let source = target.transformed(&truth.inverse());
        let config = RefineConfig {
            trim: 1.0,
            ..RefineConfig::default()
        };
        let result = refine(&source, &target, &RigidTransform::identity(), &config).unwrap();
        let (angle, shift) = error(&result.t_target_source, &truth);
        assert!(
            angle < 1e-6 && shift < 1e-8,
            "error {angle:.3e}°, {shift:.3e}"
        );
        assert!(result.converged);
        assert_eq!(result.inlier_count, 500);
        assert!(result.inlier_rmse < 1e-8);
    }

    /// The case it exists for: two differently cropped, jittered views 25° and 0.08 apart land
    /// within half a degree (what is left is the jitter's).
    #[test]
    fn converges_on_a_partial_overlap_from_25_degrees() {
        let shape = airplane();
        let truth = RigidTransform::new(
            rotation_xyz_intrinsic(0.3, -0.25, 0.25),
            Vector3::new(0.05, -0.04, 0.05),
        );
        let target = cropped_and_jittered(&shape, Vector3::new(1.0, 0.3, 0.0), 1);
        let source = cropped_and_jittered(&shape, Vector3::new(-0.2, 1.0, 0.4), 2)
            .transformed(&truth.inverse());
        let start = RigidTransform::identity();
        let (start_angle, _) = error(&start, &truth);
        assert!(start_angle > 25.0, "start {start_angle:.2}°");
        let refined = refine(&source, &target, &start, &RefineConfig::default()).unwrap();
        let (angle, shift) = error(&refined.t_target_source, &truth);
        assert!(
            angle < 0.6 && shift < 0.01,
            "refined error {angle:.3}°, {shift:.4}"
        );
        assert!(refined.iterations > 3 && refined.converged, "{refined:?}");
    }

    /// Two crops of one jittered shape, as the benchmark pairs them: the point-to-point stages
    /// pin down what point-to-plane leaves loose along the surface.
    #[test]
    fn point_to_point_stages_sharpen_the_result() {
        let shape = airplane();
        let truth = RigidTransform::new(
            rotation_xyz_intrinsic(0.1, -0.05, 0.08),
            Vector3::new(0.03, -0.02, 0.01),
        );
        let target = cropped_and_jittered(&shape, Vector3::new(1.0, 0.3, 0.0), 3);
        let source = cropped_and_jittered(&shape, Vector3::new(0.6, 1.0, 0.2), 4)
            .transformed(&truth.inverse());
        let start = RigidTransform::identity();
        let plane_only = RefineConfig {
            point_distances: vec![],
            ..RefineConfig::default()
        };
        let coarse = refine(&source, &target, &start, &plane_only).unwrap();
        let fine = refine(&source, &target, &start, &RefineConfig::default()).unwrap();
        let (coarse_angle, _) = error(&coarse.t_target_source, &truth);
        let (fine_angle, fine_shift) = error(&fine.t_target_source, &truth);
        // Measured: 0.84° after the point-to-plane stages, 0.64° (and 0.0035) after all.
        assert!(
            fine_angle < coarse_angle - 0.15 && fine_shift < 0.01,
            "{fine_angle:.3}° and {fine_shift:.4} vs {coarse_angle:.3}°"
        );
        assert!(fine.iterations > coarse.iterations);
    }

    /// Two independent dense samples of a box (spacing about 0.006), the source jittered by
    /// σ 0.0005 and off by 0.3° and 0.004: the stages at 4 and 2 spacings and at the noise
    /// land far closer than the 0.03 the coarse stages end at.
    #[test]
    fn the_resolution_stages_reach_the_dense_clouds_precision() {
        let target = box_surface(20_000, 1);
        let mut rng = StdRng::seed_from_u64(5);
        let noise = Normal::new(0.0f64, 0.0005).expect("a valid σ");
        let source = PointCloud::new(
            box_surface(20_000, 2)
                .points
                .iter()
                .map(|p| {
                    p + Vector3::new(
                        noise.sample(&mut rng),
                        noise.sample(&mut rng),
                        noise.sample(&mut rng),
                    )
                })
                .collect(),
        );
        let truth = RigidTransform::new(
            rotation_xyz_intrinsic(0.004, -0.002, 0.003),
            Vector3::new(0.003, -0.002, 0.002),
        );
        let source = source.transformed(&truth.inverse());
        let index = KnnIndex::new(&target.points);
        let spacing = median_spacing(&target.points, &index, 2000);
        assert!(spacing > 0.003 && spacing < 0.008, "spacing {spacing}");
        let start = RigidTransform::identity();
        let (found, iterations) = refine_at_resolution(
            &source,
            &target,
            &index,
            spacing,
            &start,
            0.03,
            &ResolutionConfig::default(),
        )
        .unwrap();
        let (angle, shift) = error(&found, &truth);
        assert!(
            angle < 0.02 && shift < 2e-4,
            "error {angle:.4}°, {shift:.2e}"
        );
        assert!(iterations >= 3, "{iterations}");
        // A tenth of the source, at an even stride, pins the fit down as well. Stages before
        // the finest on 20 points only bring the pose near; the finest and the last, on every
        // sampled point, fit it as precisely (20 points alone: 0.07°, 2e-4).
        let few = ResolutionConfig {
            max_source_points: 2000,
            ..ResolutionConfig::default()
        };
        let coarse = ResolutionConfig {
            max_coarse_points: 20,
            ..ResolutionConfig::default()
        };
        for (config, bounds) in [(few, (0.03, 3e-4)), (coarse, (0.005, 2e-5))] {
            let (found, _) =
                refine_at_resolution(&source, &target, &index, spacing, &start, 0.03, &config)
                    .unwrap();
            let (angle, shift) = error(&found, &truth);
            assert!(
                angle < bounds.0 && shift < bounds.1,
                "error {angle:.4}°, {shift:.2e} with {config:?}"
            );
        }
        // Clouds as sparse as ModelNet40's have no stage finer than the coarse ones: unchanged.
        let sparse = box_surface(300, 3);
        let sparse_index = KnnIndex::new(&sparse.points);
        let nudged =
            RigidTransform::new(nalgebra::Matrix3::identity(), Vector3::new(0.01, 0.0, 0.0));
        let unchanged = refine_at_resolution(
            &sparse,
            &sparse,
            &sparse_index,
            median_spacing(&sparse.points, &sparse_index, 2000),
            &nudged,
            0.03,
            &ResolutionConfig::default(),
        )
        .unwrap();
        assert_eq!(unchanged, (nudged, 0));
    }

    #[test]
    fn no_pairs_within_reach_return_the_initial_transform_unconverged() {
        let target = box_surface(200, 3);
        let far = RigidTransform::new(nalgebra::Matrix3::identity(), Vector3::new(10.0, 0.0, 0.0));
        let result = refine(&target, &target, &far, &RefineConfig::default()).unwrap();
        assert_eq!(result.t_target_source, far);
        assert_eq!((result.iterations, result.converged), (0, false));
        assert_eq!(result.inlier_count, 0);
    }

    #[test]
    fn invalid_settings_and_clouds_are_errors() {
        let cloud = box_surface(100, 4);
        let start = RigidTransform::identity();
        for config in [
            RefineConfig {
                trim: 0.0,
                ..RefineConfig::default()
            },
            RefineConfig {
                trim: 1.5,
                ..RefineConfig::default()
            },
            RefineConfig {
                trim: f64::NAN,
                ..RefineConfig::default()
            },
            RefineConfig {
                distances: vec![],
                ..RefineConfig::default()
            },
            RefineConfig {
                distances: vec![0.2, -0.1],
                ..RefineConfig::default()
            },
        ] {
            let err = refine(&cloud, &cloud, &start, &config).unwrap_err();
            assert!(
                matches!(
                    err,
                    GeomError::Degenerate {
                        op: "refine::refine",
                        ..
                    }
                ),
                "{err}"
            );
        }
        let empty = PointCloud::new(vec![]);
        assert!(refine(&empty, &cloud, &start, &RefineConfig::default()).is_err());
    }

    #[test]
    fn names_of_before_issue_58_read_as_today_s() {
        for (old, now) in [
            ("auto+icp", "auto+refine"),
            ("sc2+icp", "sc2+refine"),
            ("fgr+icp/cells", "fgr+refine/cells"),
            ("partial-fast+icp", "partial-fast+refine"),
            // The method ICP, names of today, other refiners and what is not a name stay.
            ("icp", "icp"),
            ("icp/cells", "icp/cells"),
            ("auto+refine", "auto+refine"),
            ("fgr+p2p", "fgr+p2p"),
            ("+icp", "+icp"),
            ("a+b+icp", "a+b+icp"),
        ] {
            assert_eq!(current_name(old), now, "{old}");
        }
    }

    #[test]
    fn the_plane_step_sums_by_blocks_the_same_on_any_number_of_threads() {
        // Pairs of points near a slanted plane and their normals, in a random order.
        let mut rng = StdRng::seed_from_u64(46);
        let noise = Normal::new(0.0f64, 0.01).expect("a valid σ");
        let n = 3 * STEP_BLOCK + 123;
        let normal = Vector3::new(0.3, -0.2, 0.9).normalize();
        let mut sample = || {
            Vector3::new(
                noise.sample(&mut rng),
                noise.sample(&mut rng),
                noise.sample(&mut rng),
            )
        };
        let target = PointCloud::new((0..n).map(|_| Point3::from(sample() * 50.0)).collect());
        let moved: Vec<Point3<f64>> = target.points.iter().map(|q| q + sample()).collect();
        let normals: Vec<Vector3<f64>> = (0..n).map(|_| (normal + sample()).normalize()).collect();
        let pairs: Vec<(usize, usize, f64)> = (0..n).map(|i| (i, (i * 7919) % n, 0.0)).collect();
        // The normal equations summed pair after pair, each product of the full 6 × 6 matrix.
        let plain = |pairs: &[(usize, usize, f64)]| {
            let (mut ata, mut atb) = (Matrix6::<f64>::zeros(), Vector6::<f64>::zeros());
            for &(i, j, _) in pairs {
                let (p, n) = (moved[i], normals[j]);
                let c = p.coords.cross(&n);
                let row = Vector6::new(c.x, c.y, c.z, n.x, n.y, n.z);
                ata += row * row.transpose();
                atb += row * (target.points[j] - p).dot(&n);
            }
            let damping = 1e-9 * ata.trace() / 6.0 + f64::MIN_POSITIVE;
            for k in 0..6 {
                ata[(k, k)] += damping;
            }
            let x = ata.cholesky().unwrap().solve(&atb);
            let rotation = Rotation3::new(Vector3::new(x[0], x[1], x[2]));
            RigidTransform::new(rotation.into_inner(), Vector3::new(x[3], x[4], x[5]))
        };
        let step = |threads: usize, pairs: &[(usize, usize, f64)]| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                point_to_plane_step(&moved, &target, KnownNormals::Given(&normals), pairs)
            })
        };
        // One block: the plain sum, bit for bit.
        let one_block = &pairs[..STEP_BLOCK];
        assert_eq!(step(1, one_block), plain(one_block));
        assert_eq!(step(2, one_block), plain(one_block));
        // Four blocks: the same bits on one thread and on three, and the plain sum to rounding.
        let blocks = step(1, &pairs);
        assert_eq!(blocks, step(3, &pairs));
        let difference = plain(&pairs).inverse().compose(&blocks);
        assert!(difference.rotation_angle_deg() < 1e-9, "{difference:?}");
        assert!(difference.translation.norm() < 1e-10, "{difference:?}");
        assert!(
            blocks.rotation_angle_deg() > 1e-3,
            "the step must move: {blocks:?}"
        );
    }

    #[test]
    fn a_plane_fit_s_searches_answer_what_a_fresh_search_answers() {
        // A partial overlap: the source cut to 70 % and moved a little each iteration, so that
        // searches start from earlier partners' neighbours and from earlier misses' clearances.
        let target = box_surface(6000, 41);
        let source = cropped_and_jittered(&box_surface(6000, 42), Vector3::new(0.3, 0.8, 0.5), 43);
        let index = KnnIndex::new(&target.points);
        let plane = PlaneFit::at_spacing(&source, &target, &index, 0.012);
        let mut scratch = PlaneScratch::default();
        let mut rng = StdRng::seed_from_u64(44);
        let (mut misses, mut fresh) = (0, Vec::new());
        for (step, max_distance) in [0.05, 0.05, 0.03, 0.03, 0.02, 0.02, 0.02]
            .iter()
            .enumerate()
        {
            let nudge = RigidTransform::random(&mut rng, 0.3, 0.004);
            let transform = nudge.compose(&RigidTransform::random(
                &mut StdRng::seed_from_u64(45),
                3.0,
                0.02,
            ));
            plane.nearest_each(&transform, *max_distance, &mut scratch.nearest);
            nearest_each(
                &source.points,
                &index,
                &transform,
                *max_distance,
                &mut fresh,
            );
            assert_eq!(scratch.nearest.found, fresh, "iteration {step}");
            fresh.clear();
            misses += scratch.nearest.found.iter().filter(|f| f.is_none()).count();
            plane.compute_normals(
                scratch
                    .nearest
                    .found
                    .par_iter()
                    .filter_map(|f| Some(f.as_ref()?.0)),
            );
        }
        assert!(misses > 1000, "{misses} misses");
    }
}
