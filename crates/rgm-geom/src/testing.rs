//! Shapes shared by the tests of several modules.

use nalgebra::Point3;
use rand::{rngs::StdRng, Rng, SeedableRng};

use crate::PointCloud;

/// `n` points on the faces of a 1.0 × 0.6 × 0.4 box centred at the origin: a shape with no
/// rotational symmetry, reproducible from `seed`.
pub fn box_surface(n: usize, seed: u64) -> PointCloud {
    let mut rng = StdRng::seed_from_u64(seed);
    let half = [0.5, 0.3, 0.2];
    let points = (0..n)
        .map(|_| {
            let axis = rng.gen_range(0..3);
            let sign = if rng.gen_bool(0.5) { 1.0 } else { -1.0 };
            let p: [f64; 3] = std::array::from_fn(|a| {
                if a == axis {
                    sign * half[a]
                } else {
                    rng.gen_range(-half[a]..half[a])
                }
            });
            Point3::new(p[0], p[1], p[2])
        })
        .collect();
    PointCloud::new(points)
}
