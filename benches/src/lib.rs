//! Inputs shared by the benches: seeded random data at the paper's sizes (the seeded room the
//! geometry benches and rgm-registration's tests share is `rgm_geom::testing::room_points`).

use nalgebra::Point3;
use rand::{rngs::StdRng, Rng, SeedableRng};

/// Point counts of the paper's settings: partial (717 of 1,024) and full clouds.
pub const SIZES: [usize; 2] = [717, 1024];

/// `n` points uniform in the unit ball, reproducible from `seed`.
pub fn unit_ball_points(n: usize, seed: u64) -> Vec<Point3<f64>> {
    let mut rng = StdRng::seed_from_u64(seed);
    let mut out = Vec::with_capacity(n);
    while out.len() < n {
        let p = Point3::new(
            rng.gen_range(-1.0..1.0),
            rng.gen_range(-1.0..1.0),
            rng.gen_range(-1.0..1.0),
        );
        if p.coords.norm_squared() <= 1.0 {
            out.push(p);
        }
    }
    out
}
