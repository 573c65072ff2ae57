//! Inputs shared by the benches (and rgm-geom's tests): seeded random data at the paper's sizes.

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

/// `n` points sampled at random on a room corner (metres): a 4 × 3 m floor, two walls 2.5 m
/// high, a box on the floor and a slanted board, reproducible from `seed`. Two samplings of
/// it, one moved, make a scene pair that shares every surface but no point.
pub fn room_points(n: usize, seed: u64) -> Vec<Point3<f64>> {
    let mut rng = StdRng::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            let (u, v): (f64, f64) = (rng.gen(), rng.gen());
            match rng.gen_range(0..5) {
                0 => Point3::new(4.0 * u, 3.0 * v, 0.0),
                1 => Point3::new(4.0 * u, 0.0, 2.5 * v),
                2 => Point3::new(0.0, 3.0 * u, 2.5 * v),
                3 => Point3::new(1.5 + 0.6 * u, 1.0 + 0.4 * v, 0.5),
                _ => Point3::new(3.0 + 0.5 * u, 2.0 + 0.8 * v, 0.3 + 0.6 * u),
            }
        })
        .collect()
}
