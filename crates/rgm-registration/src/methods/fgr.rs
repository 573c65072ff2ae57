//! Fast Global Registration (Zhou, Park & Koltun, ECCV 2016) on FPFH features, as Open3D's
//! `registration_fgr_based_on_feature_matching` with `FastGlobalRegistrationOption`.
//!
//! Open3D's steps, followed one by one:
//! 1. Features: PCA normals and FPFH of each cloud ([`rgm_geom::fpfh::features`]).
//! 2. Initial matching: mutual nearest neighbours in the 33-D feature space (exact, brute force;
//!    ties to the lowest index), ordered by source index.
//! 3. Tuple test: `100 × matches` times draw three matches at random; keep the triple when each
//!    of its three side lengths agrees between the clouds within a factor `tuple_scale`
//!    (`scale·l_s < l_t < l_s/scale`), until `maximum_tuple_count` triples; every kept triple
//!    adds its three matches (repeats allowed) to the final list. Open3D draws from its global
//!    random generator; we draw from a generator seeded by `seed`, so results are reproducible.
//! 4. Normalisation: each cloud is centred on its own mean; both are divided by the largest
//!    distance of a centred point to its centre (unless `use_absolute_scale`).
//! 5. Optimisation: `iteration_number` Gauss–Newton steps of the Geman–McClure objective with
//!    line processes: weights `l = (μ / (μ + ‖p − T q‖²))²`, a step linearised in the rotation
//!    (small angles ω, applied as `Rz(ω_z)·Ry(ω_y)·Rx(ω_x)`), the target moved onto the source.
//!    μ starts at the normalising scale (as Open3D passes it; 1 with `use_absolute_scale`) and,
//!    with `decrease_mu`, is divided by `division_factor` every 4th iteration while above
//!    `maximum_correspondence_distance`. A failed solve leaves the transform unchanged for that
//!    iteration (Open3D's zero step) and marks the result not converged.
//! 6. The transform is brought back to the original scale and inverted, to map source onto
//!    target. With fewer than 10 matches Open3D returns the identity; so do we (`converged`
//!    false).
//!
//! Clouds of more than [`FgrConfig::max_points`] points are first voxel-downsampled, as
//! Open3D's FGR pipeline does (its tutorial downsamples before computing features): matching
//! is quadratic in the points (100,000 points took two minutes).
//!
//! The result's fitness and RMSE are Open3D's score of the final transform at
//! `maximum_correspondence_distance` (0.025 by default, in the clouds' units), as Open3D's
//! `EvaluateRegistration` call at the end of FGR.
//!
//! The file is long because its unit tests sit beside the code they check (as everywhere in
//! rgm); the code itself is one job, kept in one place.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Mutex, OnceLock};
use std::time::Instant;

use nalgebra::{Matrix3, Matrix6, Point3, Vector3, Vector6};
use rand::{rngs::StdRng, Rng, SeedableRng};
use rayon::prelude::*;
use rgm_geom::euler::rotation_xyz_extrinsic;
use rgm_geom::fpfh::{features, Fpfh, FpfhConfig, FPFH_LEN};
use rgm_geom::normals::NormalsConfig;
use rgm_geom::{lockstep, GeomError, PointCloud, Result, RigidTransform};

use crate::fit::{score, Fit};
use crate::methods::icp::check_clouds;
use crate::registrar::{MethodId, Progress, Registrar, Registration};
use crate::Prepared;

/// Open3D returns the identity below this many matches.
const MIN_MATCHES: usize = 10;

/// Settings of [`register`]: Open3D's `FastGlobalRegistrationOption` defaults except
/// `decrease_mu`, plus the feature settings of the project's Open3D measurements.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FgrConfig {
    /// Normals for FPFH (default radius 0.2, max_nn 30).
    pub normals: NormalsConfig,
    /// FPFH neighbourhood (default radius 0.4, max_nn 100).
    pub fpfh: FpfhConfig,
    /// μ is divided by this (default 1.4).
    pub division_factor: f64,
    /// Work in the clouds' own units instead of normalising by their extent (default false).
    pub use_absolute_scale: bool,
    /// Graduated non-convexity: decrease μ during the iterations. Default true, the paper's
    /// algorithm; Open3D's default is false (μ stays at its loose start), which is markedly less
    /// accurate (`docs/geom.md`). Set false to reproduce Open3D's defaults.
    pub decrease_mu: bool,
    /// μ stops decreasing below this (default 0.025, in normalised units).
    pub maximum_correspondence_distance: f64,
    /// Gauss–Newton iterations (default 64).
    pub iteration_number: usize,
    /// Side-length agreement factor of the tuple test (default 0.95).
    pub tuple_scale: f64,
    /// Most triples kept by the tuple test (default 1000).
    pub maximum_tuple_count: usize,
    /// Run the tuple test (default true).
    pub tuple_test: bool,
    /// Seed of the tuple test's random draws (default 0).
    pub seed: u64,
    /// A cloud with more points is voxel-downsampled first, with the finest voxel (of a
    /// ladder of sizes 1.25× apart) that leaves at most this many (default 5,000; the
    /// benchmark's clouds have 1,024). The transform is scored on the full clouds.
    pub max_points: usize,
}

impl Default for FgrConfig {
    fn default() -> Self {
        Self {
            normals: NormalsConfig::default(),
            fpfh: FpfhConfig::default(),
            division_factor: 1.4,
            use_absolute_scale: false,
            decrease_mu: true,
            maximum_correspondence_distance: 0.025,
            iteration_number: 64,
            tuple_scale: 0.95,
            maximum_tuple_count: 1000,
            tuple_test: true,
            seed: 0,
            max_points: 5000,
        }
    }
}

/// The method's name ([`crate::registrar::MethodId`]).
pub const NAME: &str = "fgr";

/// Registers `source` onto `target`: features, matching, tuple test, optimisation.
pub fn register(source: &PointCloud, target: &PointCloud, config: &FgrConfig) -> Result<Fit> {
    register_with_progress(source, target, config, &mut |_| {})
}

/// [`register`], telling `progress` where it is (for a progress bar on large clouds).
pub fn register_with_progress(
    source: &PointCloud,
    target: &PointCloud,
    config: &FgrConfig,
    progress: &mut dyn FnMut(Progress),
) -> Result<Fit> {
    register_prepared(
        &Prepared::new(source),
        &Prepared::new(target),
        config,
        progress,
    )
}

/// [`register_with_progress`] on prepared clouds: the trees of clouds small enough to be used
/// whole are those of the stages before, kept for the stages after.
pub fn register_prepared(
    source: &Prepared,
    target: &Prepared,
    config: &FgrConfig,
    progress: &mut dyn FnMut(Progress),
) -> Result<Fit> {
    check_clouds("fgr::register", source, target)?;
    let mut report = |step, done| progress(Progress { step, done });
    report("downsampling", 0.0);
    let (source_downsampled, target_downsampled) = (
        downsampled(source, config.max_points).map(Prepared::new),
        downsampled(target, config.max_points).map(Prepared::new),
    );
    let small_source = source_downsampled.as_ref().unwrap_or(source);
    let small_target = target_downsampled.as_ref().unwrap_or(target);
    // The fractions are rough shares of the time on a million points.
    report("features", 0.15);
    // The two clouds' features are independent: side by side when there are cores to spare.
    let of =
        |cloud: &Prepared| features(&cloud.points, cloud.index(), &config.normals, &config.fpfh);
    let (source_features, target_features) = rayon::join(|| of(small_source), || of(small_target));
    report("matching", 0.25);
    let matches = mutual_matches_reporting(&source_features, &target_features, &mut |rows| {
        report("matching", 0.25 + 0.3 * rows)
    });
    report("optimising", 0.55);
    let mut result = register_matches(small_source, small_target, matches, config)?;
    if source_downsampled.is_some() || target_downsampled.is_some() {
        // The transform is for the full clouds; so is its score.
        report("scoring", 0.6);
        let s = score(
            &source.points,
            target.index(),
            &result.t_target_source,
            config.maximum_correspondence_distance,
            None,
        );
        result = Fit::scored(
            result.t_target_source,
            result.iterations,
            result.converged,
            s,
        );
    }
    report("done", 1.0);
    Ok(result)
}

/// `cloud`'s voxel downsampling to at most `max_points` points, if it has more: the finest
/// voxel of the ladder `extent / √max_points · 1.25ᵏ` that leaves so few (a surface of side
/// `extent` fills about `(extent / voxel)²` cubes, so the ladder starts near the answer).
fn downsampled(cloud: &PointCloud, max_points: usize) -> Option<PointCloud> {
    // Cubes are aligned on the origin: however large, up to 8 may hold points.
    let max_points = max_points.max(8);
    if cloud.len() <= max_points {
        return None;
    }
    let (lo, hi) = rgm_geom::cloud::bounds(cloud.points.iter().copied());
    let extent = (hi - lo).max();
    if !(extent > 0.0) {
        // One point repeated.
        return Some(PointCloud::new(vec![cloud.points[0]]));
    }
    let mut voxel = extent / (max_points as f64).sqrt() / 1.25;
    loop {
        let small = cloud.voxel_downsampled(voxel);
        if small.len() <= max_points {
            return Some(small);
        }
        voxel *= 1.25;
    }
}

/// [`register`] with the features given (one per point of each cloud).
pub fn register_features(
    source: &PointCloud,
    target: &PointCloud,
    source_features: &[Fpfh],
    target_features: &[Fpfh],
    config: &FgrConfig,
) -> Result<Fit> {
    const OP: &str = "fgr::register_features";
    check_clouds(OP, source, target)?;
    if source_features.len() != source.len() {
        return Err(GeomError::LengthMismatch {
            op: OP,
            left: source.len(),
            right: source_features.len(),
        });
    }
    if target_features.len() != target.len() {
        return Err(GeomError::LengthMismatch {
            op: OP,
            left: target.len(),
            right: target_features.len(),
        });
    }
    register_matches(
        source,
        &Prepared::new(target),
        mutual_matches(source_features, target_features),
        config,
    )
}

/// Steps 3–6 from the mutual matches.
fn register_matches(
    source: &PointCloud,
    target: &Prepared,
    mut matches: Vec<(usize, usize)>,
    config: &FgrConfig,
) -> Result<Fit> {
    const OP: &str = "fgr::register";
    if !(config.division_factor > 1.0 && config.tuple_scale > 0.0 && config.tuple_scale <= 1.0) {
        return Err(GeomError::Degenerate {
            op: OP,
            why: format!(
                "division_factor must be > 1 and tuple_scale in (0, 1], got {} and {}",
                config.division_factor, config.tuple_scale
            ),
        });
    }
    if config.tuple_test {
        matches = tuple_test(&source.points, &target.points, &matches, config);
    }
    let (transform, iterations, converged) = if matches.len() < MIN_MATCHES {
        (RigidTransform::identity(), 0, false)
    } else {
        optimise(source, target, &matches, config)
    };
    let s = score(
        &source.points,
        target.index(),
        &transform,
        config.maximum_correspondence_distance,
        None,
    );
    Ok(Fit::scored(transform, iterations, converged, s))
}

/// Mutual nearest neighbours between the two feature sets: pairs (i, j) where j is the nearest
/// target feature of source feature i and i the nearest source feature of j. Sorted by i.
pub fn mutual_matches(source: &[Fpfh], target: &[Fpfh]) -> Vec<(usize, usize)> {
    mutual_matches_reporting(source, target, &mut |_| {})
}

/// A row's or a column's nearest so far: (squared distance, index).
type Nearest = (f64, usize);

/// [`mutual_matches`], telling `rows_done` the fraction of source rows done before each wave of
/// blocks (a block is 1/64 of the rows).
fn mutual_matches_reporting(
    source: &[Fpfh],
    target: &[Fpfh],
    rows_done: &mut dyn FnMut(f64),
) -> Vec<(usize, usize)> {
    let (row_best, col_best) = nearest_features_reporting(source, target, rows_done);
    row_best
        .iter()
        .enumerate()
        .filter(|&(i, &(_, j))| j != usize::MAX && col_best[j].1 == i)
        .map(|(i, &(_, j))| (i, j))
        .collect()
}

/// Each source feature's nearest target feature, as (i, j) sorted by i (exact, brute force;
/// ties to the lowest index): Open3D's matching without its mutual filter.
pub fn nearest_matches(source: &[Fpfh], target: &[Fpfh]) -> Vec<(usize, usize)> {
    let (row_best, _) = nearest_features_reporting(source, target, &mut |_| {});
    row_best
        .iter()
        .enumerate()
        .filter(|&(_, &(_, j))| j != usize::MAX)
        .map(|(i, &(_, j))| (i, j))
        .collect()
}

/// Each source feature's nearest target feature (N,) and each target feature's nearest source
/// feature (M,), telling `rows_done` as [`mutual_matches_reporting`] does.
fn nearest_features_reporting(
    source: &[Fpfh],
    target: &[Fpfh],
    rows_done: &mut dyn FnMut(f64),
) -> (Vec<Nearest>, Vec<Nearest>) {
    // One pass over the (N, M) squared distances keeps each row's and each column's minimum,
    // in blocks of rows that run side by side, a wave of them per thread at a time.
    let tiles = feature_tiles(target); // (⌈M/T⌉, 33, T)
    let mut row_best = vec![(f64::INFINITY, usize::MAX); source.len()]; // (N,)
    let mut col_best = vec![(f64::INFINITY, usize::MAX); target.len()]; // (M,)
    let rows_per_block = source.len().div_ceil(64).max(1);
    let blocks: Vec<(usize, &[Fpfh])> = source
        .chunks(rows_per_block)
        .enumerate()
        .map(|(b, rows)| (b * rows_per_block, rows))
        .collect();
    for wave in blocks.chunks(rayon::current_num_threads().max(1)) {
        rows_done(wave[0].0 as f64 / source.len() as f64);
        let found: Vec<(Vec<Nearest>, Vec<Nearest>)> = wave
            .par_iter()
            .map(|&(first, rows)| {
                let mut rows_best = vec![(f64::INFINITY, usize::MAX); rows.len()]; // (B,)
                let mut cols_best = vec![(f64::INFINITY, usize::MAX); target.len()]; // (M,)
                nearest_in_block(first, rows, &tiles, &mut rows_best, &mut cols_best);
                (rows_best, cols_best)
            })
            .collect();
        // Blocks merged in row order, strictly: a tie keeps the earlier block's row.
        for (&(first, _), (rows_best, cols_best)) in wave.iter().zip(found) {
            row_best[first..first + rows_best.len()].copy_from_slice(&rows_best);
            for (best, block) in col_best.iter_mut().zip(cols_best) {
                if block.0 < best.0 {
                    *best = block;
                }
            }
        }
    }
    (row_best, col_best)
}

/// Each row's nearest tile lane and each column's nearest row between the source rows `rows`
/// (the first is row `first`) and every target tile, into `rows_best` (B,) and `cols_best` (M,).
fn nearest_in_block(
    first: usize,
    rows: &[Fpfh],
    tiles: &[FeatureTile],
    rows_best: &mut [Nearest],
    cols_best: &mut [Nearest],
) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx512f") {
        // SAFETY: the CPU has AVX-512F.
        return unsafe { nearest_in_block_avx512(first, rows, tiles, rows_best, cols_best) };
    }
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2.
        return unsafe { nearest_in_block_avx2(first, rows, tiles, rows_best, cols_best) };
    }
    nearest_in_block_any(first, rows, tiles, rows_best, cols_best)
}

/// [`nearest_in_block`] compiled with AVX-512: a tile's eight lanes in one register.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn nearest_in_block_avx512(
    first: usize,
    rows: &[Fpfh],
    tiles: &[FeatureTile],
    rows_best: &mut [Nearest],
    cols_best: &mut [Nearest],
) {
    nearest_in_block_any(first, rows, tiles, rows_best, cols_best)
}

/// [`nearest_in_block`] compiled with AVX2: the same operations (never fused), wider vectors.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn nearest_in_block_avx2(
    first: usize,
    rows: &[Fpfh],
    tiles: &[FeatureTile],
    rows_best: &mut [Nearest],
    cols_best: &mut [Nearest],
) {
    nearest_in_block_any(first, rows, tiles, rows_best, cols_best)
}

/// [`nearest_in_block`] for any CPU.
#[inline(always)]
fn nearest_in_block_any(
    first: usize,
    rows: &[Fpfh],
    tiles: &[FeatureTile],
    rows_best: &mut [Nearest],
    cols_best: &mut [Nearest],
) {
    for (r, (a, best)) in rows.iter().zip(rows_best).enumerate() {
        for (tile, cols) in tiles.iter().zip(cols_best.chunks_mut(TILE)) {
            let d2 = tile_squared_distances(a, tile);
            // Strict `<` while rows and j ascend keeps the lowest index among ties: the row's,
            // the first lane at the tile's minimum (exact, in any order).
            let tile_min = d2.iter().copied().fold(f64::INFINITY, f64::min);
            if tile_min < best.0 {
                let l = d2.iter().position(|&d| d == tile_min).unwrap_or(0);
                *best = (tile_min, tile.first + l);
            }
            for (&d2, col) in d2.iter().zip(cols) {
                if d2 < col.0 {
                    *col = (d2, first + r);
                }
            }
        }
    }
}

/// Target features per tile of the matching: one source feature is compared with `TILE` target
/// features at once, lane by lane (independent sums, so vector instructions compute them).
const TILE: usize = 8;

/// `TILE` consecutive target features, channel-major: `channels[c][l]` is channel c of feature
/// `first + l`. The last tile's missing features are infinite: their lanes are never nearest.
struct FeatureTile {
    first: usize,
    channels: [[f64; TILE]; FPFH_LEN], // (33, T)
}

/// `features` in tiles of `TILE`. // (⌈M/T⌉,)
fn feature_tiles(features: &[Fpfh]) -> Vec<FeatureTile> {
    features
        .chunks(TILE)
        .enumerate()
        .map(|(t, chunk)| {
            let mut channels = [[f64::INFINITY; TILE]; FPFH_LEN];
            for (l, feature) in chunk.iter().enumerate() {
                for (c, v) in feature.iter().enumerate() {
                    channels[c][l] = *v;
                }
            }
            FeatureTile {
                first: t * TILE,
                channels,
            }
        })
        .collect()
}

/// `‖a − b‖²` for each feature b of `tile`, each with four independent partial sums (a serial
/// sum would stall on each addition) joined as `(s₀ + s₁) + (s₂ + s₃) + rest`. // (T,)
#[inline(always)]
fn tile_squared_distances(a: &Fpfh, tile: &FeatureTile) -> [f64; TILE] {
    let mut acc = [[0.0; TILE]; 4]; // (4, T)
    let whole = FPFH_LEN / 4 * 4;
    for (xs, columns) in a[..whole]
        .chunks_exact(4)
        .zip(tile.channels[..whole].chunks_exact(4))
    {
        for ((sums, x), column) in acc.iter_mut().zip(xs).zip(columns) {
            for (s, y) in sums.iter_mut().zip(column) {
                let d = x - y;
                *s += d * d;
            }
        }
    }
    let mut rest = [0.0; TILE];
    for (x, column) in a[whole..].iter().zip(&tile.channels[whole..]) {
        for (s, y) in rest.iter_mut().zip(column) {
            let d = x - y;
            *s += d * d;
        }
    }
    std::array::from_fn(|l| (acc[0][l] + acc[1][l]) + (acc[2][l] + acc[3][l]) + rest[l])
}

/// The tuple test of step 3 on `matches` (source index, target index): up to `100 · len`
/// random triples drawn from one seeded stream, tested in the order drawn.
///
/// Step c of [`lockstep::two_halves`] draws chunk c of the triples (one half) beside the test of
/// chunk c − 1 (the other), in two buffers by parity; what is kept is what one loop keeps.
fn tuple_test(
    source: &[Point3<f64>],
    target: &[Point3<f64>],
    matches: &[(usize, usize)],
    config: &FgrConfig,
) -> Vec<(usize, usize)> {
    let n = matches.len();
    let trials = 100 * n;
    let chunks = trials.div_ceil(TUPLE_CHUNK);
    let rng = Mutex::new(StdRng::seed_from_u64(config.seed));
    let drawn = [(); 2].map(|_| Mutex::new(Vec::<[usize; 3]>::new())); // (≤ TUPLE_CHUNK,) each
    let kept = Mutex::new(Vec::with_capacity(
        3 * config.maximum_tuple_count.min(trials),
    ));
    let full = AtomicBool::new(false);
    lockstep::two_halves(
        chunks + 1,
        trials >= SIDE_BY_SIDE_TRIALS,
        || (),
        |_, c, half| {
            if full.load(Ordering::Relaxed) {
                return;
            }
            if half == 0 && c < chunks {
                let mut rng = rng.lock().expect("no half panicked");
                let mut picks = drawn[c % 2].lock().expect("no half panicked");
                picks.clear();
                let count = TUPLE_CHUNK.min(trials - c * TUPLE_CHUNK);
                picks.extend((0..count).map(|_| {
                    [
                        rng.gen_range(0..n),
                        rng.gen_range(0..n),
                        rng.gen_range(0..n),
                    ]
                }));
            } else if half == 1 && c > 0 {
                let picks = drawn[(c - 1) % 2].lock().expect("no half panicked");
                let mut kept = kept.lock().expect("no half panicked");
                for &[i, j, k] in picks.iter() {
                    let triple = [matches[i], matches[j], matches[k]];
                    if consistent(source, target, triple, config.tuple_scale) {
                        kept.extend_from_slice(&triple);
                        if kept.len() >= 3 * config.maximum_tuple_count {
                            full.store(true, Ordering::Relaxed);
                            break;
                        }
                    }
                }
            }
        },
    );
    kept.into_inner().expect("no half panicked")
}

/// Whether the three matches (source index, target index) of `triple` span triangles whose
/// sides agree between the clouds within the factor `scale` (`scale·l_s < l_t < l_s/scale`).
fn consistent(
    source: &[Point3<f64>],
    target: &[Point3<f64>],
    triple: [(usize, usize); 3],
    scale: f64,
) -> bool {
    let agrees = |ls: f64, lt: f64| ls * scale < lt && lt < ls / scale;
    let side = |pts: &[Point3<f64>], a: usize, b: usize| (pts[a] - pts[b]).norm();
    let [(s0, t0), (s1, t1), (s2, t2)] = triple;
    agrees(side(source, s0, s1), side(target, t0, t1))
        && agrees(side(source, s1, s2), side(target, t1, t2))
        && agrees(side(source, s2, s0), side(target, t2, t0))
}

/// Triples drawn, or tested, per step of [`tuple_test`].
const TUPLE_CHUNK: usize = 512;

/// Triples from which [`tuple_test`] asks for a second worker.
const SIDE_BY_SIDE_TRIALS: usize = 4096;

/// Steps 4–6: (t_target_source, iterations, every solve succeeded).
fn optimise(
    source: &PointCloud,
    target: &PointCloud,
    matches: &[(usize, usize)],
    config: &FgrConfig,
) -> (RigidTransform, usize, bool) {
    let mean_s = source.centroid().coords;
    let mean_t = target.centroid().coords;
    let extent = |c: &PointCloud, m: Vector3<f64>| {
        c.points
            .iter()
            .map(|p| (p.coords - m).norm())
            .fold(0.0, f64::max)
    };
    let scale = extent(source, mean_s).max(extent(target, mean_t));
    let scale_global = if config.use_absolute_scale {
        1.0
    } else {
        scale
    };
    // Open3D's normalisation also returns a `scale_start` (1, or the extent with absolute
    // scale) but passes `scale_global` to the optimisation as the first μ; followed here.
    let mu = scale_global;
    if !(scale_global > 0.0) {
        // Both clouds are single points repeated: nothing to rotate.
        return (RigidTransform::identity(), 0, false);
    }
    // Normalised matched points: p from the source (fixed), q from the target (moved). // (P,)
    let p: Vec<Vector3<f64>> = matches
        .iter()
        .map(|&(i, _)| (source.points[i].coords - mean_s) / scale_global)
        .collect();
    let q: Vec<Vector3<f64>> = matches
        .iter()
        .map(|&(_, j)| (target.points[j].coords - mean_t) / scale_global)
        .collect();

    // Iteration i's μ, which depends on the settings alone.
    let mus: Vec<f64> = (0..config.iteration_number)
        .scan(mu, |mu, iteration| {
            let this = *mu;
            if config.decrease_mu
                && iteration % 4 == 0
                && *mu > config.maximum_correspondence_distance
            {
                *mu /= config.division_factor;
            }
            Some(this)
        })
        .collect();
    let (trans, solved) = gauss_newton(&p, &q, &mus);
    let iterations = mus.len();
    // Back to the original scale: target → source is q ↦ R q − R μ_t + s t + μ_s; invert it.
    let r: Matrix3<f64> = trans.rotation;
    let t_source_target =
        RigidTransform::new(r, -(r * mean_t) + trans.translation * scale_global + mean_s);
    (t_source_target.inverse(), iterations, solved)
}

/// Steps 5–6 in Open3D's normalised frame: one Gauss–Newton step per entry of `mus` (its μ) on
/// the matches `p` (source, fixed) and `q` (target, moved), (P,) each; (the transform moving
/// the normalised target onto the normalised source, every solve succeeded).
fn gauss_newton(p: &[Vector3<f64>], q: &[Vector3<f64>], mus: &[f64]) -> (RigidTransform, bool) {
    // Gauss–Newton on Σ l·‖r‖², r = p − (q + ω × q + t) = (p − q) + [q]ₓ ω − t, so
    // J = [[q]ₓ, −I] and the normal equations are weighted sums over the matches:
    // JᵀJ = [[|q|² I − q qᵀ, [q]ₓ], [−[q]ₓ, I]], Jᵀr = [r × q, −r] — Open3D's three rank-one
    // updates per match, summed in closed form.
    //
    // Step i of [`lockstep::two_halves`] makes iteration i's sums: one half those of Jᵀr and
    // [q]ₓ, the other those of |q|² I − q qᵀ. Each worker keeps a copy of q of its own, moved by
    // every step solved so far, so that no worker writes what the other reads (a write to lines
    // the other core holds costs more than the step).
    let iterations = mus.len();
    let sums = [(); 2].map(|_| Mutex::new((Sums::default(), Matrix3::zeros()))); // by parity of i
    let steps: Vec<OnceLock<Option<RigidTransform>>> =
        (0..iterations).map(|_| OnceLock::new()).collect();
    let step_of = |i: usize| {
        *steps[i].get_or_init(|| {
            let (sum, sqq) = *sums[i % 2].lock().expect("no half panicked");
            sum.step(&sqq)
        })
    };
    lockstep::two_halves(
        iterations,
        p.len() >= SIDE_BY_SIDE_MATCHES,
        || (q.to_vec(), 0), // (q moved by the first `moved` steps, moved)
        |(q, moved), i, half| {
            for done in *moved..i {
                // A failed solve is a zero step, as Open3D's.
                if let Some(delta) = step_of(done) {
                    for qi in q.iter_mut() {
                        *qi = delta.rotation * *qi + delta.translation;
                    }
                }
            }
            *moved = i;
            let slot = &sums[i % 2];
            if half == 0 {
                let sum = Sums::of(p, q, mus[i]);
                slot.lock().expect("no half panicked").0 = sum;
            } else {
                let sqq = rotation_block(p, q, mus[i]);
                slot.lock().expect("no half panicked").1 = sqq;
            }
        },
    );
    // `trans` maps normalised target points onto normalised source points.
    let mut trans = RigidTransform::identity();
    let mut solved = true;
    for i in 0..iterations {
        match step_of(i) {
            Some(delta) => trans = delta.compose(&trans),
            None => solved = false,
        }
    }
    (trans, solved)
}

/// Matches from which [`gauss_newton`] asks for a second worker.
const SIDE_BY_SIDE_MATCHES: usize = 512;

/// The weight l² of a match in the Geman–McClure objective at scale μ, l = μ / (‖r‖² + μ).
fn weight(r: &Vector3<f64>, mu: f64) -> f64 {
    let l = mu / (r.norm_squared() + mu);
    l * l
}

/// One Gauss–Newton iteration's weighted sums over the matches but the rotation block.
#[derive(Clone, Copy, Default)]
struct Sums {
    sw: f64,           // Σ w
    sq: Vector3<f64>,  // Σ w q
    sr: Vector3<f64>,  // Σ w r
    srq: Vector3<f64>, // Σ w r × q
}

impl Sums {
    /// The sums over the matches `p` (source, fixed) and `q` (target, moved), in order.
    fn of(p: &[Vector3<f64>], q: &[Vector3<f64>], mu: f64) -> Self {
        let mut sums = Self::default();
        for (pi, qi) in p.iter().zip(q) {
            let r = pi - qi;
            let w = weight(&r, mu);
            sums.sw += w;
            sums.sq += w * qi;
            sums.sr += w * r;
            sums.srq += w * r.cross(qi);
        }
        sums
    }

    /// The step that solves the normal equations with rotation block `sqq`; `None` when they
    /// cannot be solved.
    fn step(&self, sqq: &Matrix3<f64>) -> Option<RigidTransform> {
        let sq_cross = self.sq.cross_matrix();
        let mut jtj = Matrix6::<f64>::zeros(); // (6, 6)
        jtj.fixed_view_mut::<3, 3>(0, 0).copy_from(sqq);
        jtj.fixed_view_mut::<3, 3>(0, 3).copy_from(&sq_cross);
        jtj.fixed_view_mut::<3, 3>(3, 0).copy_from(&(-sq_cross));
        jtj.fixed_view_mut::<3, 3>(3, 3)
            .copy_from(&Matrix3::from_diagonal_element(self.sw));
        let (srq, sr) = (self.srq, self.sr);
        let jtr = Vector6::new(srq.x, srq.y, srq.z, -sr.x, -sr.y, -sr.z); // (6,)
        let x = jtj
            .cholesky()
            .map(|c| -c.solve(&jtr))
            .filter(|x| x.iter().all(|v| v.is_finite()))?;
        Some(RigidTransform::new(
            rotation_xyz_extrinsic(x[0], x[1], x[2]),
            Vector3::new(x[3], x[4], x[5]),
        ))
    }
}

/// Σ w (|q|² I − q qᵀ), the rotation block of JᵀJ, over the matches `p`, `q` in order. The
/// block is symmetric, its (a, b) and (b, a) terms the same numbers, so six sums make it.
fn rotation_block(p: &[Vector3<f64>], q: &[Vector3<f64>], mu: f64) -> Matrix3<f64> {
    let mut diagonal = [0.0; 3]; // Σ w (|q|² − q_a²)
    let mut off = [0.0; 3]; // Σ w (0 − q_a q_b) for (a, b) = (0, 1), (0, 2), (1, 2)
    for (pi, qi) in p.iter().zip(q) {
        let w = weight(&(pi - qi), mu);
        let n = qi.norm_squared();
        for a in 0..3 {
            diagonal[a] += w * (n - qi[a] * qi[a]);
        }
        for (k, (a, b)) in [(0, 1), (0, 2), (1, 2)].into_iter().enumerate() {
            off[k] += w * (0.0 - qi[a] * qi[b]);
        }
    }
    Matrix3::new(
        diagonal[0],
        off[0],
        off[1], //
        off[0],
        diagonal[1],
        off[2], //
        off[1],
        off[2],
        diagonal[2],
    )
}

/// Fast Global Registration on FPFH features ([`crate::methods::fgr`]).
impl<E: From<GeomError>> Registrar<E> for FgrConfig {
    fn id(&self) -> MethodId {
        MethodId::plain(NAME)
    }

    fn register_prepared(
        &mut self,
        source: &Prepared,
        target: &Prepared,
        progress: &mut dyn FnMut(Progress),
    ) -> std::result::Result<Registration, E> {
        let start = Instant::now();
        let result = register_prepared(source, target, self, progress)?;
        let distance = self.maximum_correspondence_distance;
        Ok(Registration::scored_within(
            result, source, target, distance, start,
        ))
    }
}

#[cfg(test)]
mod tests;
