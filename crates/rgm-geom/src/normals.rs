//! Surface normals by PCA, as Open3D's `estimate_normals` with `KDTreeSearchParamHybrid`,
//! then oriented away from the cloud's centroid.
//!
//! For each point: its neighbours are the at most `max_nn` nearest points strictly within
//! `radius` (itself included); with at least 3 of them the normal is the eigenvector of the
//! smallest eigenvalue of their covariance, otherwise (or when the covariance is zero) Open3D's
//! fallback (0, 0, 1). PCA leaves the sign free; we flip each normal so that
//! `n · (p − centroid) ≥ 0` — the setup the project's Open3D measurements used.
//!
//! The covariance and eigenvector are computed with Open3D's arithmetic (see `pca_normal`), so
//! the normals equal Open3D's bit for bit (checked on ModelNet40 `airplane_0627`).

use nalgebra::{Matrix3, Point3, Vector3};
use rayon::prelude::*;

use crate::knn::{KnnIndex, Neighbourhoods};

/// Settings of [`estimate_normals`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NormalsConfig {
    /// Neighbourhood radius (default 0.2, for shapes in the unit sphere).
    pub radius: f64,
    /// Most neighbours, nearest first (default 30, Open3D's tutorial value).
    pub max_nn: usize,
}

impl Default for NormalsConfig {
    fn default() -> Self {
        Self {
            radius: 0.2,
            max_nn: 30,
        }
    }
}

/// Unit normals of `points`, oriented away from their centroid. `index` must index `points`. // (N,)
pub fn estimate_normals(
    points: &[Point3<f64>],
    index: &KnnIndex,
    config: &NormalsConfig,
) -> Vec<Vector3<f64>> {
    let neighbourhoods = Neighbourhoods::hybrid(index, points, config.radius, config.max_nn);
    normals_from_neighbourhoods(points, &neighbourhoods, config)
}

/// [`estimate_normals`] from precomputed hybrid neighbourhoods of `points` in `points`, searched
/// with a radius and max_nn at least those of `config` (e.g. FPFH's, to search only once). // (N,)
pub fn normals_from_neighbourhoods(
    points: &[Point3<f64>],
    neighbourhoods: &Neighbourhoods,
    config: &NormalsConfig,
) -> Vec<Vector3<f64>> {
    let n = points.len().max(1) as f64;
    let centroid: Vector3<f64> = points.iter().map(|p| p.coords).sum::<Vector3<f64>>() / n;
    points
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let around = neighbourhoods.get_within(i, config.radius, config.max_nn);
            let normal = pca_normal(points, around).unwrap_or_else(Vector3::z);
            if normal.dot(&(p.coords - centroid)) < 0.0 {
                -normal
            } else {
                normal
            }
        })
        .collect()
}

/// Settings of [`normals_within`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WithinConfig {
    /// The neighbours of a point are every point strictly within this.
    pub radius: f64,
    /// Where fewer than [`MIN_WITHIN`] lie within `radius`, or they lie along a line, the
    /// point's normal is [`estimate_normals`]' with these settings.
    pub sparse: NormalsConfig,
}

/// Fewer neighbours than this within [`WithinConfig::radius`] are too few to fit a plane to.
pub const MIN_WITHIN: usize = 8;

/// A neighbourhood whose middle spread (eigenvalue) is below this share of its largest lies
/// along a line (a LiDAR ring within the radius), which leaves its plane's normal free.
const LINE_LIKE: f64 = 0.1;

/// The unit normals at `points[i]` for each `i` of `which`, unoriented (a sign point-to-plane
/// fitting does not see), each by [`normal_from_around`] of every point strictly within
/// `config.radius` of it: for the few points of a large cloud that need one, at a fraction of
/// the cost of the hybrid search of [`estimate_normals`] (30 nearest, sorted). `index` must
/// index `points`. // (W,)
pub fn normals_within(
    points: &[Point3<f64>],
    index: &KnnIndex,
    which: &[usize],
    config: &WithinConfig,
) -> Vec<Vector3<f64>> {
    let mut around = Vec::new(); // (≤ the most points within the radius,)
    which
        .iter()
        .map(|&i| {
            around.clear();
            index.for_each_within(&points[i], config.radius, |j, _| around.push(j as u32));
            normal_from_around(points, index, i, &around, config)
        })
        .collect()
}

/// The unit normal at `points[i]`, unoriented, by PCA of `around`: every point strictly within
/// `config.radius` of it (Open3D's `KDTreeSearchParamRadius`, as
/// [`KnnIndex::for_each_within`] meets them: the same order, so the same bits, wherever the
/// list comes from). Where those are fewer than [`MIN_WITHIN`] or lie along a line, the hybrid
/// normal of `config.sparse` instead. `index` must index `points`.
pub fn normal_from_around(
    points: &[Point3<f64>],
    index: &KnnIndex,
    i: usize,
    around: &[u32],
    config: &WithinConfig,
) -> Vector3<f64> {
    let q = points[i];
    // Sums of d and of d dᵀ's xx, xy, xz, yy, yz, zz over the neighbours, d = p − q: about the
    // point, so that the covariance does not cancel the cloud's offset away.
    let mut sums = [0.0; 9];
    for &j in around {
        let d = points[j as usize] - q;
        add_moments(&mut sums, [d.x, d.y, d.z]);
    }
    let cov = covariance(&sums, around.len().max(1) as f64);
    let own = (around.len() >= MIN_WITHIN && spans_a_plane(&cov))
        .then(|| unit_normal(smallest_eigenvector(&cov)))
        .flatten();
    own.unwrap_or_else(|| {
        let sparse = &config.sparse;
        let hybrid = index.hybrid(&q, sparse.radius, sparse.max_nn);
        pca_normal(points, &hybrid).unwrap_or_else(Vector3::z)
    })
}

/// `normal` where it is one: not zero (a zero covariance's) and finite.
fn unit_normal(normal: Vector3<f64>) -> Option<Vector3<f64>> {
    (normal != Vector3::zeros() && normal.iter().all(|v| v.is_finite())).then_some(normal)
}

/// Adds x, y, z, xx, xy, xz, yy, yz, zz of one point to `sums`.
#[inline]
fn add_moments(sums: &mut [f64; 9], [x, y, z]: [f64; 3]) {
    let terms = [x, y, z, x * x, x * y, x * z, y * y, y * z, z * z];
    for (sum, t) in sums.iter_mut().zip(terms) {
        *sum += t;
    }
}

/// The covariance from the sums of x, y, z, xx, xy, xz, yy, yz, zz over `n` points. // (3, 3)
fn covariance(sums: &[f64; 9], n: f64) -> Matrix3<f64> {
    let c = sums.map(|sum| sum / n);
    let (xx, yy, zz) = (c[3] - c[0] * c[0], c[6] - c[1] * c[1], c[8] - c[2] * c[2]);
    let (xy, xz, yz) = (c[4] - c[0] * c[1], c[5] - c[0] * c[2], c[7] - c[1] * c[2]);
    Matrix3::new(xx, xy, xz, xy, yy, yz, xz, yz, zz)
}

/// Whether a covariance's points spread in two directions rather than along a line: its middle
/// eigenvalue at least [`LINE_LIKE`] of its largest (closed-form eigenvalues of a symmetric 3×3
/// matrix, the trigonometric solution).
fn spans_a_plane(cov: &Matrix3<f64>) -> bool {
    let q = cov.trace() / 3.0;
    let off = cov[(0, 1)].powi(2) + cov[(0, 2)].powi(2) + cov[(1, 2)].powi(2);
    let p2 = (0..3).map(|a| (cov[(a, a)] - q).powi(2)).sum::<f64>() + 2.0 * off;
    let p = (p2 / 6.0).sqrt();
    if !(p > 0.0) {
        // A multiple of the identity: spread evenly in every direction, or not at all.
        return q > 0.0;
    }
    let b = (cov - Matrix3::identity() * q) / p;
    let phi = (b.determinant() / 2.0).clamp(-1.0, 1.0).acos() / 3.0;
    let largest = q + 2.0 * p * phi.cos();
    let smallest = q + 2.0 * p * (phi + 2.0 * std::f64::consts::PI / 3.0).cos();
    let middle = 3.0 * q - largest - smallest;
    middle >= LINE_LIKE * largest
}

/// The unit eigenvector of the smallest eigenvalue of the neighbours' covariance; `None` with
/// fewer than 3 neighbours or a zero covariance (Open3D then uses (0, 0, 1)). Computed as Open3D
/// does, operation for operation (one-pass covariance in neighbour order, then the closed-form
/// solver of Eberly's "A Robust Eigensolver for 3×3 Symmetric Matrices"), because FPFH depends
/// on the normals' last bits (see `fpfh`).
fn pca_normal(points: &[Point3<f64>], neighbours: &[(usize, f64)]) -> Option<Vector3<f64>> {
    if neighbours.len() < 3 {
        return None;
    }
    // Cumulants Σx, Σy, Σz, Σxx, Σxy, Σxz, Σyy, Σyz, Σzz over the neighbours, then means.
    let mut c = [0.0; 9];
    for &(j, _) in neighbours {
        add_moments(&mut c, [points[j].x, points[j].y, points[j].z]);
    }
    unit_normal(smallest_eigenvector(&covariance(
        &c,
        neighbours.len() as f64,
    )))
}

/// `a · b`, summed x, y, z in that order.
fn dot(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    a.x * b.x + a.y * b.y + a.z * b.z
}

/// Unit eigenvector of the smallest eigenvalue of a symmetric 3×3 matrix (Eberly's closed form,
/// as Open3D's `FastEigen3x3`); zero for the zero matrix.
fn smallest_eigenvector(cov: &Matrix3<f64>) -> Vector3<f64> {
    let max_coeff = cov.max();
    if max_coeff == 0.0 {
        return Vector3::zeros();
    }
    let a = cov / max_coeff;
    let off = a[(0, 1)] * a[(0, 1)] + a[(0, 2)] * a[(0, 2)] + a[(1, 2)] * a[(1, 2)];
    if !(off > 0.0) {
        // Diagonal: the axis of the strictly smallest diagonal entry, else z.
        let d = [cov[(0, 0)], cov[(1, 1)], cov[(2, 2)]];
        return if d[0] < d[1] && d[0] < d[2] {
            Vector3::x()
        } else if d[1] < d[0] && d[1] < d[2] {
            Vector3::y()
        } else {
            Vector3::z()
        };
    }
    // Eigenvalues q + p·β with β = 2 cos(θ/3 + 2πk/3), θ = acos(det(B)/2), B = (A − qI)/p.
    let q = (a[(0, 0)] + a[(1, 1)] + a[(2, 2)]) / 3.0;
    let (b00, b11, b22) = (a[(0, 0)] - q, a[(1, 1)] - q, a[(2, 2)] - q);
    let p = ((b00 * b00 + b11 * b11 + b22 * b22 + off * 2.0) / 6.0).sqrt();
    let c00 = b11 * b22 - a[(1, 2)] * a[(1, 2)];
    let c01 = a[(0, 1)] * b22 - a[(1, 2)] * a[(0, 2)];
    let c02 = a[(0, 1)] * a[(1, 2)] - b11 * a[(0, 2)];
    let det = (b00 * c00 - a[(0, 1)] * c01 + a[(0, 2)] * c02) / (p * p * p);
    let half_det = (det * 0.5).clamp(-1.0, 1.0);
    let angle = half_det.acos() / 3.0;
    const TWO_THIRDS_PI: f64 = 2.094_395_102_393_195_5;
    let beta2 = angle.cos() * 2.0;
    let beta0 = (angle + TWO_THIRDS_PI).cos() * 2.0;
    let beta1 = -(beta0 + beta2);
    let eval = [q + p * beta0, q + p * beta1, q + p * beta2];
    let is_smallest = |i: usize| (0..3).filter(|&j| j != i).all(|j| eval[i] < eval[j]);
    // Start from the eigenvalue farthest from the other two (the best conditioned).
    let first = if half_det >= 0.0 { 2 } else { 0 };
    let evec_first = eigenvector_of_simple(&a, eval[first]);
    if is_smallest(first) {
        return evec_first;
    }
    let evec1 = eigenvector_in_complement(&a, &evec_first, eval[1]);
    if is_smallest(1) {
        return evec1;
    }
    // The third is the cross product of the other two, in Open3D's order.
    if half_det >= 0.0 {
        evec1.cross(&evec_first)
    } else {
        evec_first.cross(&evec1)
    }
}

/// Eigenvector for an eigenvalue of multiplicity one: the largest cross product of two rows of
/// `a − λI`, normalised.
fn eigenvector_of_simple(a: &Matrix3<f64>, lambda: f64) -> Vector3<f64> {
    let row0 = Vector3::new(a[(0, 0)] - lambda, a[(0, 1)], a[(0, 2)]);
    let row1 = Vector3::new(a[(0, 1)], a[(1, 1)] - lambda, a[(1, 2)]);
    let row2 = Vector3::new(a[(0, 2)], a[(1, 2)], a[(2, 2)] - lambda);
    let crosses = [row0.cross(&row1), row0.cross(&row2), row1.cross(&row2)];
    let d = [
        dot(&crosses[0], &crosses[0]),
        dot(&crosses[1], &crosses[1]),
        dot(&crosses[2], &crosses[2]),
    ];
    let mut best = 0;
    if d[1] > d[best] {
        best = 1;
    }
    if d[2] > d[best] {
        best = 2;
    }
    crosses[best] / d[best].sqrt()
}

/// `(x, y) / ‖(x, y)‖` for a non-zero pair, dividing by the larger entry first (no overflow).
fn unit_direction(mut x: f64, mut y: f64) -> (f64, f64) {
    if x.abs() >= y.abs() {
        y /= x;
        x = 1.0 / (1.0 + y * y).sqrt();
        y *= x;
    } else {
        x /= y;
        y = 1.0 / (1.0 + x * x).sqrt();
        x *= y;
    }
    (x, y)
}

/// Eigenvector for `lambda` orthogonal to the unit eigenvector `e`: solve the 2×2 problem in an
/// orthonormal basis (U, V) of e's complement.
fn eigenvector_in_complement(a: &Matrix3<f64>, e: &Vector3<f64>, lambda: f64) -> Vector3<f64> {
    let u = if e.x.abs() > e.y.abs() {
        let inv = 1.0 / (e.x * e.x + e.z * e.z).sqrt();
        Vector3::new(-e.z * inv, 0.0, e.x * inv)
    } else {
        let inv = 1.0 / (e.y * e.y + e.z * e.z).sqrt();
        Vector3::new(0.0, e.z * inv, -e.y * inv)
    };
    let v = e.cross(&u);
    let times = |w: &Vector3<f64>| {
        Vector3::new(
            a[(0, 0)] * w.x + a[(0, 1)] * w.y + a[(0, 2)] * w.z,
            a[(0, 1)] * w.x + a[(1, 1)] * w.y + a[(1, 2)] * w.z,
            a[(0, 2)] * w.x + a[(1, 2)] * w.y + a[(2, 2)] * w.z,
        )
    };
    let (au, av) = (times(&u), times(&v));
    let m00 = dot(&u, &au) - lambda;
    let m01 = dot(&u, &av);
    let m11 = dot(&v, &av) - lambda;
    // The null vector of [[m00, m01], [m01, m11]] from its larger row, normalised.
    if m00.abs() >= m11.abs() {
        if m00.abs().max(m01.abs()) > 0.0 {
            let (m00, m01) = unit_direction(m00, m01);
            return m01 * u - m00 * v;
        }
    } else if m11.abs().max(m01.abs()) > 0.0 {
        let (m11, m01) = unit_direction(m11, m01);
        return m11 * u - m01 * v;
    }
    u
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::box_surface;

    /// The angle between two unoriented normals, in degrees.
    fn apart_deg(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
        a.dot(b).abs().min(1.0).acos().to_degrees()
    }

    #[test]
    fn normals_within_a_radius_are_a_box_faces_axes() {
        // As `box_faces_get_their_outward_axis`: a point at least 0.1 from every other face
        // has its face's axis (either sign), from its neighbours within 0.08 (≈ 24), or the
        // 30 nearest within 0.09 where fewer than 8 lie that near.
        let cloud = box_surface(3000, 5);
        let index = KnnIndex::new(&cloud.points);
        let config = WithinConfig {
            radius: 0.08,
            sparse: NormalsConfig {
                radius: 0.09,
                max_nn: 30,
            },
        };
        let which: Vec<usize> = (0..cloud.len()).collect();
        let normals = normals_within(&cloud.points, &index, &which, &config);
        let half = [0.5, 0.3, 0.2];
        let mut checked = 0;
        for (p, n) in cloud.points.iter().zip(&normals) {
            let on: Vec<usize> = (0..3)
                .filter(|&a| (p[a].abs() - half[a]).abs() < 1e-12)
                .collect();
            let interior = (0..3).all(|a| on.contains(&a) || p[a].abs() < half[a] - 0.1);
            if on.len() == 1 && interior {
                let mut axis = Vector3::zeros();
                axis[on[0]] = 1.0;
                assert!(apart_deg(n, &axis) < 1e-4, "point {p} normal {n}");
                checked += 1;
            }
        }
        assert!(checked > 300, "only {checked} interior face points");
        // Alone or among others, a normal is the same to the bit.
        for i in (0..cloud.len()).step_by(97) {
            assert_eq!(
                normals_within(&cloud.points, &index, &[i], &config)[0],
                normals[i]
            );
        }
    }

    #[test]
    fn sparse_or_line_like_neighbourhoods_take_the_hybrid_normal() {
        // Rings as a LiDAR sweeps them: dense along each line, lines 0.1 apart on one plane
        // (z = 0, then turned, so that no axis is special). Within 0.05 a point sees only its
        // own line (its plane's normal is free); the hybrid 60 within 0.5 reach the next lines
        // and find the plane's.
        let turn = nalgebra::Rotation3::from_axis_angle(
            &nalgebra::Unit::new_normalize(Vector3::new(1.0, 2.0, 3.0)),
            0.7,
        );
        let up = turn * Vector3::z();
        let points: Vec<Point3<f64>> = (0..20)
            .flat_map(|line| {
                (0..100).map(move |i| turn * Point3::new(0.01 * i as f64, 0.1 * line as f64, 0.0))
            })
            .collect();
        let index = KnnIndex::new(&points);
        let sparse = NormalsConfig {
            radius: 0.5,
            max_nn: 60,
        };
        let which: Vec<usize> = (0..points.len()).step_by(13).collect();
        for radius in [0.05, 0.015] {
            // 0.05: line-like; 0.015: 3 neighbours, too few.
            let config = WithinConfig { radius, sparse };
            let normals = normals_within(&points, &index, &which, &config);
            for (&i, n) in which.iter().zip(&normals) {
                let around = index.hybrid(&points[i], sparse.radius, sparse.max_nn);
                assert_eq!(Some(*n), pca_normal(&points, &around), "{i} at {radius}");
                assert!(apart_deg(n, &up) < 1e-4, "{i}: {n}");
            }
        }
        // Within 0.25 a point sees five lines: a plane, fitted from its own neighbours.
        let config = WithinConfig {
            radius: 0.25,
            sparse,
        };
        for n in normals_within(&points, &index, &which, &config) {
            assert!(apart_deg(&n, &up) < 1e-4, "{n}");
        }
    }

    #[test]
    fn a_line_spreads_in_one_direction_a_plane_in_two() {
        let line = Matrix3::from_diagonal(&Vector3::new(1.0, 1e-4, 0.0));
        let turned = Matrix3::new(0.5, 0.5, 0.0, 0.5, 0.5, 0.0, 0.0, 0.0, 1e-6);
        let plane = Matrix3::new(1.0, 0.2, 0.0, 0.2, 0.5, 0.0, 0.0, 0.0, 1e-4);
        assert!(!spans_a_plane(&line));
        assert!(!spans_a_plane(&turned));
        assert!(spans_a_plane(&plane));
        assert!(spans_a_plane(&Matrix3::identity()));
        assert!(!spans_a_plane(&Matrix3::zeros()));
    }

    #[test]
    fn box_faces_get_their_outward_axis() {
        // Away from edges, a point on the face x = +0.5 has normal +x, on y = −0.3 normal −y, …
        let cloud = box_surface(3000, 5);
        let index = KnnIndex::new(&cloud.points);
        let config = NormalsConfig {
            radius: 0.08,
            max_nn: 30,
        };
        let normals = estimate_normals(&cloud.points, &index, &config);
        let half = [0.5, 0.3, 0.2];
        let mut checked = 0;
        for (p, n) in cloud.points.iter().zip(&normals) {
            assert!((n.norm() - 1.0).abs() < 1e-12);
            // Points at least 0.1 from every other face: the face is the one they lie on.
            let on: Vec<usize> = (0..3)
                .filter(|&a| (p[a].abs() - half[a]).abs() < 1e-12)
                .collect();
            let interior = (0..3).all(|a| on.contains(&a) || p[a].abs() < half[a] - 0.1);
            if on.len() == 1 && interior {
                let a = on[0];
                let mut expected = Vector3::zeros();
                expected[a] = p[a].signum();
                assert!((n - expected).norm() < 1e-9, "point {p} normal {n}");
                checked += 1;
            }
        }
        assert!(checked > 300, "only {checked} interior face points");
    }

    #[test]
    fn sphere_normals_point_outward() {
        // Points on a sphere of radius 1 around (2, 0, 0): normal ≈ (p − centre), up to the
        // curvature within the neighbourhood.
        let centre = Vector3::new(2.0, 0.0, 0.0);
        let points: Vec<Point3<f64>> = (0..2000)
            .map(|i| {
                // Fibonacci sphere.
                let z = 1.0 - 2.0 * (i as f64 + 0.5) / 2000.0;
                let phi = i as f64 * std::f64::consts::PI * (3.0 - 5f64.sqrt());
                let r = (1.0 - z * z).sqrt();
                Point3::from(centre + Vector3::new(r * phi.cos(), r * phi.sin(), z))
            })
            .collect();
        let normals = estimate_normals(&points, &KnnIndex::new(&points), &NormalsConfig::default());
        for (p, n) in points.iter().zip(&normals) {
            assert!(n.dot(&(p.coords - centre)) > 0.999, "point {p} normal {n}");
        }
    }

    /// Pinned from Open3D 0.20 on ModelNet40 `airplane_0627`:
    ///
    /// ```python
    /// pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))  # pts: the .npy as float64
    /// pcd.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=0.2, max_nn=30))
    /// n = np.asarray(pcd.normals); n[((pts - pts.mean(0)) * n).sum(1) < 0] *= -1
    /// n[0], n[500]
    /// ```
    #[test]
    fn normals_match_open3d() {
        let cloud = crate::testing::airplane();
        let normals = estimate_normals(
            &cloud.points,
            &KnnIndex::new(&cloud.points),
            &NormalsConfig::default(),
        );
        let pinned = [
            (
                0,
                [
                    -0.9080177930218877,
                    0.3531019644704376,
                    -0.22543888360879175,
                ],
            ),
            (
                500,
                [0.9687423695198114, 0.24788958169310935, 0.00943275066758592],
            ),
        ];
        for (i, expected) in pinned {
            let diff = (normals[i] - Vector3::from(expected)).abs().max();
            assert!(diff < 1e-9, "point {i}: {} vs {expected:?}", normals[i]);
        }
    }

    #[test]
    fn wider_neighbourhoods_restricted_give_the_same_normals() {
        // FPFH's neighbourhoods (0.4, 100) cut down to (0.2, 30) are exactly the normals' own.
        let cloud = crate::testing::airplane();
        let index = KnnIndex::new(&cloud.points);
        let config = NormalsConfig::default();
        let wide = Neighbourhoods::hybrid(&index, &cloud.points, 0.4, 100);
        let own = Neighbourhoods::hybrid(&index, &cloud.points, config.radius, config.max_nn);
        for i in 0..cloud.len() {
            assert_eq!(
                wide.get_within(i, config.radius, config.max_nn),
                own.get(i),
                "point {i}"
            );
        }
        assert_eq!(
            normals_from_neighbourhoods(&cloud.points, &wide, &config),
            estimate_normals(&cloud.points, &index, &config)
        );
    }

    #[test]
    fn too_few_neighbours_fall_back_to_z() {
        // Two far-apart points: fewer than 3 neighbours each → (0, 0, ±1), signed away from the
        // centroid (both have z = 0 relative to it, so the dot is 0 and +z stays).
        let points = vec![Point3::new(0.0, 0.0, 0.0), Point3::new(5.0, 0.0, 0.0)];
        let normals = estimate_normals(&points, &KnnIndex::new(&points), &NormalsConfig::default());
        assert_eq!(normals, vec![Vector3::z(), Vector3::z()]);
    }
}
