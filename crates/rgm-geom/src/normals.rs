//! Surface normals by PCA, as Open3D's `estimate_normals` with `KDTreeSearchParamHybrid`,
//! then oriented away from the cloud's centroid.
//!
//! For each point: its neighbours are the at most `max_nn` nearest points strictly within
//! `radius` (itself included); with at least 3 of them the normal is the eigenvector of the
//! smallest eigenvalue of their covariance, otherwise (or when the covariance is zero) Open3D's
//! fallback (0, 0, 1). PCA leaves the sign free; we flip each normal so that
//! `n · (p − centroid) ≥ 0` — the setup the project's Open3D measurements used.

use nalgebra::{Matrix3, Point3, SymmetricEigen, Vector3};

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
        .iter()
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

/// The unit eigenvector of the smallest eigenvalue of the neighbours' covariance; `None` with
/// fewer than 3 neighbours or a zero covariance (Open3D then uses (0, 0, 1)).
fn pca_normal(points: &[Point3<f64>], neighbours: &[(usize, f64)]) -> Option<Vector3<f64>> {
    if neighbours.len() < 3 {
        return None;
    }
    let k = neighbours.len() as f64;
    let mean: Vector3<f64> = neighbours
        .iter()
        .map(|&(j, _)| points[j].coords)
        .sum::<Vector3<f64>>()
        / k;
    let mut cov = Matrix3::zeros(); // (3, 3)
    for &(j, _) in neighbours {
        let d = points[j].coords - mean;
        cov += d * d.transpose();
    }
    cov /= k;
    if cov.abs().max() == 0.0 {
        return None;
    }
    let eigen = SymmetricEigen::new(cov);
    let smallest = eigen.eigenvalues.imin();
    let normal: Vector3<f64> = eigen.eigenvectors.column(smallest).into();
    let norm = normal.norm();
    (norm > 0.0 && norm.is_finite()).then(|| normal / norm)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::box_surface;

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
