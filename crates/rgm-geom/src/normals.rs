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

/// The unit normal at `points[i]` as [`estimate_normals`] finds it, but unoriented (a sign
/// that point-to-plane fitting does not see): for the few points of a large cloud that need
/// one. `index` must index `points`.
pub fn normal_at(
    points: &[Point3<f64>],
    index: &KnnIndex,
    i: usize,
    config: &NormalsConfig,
) -> Vector3<f64> {
    let around = index.hybrid(&points[i], config.radius, config.max_nn);
    pca_normal(points, &around).unwrap_or_else(Vector3::z)
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
        let [x, y, z] = [points[j].x, points[j].y, points[j].z];
        let terms = [x, y, z, x * x, x * y, x * z, y * y, y * z, z * z];
        for (ci, t) in c.iter_mut().zip(terms) {
            *ci += t;
        }
    }
    let k = neighbours.len() as f64;
    c.iter_mut().for_each(|ci| *ci /= k);
    let (xx, yy, zz) = (c[3] - c[0] * c[0], c[6] - c[1] * c[1], c[8] - c[2] * c[2]);
    let (xy, xz, yz) = (c[4] - c[0] * c[1], c[5] - c[0] * c[2], c[7] - c[1] * c[2]);
    let cov = Matrix3::new(xx, xy, xz, xy, yy, yz, xz, yz, zz); // (3, 3)
    let normal = smallest_eigenvector(&cov);
    (normal != Vector3::zeros() && normal.iter().all(|v| v.is_finite())).then_some(normal)
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

    #[test]
    fn a_normal_at_one_point_is_the_estimated_one_up_to_sign() {
        let cloud = box_surface(2000, 6);
        let index = KnnIndex::new(&cloud.points);
        let config = NormalsConfig {
            radius: 0.1,
            max_nn: 20,
        };
        let normals = estimate_normals(&cloud.points, &index, &config);
        for i in (0..cloud.len()).step_by(37) {
            let one = normal_at(&cloud.points, &index, i, &config);
            assert!(
                one == normals[i] || one == -normals[i],
                "{i}: {one} vs {}",
                normals[i]
            );
        }
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
