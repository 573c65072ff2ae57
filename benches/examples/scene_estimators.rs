//! The scene stage's global estimators side by side on scene folders (3DMatch layout,
//! `rgm_data::scenes`): RANSAC at several seeds and lengths, and second-order compatibility
//! (SC²) at its defaults and with each setting halved and doubled. Each alone, unrefined by the
//! default's later stages, on one thread: how many pairs within 15° and 0.3 m, and the mean time.
//!
//!     cargo run --release -p rgm-benches --example scene_estimators -- [SCENE_DIR ...]
//!
//! (default: ../shared/data/scenes/redkitchen). Used for docs/baselines.md, "Scenes:
//! second-order compatibility".

use std::time::Instant;

use rgm_data::scenes::LoadedScenePair;
use rgm_data::SceneFolder;
use rgm_geom::Result;
use rgm_registration::methods::feature_matches::MatchingConfig;
use rgm_registration::methods::ransac::{self, RansacConfig};
use rgm_registration::methods::sc2::{self, Sc2Config};
use rgm_registration::Fit;

fn main() {
    let folders: Vec<String> = std::env::args().skip(1).collect();
    let folders = if folders.is_empty() {
        vec!["../shared/data/scenes/redkitchen".to_string()]
    } else {
        folders
    };
    let pairs: Vec<LoadedScenePair> = folders
        .iter()
        .flat_map(|f| SceneFolder::open(f).expect("a scene folder").pairs)
        .map(|p| p.load(None).expect("readable fragments"))
        .collect();
    let rayon = rayon_one_thread();
    // The default lengths read Open3D's voxel as 5/3 spacings of the thinned pair
    // (voxel-averaging leaves points about 0.6 voxel apart); these as one.
    let shorter = MatchingConfig {
        normal_spacings: 2.0,
        feature_spacings: 5.0,
        inlier_spacings: 1.5,
        ..MatchingConfig::default()
    };
    type Estimator = Box<dyn Fn(&LoadedScenePair) -> Result<Fit> + Sync>;
    let mut rows: Vec<(String, Estimator)> = Vec::new();
    for seed in 0..4 {
        for (lengths, matching) in [
            ("voxel = spacing", shorter.clone()),
            ("voxel = 5/3 spacing", MatchingConfig::default()),
        ] {
            let config = RansacConfig {
                matching,
                seed,
                ..RansacConfig::default()
            };
            rows.push((
                format!("RANSAC, seed {seed}, {lengths}"),
                Box::new(move |p| ransac::register(&p.source, &p.target, &config)),
            ));
        }
    }
    let base = Sc2Config::default();
    let variants = [
        ("SC², defaults", base.clone()),
        (
            "SC², voxel = spacing",
            Sc2Config {
                matching: shorter,
                ..base.clone()
            },
        ),
        (
            "SC², seeds 100",
            Sc2Config {
                seeds: 100,
                ..base.clone()
            },
        ),
        (
            "SC², seeds 400",
            Sc2Config {
                seeds: 400,
                ..base.clone()
            },
        ),
        (
            "SC², mates 15",
            Sc2Config {
                mates: 15,
                ..base.clone()
            },
        ),
        (
            "SC², mates 60",
            Sc2Config {
                mates: 60,
                ..base.clone()
            },
        ),
        (
            "SC², compatibility 0.5",
            Sc2Config {
                compatibility: 0.5,
                ..base.clone()
            },
        ),
        (
            "SC², compatibility 2",
            Sc2Config {
                compatibility: 2.0,
                ..base.clone()
            },
        ),
        (
            "SC², judged 1",
            Sc2Config {
                judged: 1,
                ..base.clone()
            },
        ),
        (
            "SC², judged 30",
            Sc2Config {
                judged: 30,
                ..base.clone()
            },
        ),
    ];
    for (name, config) in variants {
        rows.push((
            name.to_string(),
            Box::new(move |p| sc2::register(&p.source, &p.target, &config)),
        ));
    }
    println!("| estimator | within 15° / 0.3 m | failed pairs | mean ms |\n|---|---:|---|---:|");
    for (name, estimate) in &rows {
        let (mut right, mut failed, mut ms) = (0, Vec::new(), 0.0);
        for (k, pair) in pairs.iter().enumerate() {
            let start = Instant::now();
            let found = rayon.install(|| estimate(pair));
            ms += start.elapsed().as_secs_f64() * 1e3;
            let good = found.is_ok_and(|fit| {
                let (r, t) = pair.errors(&fit.t_target_source);
                r < 15.0 && t < 0.3
            });
            if good {
                right += 1;
            } else {
                failed.push(k.to_string());
            }
        }
        println!(
            "| {name} | {right} / {} | {} | {:.0} |",
            pairs.len(),
            failed.join(", "),
            ms / pairs.len() as f64
        );
    }
}

fn rayon_one_thread() -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a thread pool")
}
