//! Split sizes, load time and ground-truth statistics of the first test pairs of a ModelNet40
//! `.npy` tree: the numbers of `docs/data.md`.
//!
//! `cargo run --release -p rgm-data --example data_stats -- ../shared/data/modelnet40_npy1024 [PAIRS]`
//! (a folder of the HDF5 release `modelnet40_ply_hdf5_2048` works too).

use std::time::Instant;

use rgm_data::{ModelNet40, PairGenerator, Setting, Split};

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
    let count: usize = std::env::args().nth(2).map_or(Ok(100), |s| s.parse())?;
    let test = data.split(Split::Test, false);
    println!("\nfirst {count} test pairs (all categories):");
    println!("| setting | source points (min) | target points (min) | matched / source | min matched / source | ms per pair |");
    println!("|---|---|---|---|---|---|");
    for setting in Setting::ALL {
        let generator = PairGenerator::new(setting);
        let start = Instant::now();
        let pairs = (0..count)
            .map(|i| generator.test_pair(&test, i))
            .collect::<Result<Vec<_>, _>>()?;
        let ms = start.elapsed().as_secs_f64() * 1e3 / count as f64;
        let mean =
            |f: &dyn Fn(&rgm_data::Pair) -> f64| pairs.iter().map(f).sum::<f64>() / count as f64;
        let min_fraction = pairs
            .iter()
            .map(|p| p.correspondence.matched_source_fraction())
            .fold(1.0, f64::min);
        let min_source = pairs.iter().map(|p| p.source.len()).min().unwrap_or(0);
        let min_target = pairs.iter().map(|p| p.target.len()).min().unwrap_or(0);
        println!(
            "| {} | {:.1} ({min_source}) | {:.1} ({min_target}) | {:.4} | {:.4} | {ms:.2} |",
            setting.name(),
            mean(&|p| p.source.len() as f64),
            mean(&|p| p.target.len() as f64),
            mean(&|p| p.correspondence.matched_source_fraction()),
            min_fraction,
        );
    }
    Ok(())
}
