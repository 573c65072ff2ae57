//! Why rgm-geom keeps its own k-d tree rather than kiddo 5's `ImmutableKdTree` (docs/geom.md):
//! kiddo orders neighbours by distance only, so among points tied at the k-th distance it keeps
//! whichever its traversal meets, where `KnnIndex` keeps the lowest indices (the order Open3D's
//! pinned results and the kNN graph's determinism rely on). And it does not panic on
//! duplicated points (kiddo 4 did).
//!
//! Run: `cargo run --release -p rgm-benches --example kiddo_ties`

use std::num::NonZero;

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rgm_geom::{KnnIndex, Point3};

fn main() {
    // A 6 × 6 × 6 lattice of unit spacing: every inner point has 6 neighbours at distance 1.
    let points: Vec<[f64; 3]> = (0..216)
        .map(|i| [(i % 6) as f64, (i / 6 % 6) as f64, (i / 36) as f64])
        .collect();
    let tree: ImmutableKdTree<f64, 3> = ImmutableKdTree::new_from_slice(&points);
    let ours = KnnIndex::new(&points.iter().map(|p| Point3::from(*p)).collect::<Vec<_>>());
    let mut differ = 0;
    for (i, q) in points.iter().enumerate() {
        let theirs: Vec<u64> = tree
            .nearest_n::<SquaredEuclidean>(q, NonZero::new(4).unwrap())
            .iter()
            .map(|n| n.item)
            .collect();
        let mine: Vec<u64> = ours
            .k_nearest(&Point3::from(*q), 4)
            .iter()
            .map(|n| n.0 as u64)
            .collect();
        let mut sorted = theirs.clone();
        sorted.sort_by_key(|&j| {
            let d: f64 = (0..3).map(|a| (points[j as usize][a] - q[a]).powi(2)).sum();
            ((d * 1e6) as u64, j)
        });
        if sorted != mine {
            if differ < 3 {
                println!("point {i}: kiddo keeps {theirs:?}, KnnIndex (lowest indices) {mine:?}");
            }
            differ += 1;
        }
    }
    println!("{differ} of 216 lattice points get another set of 4 nearest from kiddo 5.3.3");
    // Duplicates: 2,000 identical points and 3,000 sharing one coordinate build and query.
    let mut dup = vec![[0.5, 0.5, 0.5]; 2000];
    dup.extend((0..3000).map(|i| [0.25, i as f64 * 1e-3, (i % 7) as f64]));
    let tree: ImmutableKdTree<f64, 3> = ImmutableKdTree::new_from_slice(&dup);
    let n = tree.nearest_n::<SquaredEuclidean>(&[0.5, 0.5, 0.5], NonZero::new(20).unwrap());
    println!(
        "duplicates: {} neighbours at distance {}",
        n.len(),
        n[19].distance
    );
}
