//! Statistics of the training pairs `rgm train` makes (epoch 0, the first PAIRS training shapes),
//! as JSON: the numbers the GPU trainer's pairs are checked against (tools/gpu/prove_cpu.sh).
//!
//! `cargo run --release -p rgm-data --example pair_stats -- DIR SETTING PAIRS [MATCH_POINTS]`
//!
//! For each statistic: its mean and standard deviation over the pairs. The cut to MATCH_POINTS
//! points per cloud is `rgm train`'s (`Pair::subsampled` with the trainer's seed).

use rand::rngs::StdRng;
use rand::SeedableRng;
use rgm_data::pairs::train_seed;
use rgm_data::{ModelNet40, Pair, PairGenerator, Setting, Split};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 4 {
        return Err("usage: pair_stats DIR SETTING PAIRS [MATCH_POINTS]".into());
    }
    let data = ModelNet40::open(&args[1])?;
    let setting: Setting = args[2].parse()?;
    let count: usize = args[3].parse()?;
    let match_points: Option<usize> = args.get(4).map(|s| s.parse()).transpose()?;
    let train = data.split(Split::Train, false);
    let generator = PairGenerator::new(setting);
    let mut rows: Vec<[f64; 6]> = Vec::with_capacity(count); // (PAIRS, 6)
    for i in 0..count.min(train.len()) {
        let full = generator.train_pair(&train, 0, i)?;
        let cut: Pair = match match_points {
            Some(points) => full.subsampled(points, &mut StdRng::seed_from_u64(!train_seed(0, i))),
            None => full.clone(),
        };
        let r = &full.t_target_source.rotation;
        let angle = ((r.trace() - 1.0) / 2.0)
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees();
        rows.push([
            full.source.len() as f64,
            full.target.len() as f64,
            full.correspondence.pairs.len() as f64,
            cut.correspondence.pairs.len() as f64,
            angle,
            full.t_target_source.translation.norm(),
        ]);
    }
    let names = [
        "source_points",
        "target_points",
        "matched",
        "matched_cut",
        "rotation_deg",
        "translation",
    ];
    let n = rows.len() as f64;
    let fields: Vec<String> = names
        .iter()
        .enumerate()
        .map(|(k, name)| {
            let mean = rows.iter().map(|r| r[k]).sum::<f64>() / n;
            let var = rows.iter().map(|r| (r[k] - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
            format!("\"{name}\": [{mean}, {}]", var.sqrt())
        })
        .collect();
    println!("{{\"pairs\": {}, {}}}", rows.len(), fields.join(", "));
    Ok(())
}
