//! Point clouds.

use nalgebra::{Point3, Vector3};
use std::borrow::Cow;

use crate::RigidTransform;

/// A cloud of N points in 3-D.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PointCloud {
    /// The points. // (N,)
    pub points: Vec<Point3<f64>>,
}

impl PointCloud {
    /// A cloud from its points.
    pub fn new(points: Vec<Point3<f64>>) -> Self {
        Self { points }
    }

    /// A cloud from f32 rows (x, y, z), as stored in `.npy` files and used by the network.
    pub fn from_f32_rows(rows: &[[f32; 3]]) -> Self {
        Self::new(
            rows.iter()
                .map(|r| Point3::new(r[0] as f64, r[1] as f64, r[2] as f64))
                .collect(),
        )
    }

    /// The points as f32 rows (x, y, z). // (N, 3)
    pub fn to_f32_rows(&self) -> Vec<[f32; 3]> {
        self.points
            .iter()
            .map(|p| [p.x as f32, p.y as f32, p.z as f32])
            .collect()
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// True when the cloud has no point.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// Mean of the points; the origin for an empty cloud.
    pub fn centroid(&self) -> Point3<f64> {
        if self.points.is_empty() {
            return Point3::origin();
        }
        let sum: Vector3<f64> = self.points.iter().map(|p| p.coords).sum();
        Point3::from(sum / self.points.len() as f64)
    }

    /// The indices, in order, of the points that are not far outliers: those within `factor`
    /// times the median distance from the coordinate-wise median. A few stray points anywhere
    /// (a scanner's returns at 1e5) move neither median, so they cannot shrink or shift what
    /// is kept; every point is kept when that median distance is 0 or not finite.
    pub fn near_indices(&self, factor: f64) -> Vec<usize> {
        let n = self.points.len();
        if n == 0 {
            return Vec::new();
        }
        let middle = Point3::from(Vector3::from_fn(|c, _| {
            median(self.points.iter().map(|p| p[c]).collect())
        }));
        let distances: Vec<f64> = self.points.iter().map(|p| length(&(p - middle))).collect(); // (N,)
        let typical = median(distances.clone());
        if !(typical > 0.0 && typical.is_finite()) {
            return (0..n).collect();
        }
        (0..n)
            .filter(|&i| distances[i] <= factor * typical)
            .collect()
    }

    /// The cloud moved by `transform`.
    pub fn transformed(&self, transform: &RigidTransform) -> Self {
        Self::new(self.points.iter().map(|p| transform.apply(p)).collect())
    }

    /// The cloud with its points reordered: `out[i] = self[order[i]]`.
    pub fn select(&self, order: &[usize]) -> Self {
        Self::new(order.iter().map(|&i| self.points[i]).collect())
    }

    /// Indices of at most `count` points picked by farthest-point sampling: the first point,
    /// then again and again the point farthest from those picked (ties to the lowest index),
    /// until `count` are picked or every point left coincides with a picked one; every index,
    /// in order, when the cloud has no more than `count` points. It evens out the density of a
    /// cloud (a scan dense in one place and sparse in another, duplicated points) without
    /// choosing a grid size, and is deterministic.
    pub fn farthest_point_indices(&self, count: usize) -> Vec<usize> {
        let n = self.points.len();
        if n <= count {
            return (0..n).collect();
        }
        // Runs of consecutive points with their bounding boxes and largest distance: a pick no
        // nearer to a run's box than that distance lowers none of its points' (the box's
        // distance, summed as a point's is, is never above any of them), so the run is
        // skipped, and the picks are those of a pass over every point.
        //
        // One axis at a time, so that the pass over a run vectorises; the farthest is then the
        // first point at the largest distance.
        let axis = |a: usize| -> Vec<f64> { self.points.iter().map(|p| p[a]).collect() };
        let axes = [axis(0), axis(1), axis(2)]; // (3, N)
        let mut runs: Vec<FarthestRun> = (0..n)
            .step_by(FARTHEST_RUN)
            .map(|start| {
                let end = (start + FARTHEST_RUN).min(n);
                let (lo, hi) = bounds(self.points[start..end].iter().copied());
                FarthestRun {
                    start,
                    end,
                    lo: lo.into(),
                    hi: hi.into(),
                    largest: f64::INFINITY,
                }
            })
            .collect();
        let mut picked = Vec::with_capacity(count);
        let mut nearest = vec![f64::INFINITY; n]; // (N,) squared distance to the picked points
        let mut next = 0;
        while picked.len() < count {
            picked.push(next);
            let p = [axes[0][next], axes[1][next], axes[2][next]];
            for run in &mut runs {
                if box_squared_distance(p, run.lo, run.hi) >= run.largest {
                    continue;
                }
                let (start, end) = (run.start, run.end);
                let coordinates = [0, 1, 2].map(|a| &axes[a][start..end]);
                run.largest = nearer_to(&mut nearest[start..end], coordinates, p);
            }
            let farthest = runs
                .iter()
                .fold(0.0, |m, run| if run.largest > m { run.largest } else { m });
            if farthest <= 0.0 {
                break;
            }
            // The first run holding the largest distance holds its first point.
            let run = runs
                .iter()
                .find(|run| run.largest == farthest)
                .expect("the largest distance is a run's");
            next = run.start
                + nearest[run.start..run.end]
                    .iter()
                    .position(|&d| d == farthest)
                    .expect("a run's largest distance is one of its points'");
        }
        picked
    }

    /// One point per seed: the mean of the points of this cloud nearer to that seed than to
    /// any other (its Voronoi cell; one step of Lloyd's k-means); seeds whose cell is empty are
    /// left out. After farthest-point seeds it thins a dense cloud to evenly spread points with
    /// its noise averaged out, cut along other borders than a voxel grid's.
    pub fn cell_means(&self, seeds: &[Point3<f64>]) -> Self {
        let index = crate::KnnIndex::new(seeds);
        let mut sums = vec![(Vector3::zeros(), 0usize); seeds.len()]; // (S,) sum and count
        for p in &self.points {
            let (cell, _) = index.nearest(p);
            sums[cell].0 += p.coords;
            sums[cell].1 += 1;
        }
        Self::new(
            sums.into_iter()
                .filter(|&(_, n)| n > 0)
                .map(|(sum, n)| Point3::from(sum / n as f64))
                .collect(),
        )
    }

    /// The index of the first point met in each occupied cube of side `voxel` (cubes aligned on
    /// the origin), in the order the cubes are first met: a thinning that keeps points as they
    /// are, so that what belongs to each (its scan) goes with it.
    pub fn voxel_firsts(&self, voxel: f64) -> Vec<usize> {
        let mut seen = rustc_hash::FxHashSet::default();
        (0..self.len())
            .filter(|&i| {
                let key = self.points[i].coords.map(|v| (v / voxel).floor() as i64);
                seen.insert((key.x, key.y, key.z))
            })
            .collect()
    }

    /// One point per occupied cube of side `voxel` (cubes aligned on the origin): the mean of
    /// the cube's points, as Open3D's `voxel_down_sample`; in the order the cubes are first met.
    pub fn voxel_downsampled(&self, voxel: f64) -> Self {
        Cubes::of(self, voxel).means(|_| true)
    }

    /// [`PointCloud::voxel_downsampled`] without the cubes that hold only stray points
    /// ([`PointCloud::non_stray_indices`]): the same means of the cubes kept, in the same order.
    pub fn voxel_downsampled_without_strays(&self, voxel: f64, strays: &Strays) -> Self {
        let cubes = Cubes::of(self, voxel);
        let kept = cubes.kept(self, strays);
        cubes.means(|cube| kept[cube])
    }

    /// The indices, in order, of the points that are not strays at the scale of cubes of side
    /// `voxel` by `strays`' rule ([`Strays`]). What a thinning keeps of the strays,
    /// farthest-point sampling picks first.
    pub fn non_stray_indices(&self, voxel: f64, strays: &Strays) -> Vec<usize> {
        let cubes = Cubes::of(self, voxel);
        let kept = cubes.kept(self, strays);
        let kept_point = |p: &Point3<f64>| kept[cubes.cube_of[&cubes.key(p)]];
        (0..self.len())
            .filter(|&i| kept_point(&self.points[i]))
            .collect()
    }
}

/// Which points of a cloud are strays, at the scale of cubes of one side
/// ([`PointCloud::non_stray_indices`]). A cube is sparse when it holds fewer than `share` of the
/// points of a typical point's cube (the cube of the median point, the points ordered by their
/// cube's count); the points of a sparse cube whose 26 neighbours are all sparse too are strays
/// when none of them has two other points within `alone` of the side. A scanner's spurious returns
/// scattered through an object's box lie alone, while a surface's cubes hold many points, a
/// surface's edge lies beside its dense cubes, and a LiDAR sweep's far rings, sparse beside its
/// near ones, hold their points close together along each ring.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Strays {
    /// Of a typical point's cube's count: below it a cube is sparse.
    pub share: f64,
    /// Of the cube's side, at most 1 (the 27 cubes around a point hold every point that near):
    /// within it a point has company.
    pub alone: f64,
}

/// A cloud's occupied cubes of one side, aligned on the origin, in the order first met.
struct Cubes {
    side: f64,
    /// Each cube's integer coordinates. // (V,)
    keys: Vec<[i64; 3]>,
    /// The cube of each key.
    cube_of: rustc_hash::FxHashMap<[i64; 3], usize>,
    /// The sum of each cube's points and their count. // (V,)
    sums: Vec<(Vector3<f64>, usize)>,
}

impl Cubes {
    fn of(cloud: &PointCloud, side: f64) -> Self {
        // Fx hashing: the cubes' order (of first points) does not depend on the hasher.
        let mut cubes = Self {
            side,
            keys: Vec::new(),
            cube_of: rustc_hash::FxHashMap::default(),
            sums: Vec::new(),
        };
        for p in &cloud.points {
            let key = cubes.key(p);
            let cube = *cubes.cube_of.entry(key).or_insert_with(|| {
                cubes.keys.push(key);
                cubes.sums.push((Vector3::zeros(), 0));
                cubes.sums.len() - 1
            });
            cubes.sums[cube].0 += p.coords;
            cubes.sums[cube].1 += 1;
        }
        cubes
    }

    /// The integer coordinates of the cube that holds `p`.
    fn key(&self, p: &Point3<f64>) -> [i64; 3] {
        p.coords.map(|v| (v / self.side).floor() as i64).into()
    }

    /// The mean of each cube that `keep` keeps, in order.
    fn means(&self, keep: impl Fn(usize) -> bool) -> PointCloud {
        let means = self.sums.iter().enumerate().filter(|&(cube, _)| keep(cube));
        PointCloud::new(
            means
                .map(|(_, &(sum, n))| Point3::from(sum / n as f64))
                .collect(),
        )
    }

    /// Whether each cube holds points that are not strays ([`Strays`]); `cloud` is the cloud
    /// the cubes were made of.
    fn kept(&self, cloud: &PointCloud, strays: &Strays) -> Vec<bool> {
        let mut counts: Vec<usize> = self.sums.iter().map(|&(_, n)| n).collect(); // (V,)
        counts.sort_unstable();
        let points: usize = self.sums.iter().map(|&(_, n)| n).sum();
        let mut seen = 0;
        let typical = counts
            .into_iter()
            .find(|&n| {
                seen += n;
                2 * seen >= points
            })
            .unwrap_or(0);
        let dense = |cube: usize| self.sums[cube].1 as f64 >= strays.share * typical as f64;
        let around = |[x, y, z]: [i64; 3]| {
            (-1..=1).flat_map(move |dx| {
                (-1..=1).flat_map(move |dy| (-1..=1).map(move |dz| [x + dx, y + dy, z + dz]))
            })
        };
        let around_cubes =
            |cube: usize| around(self.keys[cube]).filter_map(|key| self.cube_of.get(&key).copied());
        let mut kept: Vec<bool> = (0..self.keys.len())
            .map(|cube| dense(cube) || around_cubes(cube).any(dense))
            .collect(); // (V,)
        if kept.iter().all(|&k| k) {
            return kept;
        }
        // A sparse region's cube stays when one of its points has two others near it (a ring's
        // neighbours on either side of it; two strays may lie close by chance, three seldom).
        // The reach is within a side, so the 27 cubes around a point hold every point in it.
        let members = self.members(cloud);
        let reach = (strays.alone * self.side).powi(2);
        let between_two = |i: usize, cube: usize| {
            let p = cloud.points[i];
            around_cubes(cube)
                .flat_map(|other| members.of(other))
                .filter(|&&j| j != i && (cloud.points[j] - p).norm_squared() < reach)
                .nth(1)
                .is_some()
        };
        for (cube, kept) in kept.iter_mut().enumerate() {
            if !*kept {
                *kept = members.of(cube).iter().any(|&i| between_two(i, cube));
            }
        }
        kept
    }

    /// The points of each cube of `cloud` (the cloud they were made of).
    fn members(&self, cloud: &PointCloud) -> Members {
        let mut starts = Vec::with_capacity(self.sums.len() + 1); // (V + 1,)
        let mut total = 0;
        starts.push(0);
        for &(_, n) in &self.sums {
            total += n;
            starts.push(total);
        }
        let mut next = starts.clone(); // (V + 1,)
        let mut order = vec![0; total]; // (N,)
        for (i, p) in cloud.points.iter().enumerate() {
            let cube = self.cube_of[&self.key(p)];
            order[next[cube]] = i;
            next[cube] += 1;
        }
        Members { starts, order }
    }
}

/// The points of each cube ([`Cubes::members`]): one list of point indices ordered by cube.
struct Members {
    /// Where each cube's points start in `order`, and where the last cube's end. // (V + 1,)
    starts: Vec<usize>,
    order: Vec<usize>, // (N,)
}

impl Members {
    fn of(&self, cube: usize) -> &[usize] {
        &self.order[self.starts[cube]..self.starts[cube + 1]]
    }
}

/// The corners of the box that holds `points` (lowest and highest coordinate on each axis);
/// infinities the wrong way round for none.
pub fn bounds(points: impl IntoIterator<Item = Point3<f64>>) -> (Vector3<f64>, Vector3<f64>) {
    points.into_iter().fold(
        (
            Vector3::repeat(f64::INFINITY),
            Vector3::repeat(f64::NEG_INFINITY),
        ),
        |(low, high), p| (low.inf(&p.coords), high.sup(&p.coords)),
    )
}

/// At most `most` of `points`, spread evenly over them (every k-th, from the first): every one
/// when there are no more. The sample a measure takes of a dense cloud.
pub fn evenly(points: &[Point3<f64>], most: usize) -> impl Iterator<Item = &Point3<f64>> + Clone {
    points
        .iter()
        .step_by(points.len().div_ceil(most.max(1)).max(1))
}

/// The median of `values` (the upper one of an even count); NaN for none.
pub fn median(mut values: Vec<f64>) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    let middle = values.len() / 2;
    *values.select_nth_unstable_by(middle, f64::total_cmp).1
}

/// The length of `v` at any finite scale: divided by its largest coordinate before squaring,
/// which overflows to infinity beyond about 1e154 and underflows to 0 below about 1e-162.
pub fn length(v: &Vector3<f64>) -> f64 {
    let largest = v.amax();
    if largest == 0.0 || !largest.is_finite() {
        return largest;
    }
    largest * (v / largest).norm()
}

impl From<Vec<Point3<f64>>> for PointCloud {
    fn from(points: Vec<Point3<f64>>) -> Self {
        Self::new(points)
    }
}

/// Points per run of [`PointCloud::farthest_point_indices`]: a scan's consecutive points lie
/// close together, so a run's box is small and most picks pass it by.
const FARTHEST_RUN: usize = 128;

/// Consecutive points `start..end` of a cloud, their bounding box, and the largest of their
/// squared distances to the points picked so far.
struct FarthestRun {
    start: usize,
    end: usize,
    lo: [f64; 3],
    hi: [f64; 3],
    largest: f64,
}

/// The squared distance from `p` to the box `lo`..`hi`, summed as [`nearer_to`] sums a point's:
/// each axis's gap is never above that axis's difference to a point of the box (rounding is
/// monotonic), and so the sum is never above the point's.
fn box_squared_distance(p: [f64; 3], lo: [f64; 3], hi: [f64; 3]) -> f64 {
    let gap = |a: usize| {
        if p[a] < lo[a] {
            lo[a] - p[a]
        } else if p[a] > hi[a] {
            p[a] - hi[a]
        } else {
            0.0
        }
    };
    let (gx, gy, gz) = (gap(0), gap(1), gap(2));
    gx * gx + gy * gy + gz * gz
}

/// Lowers each of `nearest` (N,) to the squared distance from its point (`axes`: (3, N)) to
/// `p` where that is nearer, and returns the largest result.
fn nearer_to(nearest: &mut [f64], axes: [&[f64]; 3], p: [f64; 3]) -> f64 {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2.
        return unsafe { nearer_to_avx2(nearest, axes, p) };
    }
    nearer_to_any(nearest, axes, p)
}

/// [`nearer_to`] compiled with AVX2: the same operations (never fused), wider vectors.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn nearer_to_avx2(nearest: &mut [f64], axes: [&[f64]; 3], p: [f64; 3]) -> f64 {
    nearer_to_any(nearest, axes, p)
}

/// [`nearer_to`] for any CPU: eight points a step, each lane keeping its own largest.
#[inline(always)]
fn nearer_to_any(nearest: &mut [f64], [xs, ys, zs]: [&[f64]; 3], [px, py, pz]: [f64; 3]) -> f64 {
    const LANES: usize = 8;
    let step = |d: &mut f64, x: f64, y: f64, z: f64, largest: &mut f64| {
        let (dx, dy, dz) = (x - px, y - py, z - pz);
        let squared = dx * dx + dy * dy + dz * dz;
        let nearer = if squared < *d { squared } else { *d };
        *d = nearer;
        *largest = if nearer > *largest { nearer } else { *largest };
    };
    let n = nearest.len();
    let whole = n / LANES * LANES;
    let mut largest = [0.0f64; LANES];
    for (((d, x), y), z) in nearest[..whole]
        .chunks_exact_mut(LANES)
        .zip(xs.chunks_exact(LANES))
        .zip(ys.chunks_exact(LANES))
        .zip(zs.chunks_exact(LANES))
    {
        for l in 0..LANES {
            step(&mut d[l], x[l], y[l], z[l], &mut largest[l]);
        }
    }
    let mut rest = 0.0f64;
    for i in whole..n {
        step(&mut nearest[i], xs[i], ys[i], zs[i], &mut rest);
    }
    largest.iter().fold(rest, |m, &d| if d > m { d } else { m })
}

// A cloud borrowed or owned, as a `Cow` (what rgm-registration's `Prepared::new` takes).
impl<'a> From<&'a PointCloud> for Cow<'a, PointCloud> {
    fn from(cloud: &'a PointCloud) -> Self {
        Cow::Borrowed(cloud)
    }
}

impl From<PointCloud> for Cow<'_, PointCloud> {
    fn from(cloud: PointCloud) -> Self {
        Cow::Owned(cloud)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lengths_hold_at_any_scale() {
        for k in [1e-200, 1e-3, 1.0, 1e200] {
            let v = Vector3::new(3.0, -4.0, 12.0) * k;
            assert!((length(&v) / (13.0 * k) - 1.0).abs() < 1e-15, "{k}");
        }
        assert_eq!(length(&Vector3::zeros()), 0.0);
    }

    #[test]
    fn far_points_are_not_near_and_do_not_move_what_is() {
        // A 10 × 10 × 10 grid of unit spacing, then one point at 1e5 and one at -1e9.
        let grid: Vec<Point3<f64>> = (0..1000)
            .map(|i| Point3::new((i % 10) as f64, (i / 10 % 10) as f64, (i / 100) as f64))
            .collect();
        let mut cloud = PointCloud::new(grid);
        let all: Vec<usize> = (0..1000).collect();
        assert_eq!(cloud.near_indices(4.0), all);
        cloud.points.push(Point3::new(1e5, 0.0, 0.0));
        cloud.points.push(Point3::new(0.0, -1e9, 3.0));
        assert_eq!(cloud.near_indices(4.0), all);
        // The median is (5, 5, 5), the median distance from it 5: a factor of 1.5 keeps the
        // points within 7.5, leaving out the corner (0, 0, 0) at 8.66.
        let tight = cloud.near_indices(1.5);
        assert!(!tight.contains(&0) && tight.contains(&555) && tight.len() < 1000);
        // Mostly coincident points: all kept.
        let same = PointCloud::new(vec![Point3::new(1.0, 2.0, 3.0); 5]);
        assert_eq!(same.near_indices(4.0), vec![0, 1, 2, 3, 4]);
        assert!(PointCloud::default().near_indices(4.0).is_empty());
    }

    #[test]
    fn cell_means_average_each_seeds_nearest_points() {
        let c = PointCloud::new(vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(0.2, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(1.0, 0.4, 0.0),
            Point3::new(0.9, 0.0, 0.0),
        ]);
        // The middle seed is nearest to no point: left out.
        let seeds = [
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(0.5, 5.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
        ];
        let m = c.cell_means(&seeds);
        assert_eq!(m.len(), 2);
        assert!((m.points[0] - Point3::new(0.1, 0.0, 0.0)).norm() < 1e-12);
        assert!((m.points[1] - Point3::new(2.9 / 3.0, 0.4 / 3.0, 0.0)).norm() < 1e-12);
    }

    #[test]
    fn voxel_downsampling_keeps_one_mean_per_cube() {
        let c = PointCloud::new(vec![
            Point3::new(0.1, 0.1, 0.1),
            Point3::new(0.3, 0.3, 0.1),
            Point3::new(1.2, 0.0, 0.0),
            Point3::new(-0.2, 0.0, 0.0),
            Point3::new(0.2, 0.2, 0.4),
        ]);
        let d = c.voxel_downsampled(0.5);
        assert_eq!(d.len(), 3);
        assert!((d.points[0] - Point3::new(0.2, 0.2, 0.2)).norm() < 1e-15);
        assert_eq!(d.points[1], Point3::new(1.2, 0.0, 0.0));
        assert_eq!(d.points[2], Point3::new(-0.2, 0.0, 0.0));
        // The same cubes, each kept as its first point.
        assert_eq!(c.voxel_firsts(0.5), vec![0, 2, 3]);
    }

    const STRAYS: Strays = Strays {
        share: 0.2,
        alone: 0.1,
    };

    #[test]
    fn strays_are_the_lone_points_of_sparse_cubes_away_from_dense_ones() {
        // A square of 100 × 100 points 0.01 apart: cubes of 0.1 hold 100 points each.
        let mut points: Vec<Point3<f64>> = (0..100)
            .flat_map(|i| {
                (0..100).map(move |j| {
                    Point3::new(0.005 + 0.01 * i as f64, 0.005 + 0.01 * j as f64, 0.05)
                })
            })
            .collect();
        // Its edge: a point alone in its cube, beside a dense one.
        points.push(Point3::new(1.005, 0.5, 0.05));
        // A line well above it, 0.008 apart (a LiDAR's far ring): its cubes are sparse, 12 or
        // 13 points each, but its points lie close together.
        points.extend((0..125).map(|k| Point3::new(0.004 + 0.008 * k as f64, 0.75, 0.55)));
        let kept: Vec<usize> = (0..points.len()).collect();
        // Strays, alone or close together in their cubes, at least two cubes from the square
        // and the line.
        for k in 0..10 {
            points.push(Point3::new(
                0.05 + 0.1 * k as f64,
                0.35,
                0.25 + 0.1 * (k % 3) as f64,
            ));
        }
        points.push(Point3::new(0.06, 0.36, 0.26));
        // A third one beside the first: it has two others within 0.17 of a side.
        points.push(Point3::new(0.04, 0.34, 0.24));
        let cloud = PointCloud::new(points);
        assert_eq!(cloud.non_stray_indices(0.1, &STRAYS), kept);
        assert_eq!(
            cloud.voxel_downsampled_without_strays(0.1, &STRAYS),
            cloud.select(&kept).voxel_downsampled(0.1)
        );
        // With a reach of 0.2 of a side, the cube of the three close strays is kept, the lone
        // ones are not.
        let wider = Strays {
            alone: 0.2,
            ..STRAYS
        };
        let mut with_three = kept.clone();
        with_three.extend([kept.len(), kept.len() + 10, kept.len() + 11]);
        assert_eq!(cloud.non_stray_indices(0.1, &wider), with_three);
        // At share 0 every cube is dense.
        let none = Strays {
            share: 0.0,
            ..STRAYS
        };
        assert_eq!(cloud.non_stray_indices(0.1, &none).len(), cloud.len());
        assert_eq!(
            cloud.voxel_downsampled_without_strays(0.1, &none),
            cloud.voxel_downsampled(0.1)
        );
    }

    #[test]
    fn farthest_point_sampling_spreads_out_and_drops_duplicates() {
        // 0, 1, …, 10 on a line, with 3 and 7 repeated: the ends first, then the middle.
        let mut xs: Vec<f64> = (0..=10).map(f64::from).collect();
        xs.extend([3.0, 7.0]);
        let c = PointCloud::new(xs.iter().map(|&x| Point3::new(x, 0.0, 0.0)).collect());
        assert_eq!(c.farthest_point_indices(3), vec![0, 10, 5]);
        // Then 2, 3, 7, 8 and the second 7 are 2 from the picked points: the lowest index
        // first, then 7 (3 is now 1 from 2).
        assert_eq!(c.farthest_point_indices(5), vec![0, 10, 5, 2, 7]);
        // 11 distinct points: asked for 12, it stops there, and the repeats are never picked.
        let all = c.farthest_point_indices(12);
        assert_eq!(all.len(), 11);
        assert!(!all.contains(&11) && !all.contains(&12));
        assert_eq!(c.farthest_point_indices(20), (0..13).collect::<Vec<_>>());
        assert!(PointCloud::default().farthest_point_indices(4).is_empty());
    }

    #[test]
    fn farthest_point_sampling_picks_what_its_definition_picks() {
        // The definition point by point, with nalgebra's squared norm: the same picks on a
        // cloud of 1,003 random points (not a multiple of the vector width) with repeats, and on
        // a 70 × 70 lattice in scan order, whose runs of points lie close together (most picks
        // skip most runs) and whose distances tie everywhere.
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let mut points: Vec<Point3<f64>> = (0..1000)
            .map(|_| Point3::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), 0.5))
            .collect();
        points.extend_from_slice(&points.clone()[..3]);
        let random = PointCloud::new(points);
        let lattice = PointCloud::new(
            (0..4900)
                .map(|k| Point3::new((k / 70) as f64 * 0.1, (k % 70) as f64 * 0.1, 0.3))
                .collect(),
        );
        let defined = |cloud: &PointCloud, count: usize| {
            let mut picked = vec![];
            let mut nearest = vec![f64::INFINITY; cloud.len()];
            let mut next = 0;
            while picked.len() < count {
                picked.push(next);
                let mut farthest = (0, -1.0);
                for (i, d) in nearest.iter_mut().enumerate() {
                    *d = d.min((cloud.points[i] - cloud.points[next]).norm_squared());
                    if *d > farthest.1 {
                        farthest = (i, *d);
                    }
                }
                if farthest.1 <= 0.0 {
                    break;
                }
                next = farthest.0;
            }
            picked
        };
        for (cloud, counts) in [
            (&random, [1, 64, 999, 1002]),
            (&lattice, [2, 100, 1024, 4899]),
        ] {
            for count in counts {
                assert_eq!(
                    cloud.farthest_point_indices(count),
                    defined(cloud, count),
                    "{} points, {count} picked",
                    cloud.len()
                );
            }
        }
    }

    #[test]
    fn centroid_is_the_mean() {
        let c = PointCloud::new(vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(2.0, 4.0, -6.0),
        ]);
        assert_eq!(c.centroid(), Point3::new(1.0, 2.0, -3.0));
    }

    #[test]
    fn f32_rows_round_trip() {
        let rows = [[1.5f32, -2.0, 0.25], [0.0, 1.0, 2.0]];
        assert_eq!(
            PointCloud::from_f32_rows(&rows).to_f32_rows(),
            rows.to_vec()
        );
    }
}
