//! How many k-d trees `rgm register`'s default builds on one pair, and its time per pair.
//!
//! ```text
//! RAYON_NUM_THREADS=1 cargo run --release -p rgm-benches --example trees_per_registration -- \
//!     SOURCE TARGET [REPEATS]
//! ```
//!
//! Registers SOURCE onto TARGET (any format `rgm register` reads) REPEATS times (5 when left
//! out) with one method value, as `rgm register --pairs` does, and prints per registration the
//! trees built (every `KnnIndex::new`, the network's neighbourhood graphs included), the wall time
//! in milliseconds and the transform. The first registration also makes the network and warms
//! the caches: take the median of the others.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use rgm_geom::knn::watch_index_builds;
use rgm_geom::Point3;
use rgm_model::{MethodOptions, Registrar};

/// Trees built in this process.
static BUILT: AtomicUsize = AtomicUsize::new(0);

fn count(_: &[Point3<f64>]) {
    BUILT.fetch_add(1, Ordering::Relaxed);
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [source, target, rest @ ..] = args.as_slice() else {
        return Err("usage: trees_per_registration SOURCE TARGET [REPEATS]".into());
    };
    let repeats: usize = match rest.first() {
        Some(n) => n.parse().map_err(|e| format!("REPEATS {n:?}: {e}"))?,
        None => 5,
    };
    watch_index_builds(count);
    let source = rgm_data::io::read_point_cloud(source)?;
    let target = rgm_data::io::read_point_cloud(target)?;
    let mut method = MethodOptions::default().build()?;
    println!("points {} {}", source.len(), target.len());
    for _ in 0..repeats {
        let before = BUILT.load(Ordering::Relaxed);
        let start = Instant::now();
        let found = method.register(&source, &target)?;
        let ms = start.elapsed().as_secs_f64() * 1e3;
        let trees = BUILT.load(Ordering::Relaxed) - before;
        let rows = found.result.t_target_source.to_rows();
        println!("trees {trees} ms {ms:.1} transform {rows:?}");
    }
    Ok(())
}
