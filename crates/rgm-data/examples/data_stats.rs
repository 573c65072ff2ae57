//! Split sizes and load time of a ModelNet40 `.npy` tree: the numbers of `docs/data.md`.
//!
//! `cargo run --release -p rgm-data --example data_stats -- ../shared/data/modelnet40_npy1024`

use std::time::Instant;

use rgm_data::{ModelNet40, Split};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = std::env::args().nth(1).ok_or("usage: data_stats DIR")?;
    let start = Instant::now();
    let data = ModelNet40::open(&dir)?;
    let load_s = start.elapsed().as_secs_f64();
    println!(
        "loaded {} shapes ({} official train, {} official test, {} categories) in {load_s:.2} s on {} threads",
        data.official_train.len() + data.official_test.len(),
        data.official_train.len(),
        data.official_test.len(),
        data.categories.len(),
        rayon::current_num_threads()
    );
    println!("| split | all categories | unseen setting |\n|---|---|---|");
    for (name, split) in [
        ("train", Split::Train),
        ("validation", Split::Validation),
        ("test", Split::Test),
    ] {
        println!(
            "| {name} | {} | {} |",
            data.split(split, false).len(),
            data.split(split, true).len()
        );
    }
    Ok(())
}
