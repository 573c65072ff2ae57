//! Seeded shapes and scenes for the tests of several crates (rgm-geom's own, rgm-registration's)
//! and the benches: compiled for rgm-geom's tests and, with the `testing` feature, for theirs
//! (as a dev-dependency). Nothing here is part of the geometry.

use nalgebra::Point3;
use rand::{rngs::StdRng, Rng, SeedableRng};

use crate::PointCloud;

/// `n` points uniform in the cube [−1, 1)³.
pub fn uniform_cube(n: usize, rng: &mut StdRng) -> Vec<Point3<f64>> {
    (0..n)
        .map(|_| {
            Point3::new(
                rng.gen_range(-1.0..1.0),
                rng.gen_range(-1.0..1.0),
                rng.gen_range(-1.0..1.0),
            )
        })
        .collect()
}

/// `n` points on the faces of a 1.0 × 0.6 × 0.4 box centred at the origin, reproducible from
/// `seed`: a shape with three unequal axes, so that its only rotational symmetries are the half
/// turns about them.
pub fn box_surface(n: usize, seed: u64) -> PointCloud {
    box_surface_of([0.5, 0.3, 0.2], n, seed)
}

/// `n` points on the faces of the box of half sides `half` centred at the origin, each on a face
/// pair chosen evenly (so the smaller faces are the denser), reproducible from `seed`.
pub fn box_surface_of(half: [f64; 3], n: usize, seed: u64) -> PointCloud {
    let mut rng = StdRng::seed_from_u64(seed);
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

/// The 1,024 points of ModelNet40's `airplane_0627` (test split), from the shared data folder.
pub fn airplane() -> PointCloud {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/data/modelnet40_npy1024/airplane/test/airplane_0627.npy"
    );
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{path}: {e}"));
    // .npy v1: magic (6), version (2), header length (u16 LE), header, then <f4 rows (1024, 3).
    assert_eq!(&bytes[..6], b"\x93NUMPY");
    let header_len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    let header = std::str::from_utf8(&bytes[10..10 + header_len]).expect("an ASCII header");
    assert!(
        header.contains("'<f4'") && header.contains("(1024, 3)"),
        "{header}"
    );
    let rows: Vec<[f32; 3]> = bytes[10 + header_len..]
        .chunks_exact(12)
        .map(|c| {
            std::array::from_fn(|k| {
                f32::from_le_bytes([c[4 * k], c[4 * k + 1], c[4 * k + 2], c[4 * k + 3]])
            })
        })
        .collect();
    assert_eq!(rows.len(), 1024);
    PointCloud::from_f32_rows(&rows)
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

/// A dense scene, in metres ([`room_points`]): a floor, two walls, a box on the
/// floor and a slanted board, sampled at `n` random points, reproducible from `seed`.
pub fn room(n: usize, seed: u64) -> PointCloud {
    PointCloud::new(room_points(n, seed))
}
