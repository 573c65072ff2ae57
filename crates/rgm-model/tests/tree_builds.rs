//! A registration builds each cloud's k-d tree once (issue 43): the stages of the default
//! (its checks, the cascade's judge, FGR, the refinements, the scene stage) share one prepared tree per
//! cloud they search, whatever they are composed into. Clouds a stage makes (the pair in the
//! network's frame, each thinning, the network's moved clouds) have trees of their own.
//!
//! The hook of [`rgm_geom::knn::watch_index_builds`] sees every tree this process builds: the test
//! is alone in its file (its own process). It needs ModelNet40, the Stanford bunny and the
//! redkitchen fragments beside the repository (`../shared/data`) and says so and passes when they
//! are absent.

use std::collections::HashMap;
use std::hash::{DefaultHasher, Hash, Hasher};
use std::path::PathBuf;
use std::sync::Mutex;

use rgm_data::{ModelNet40, PairGenerator, Setting, Split};
use rgm_geom::knn::watch_index_builds;
use rgm_geom::{Point3, PointCloud};
use rgm_model::{MethodOptions, Registrar};

/// (points, hash of their coordinates' bits) of every tree built since the last clear.
static BUILT: Mutex<Vec<(usize, u64)>> = Mutex::new(Vec::new());

fn record(points: &[Point3<f64>]) {
    let mut hasher = DefaultHasher::new();
    for p in points {
        p.coords.iter().for_each(|v| v.to_bits().hash(&mut hasher));
    }
    BUILT.lock().unwrap().push((points.len(), hasher.finish()));
}

fn shared_data() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data")
}

/// A sparse pair (ModelNet40's partial test pair 0, 717 points each), a dense one (two real
/// scans of the bunny, 40,256 and 40,097 points) and a room pair that the scene stage
/// runs on (redkitchen fragment 21 onto 6, 25,337 and 15,953 points), or `None` without the
/// data.
fn pairs() -> Option<Vec<(&'static str, PointCloud, PointCloud)>> {
    let data = shared_data();
    let (bunny, kitchen) = (data.join("stanford/bunny"), data.join("scenes/redkitchen"));
    if !data.join("modelnet40_npy1024").is_dir() || !bunny.is_dir() || !kitchen.is_dir() {
        return None;
    }
    let dataset = ModelNet40::open(data.join("modelnet40_npy1024")).unwrap();
    let shapes = dataset.split(Split::Test, false);
    let partial = PairGenerator::new(Setting::Partial)
        .test_pair(&shapes, 0)
        .unwrap();
    let scan = |name: &str| rgm_data::io::read_point_cloud(bunny.join(name)).unwrap();
    let fragment = |name: &str| rgm_data::io::read_point_cloud(kitchen.join(name)).unwrap();
    Some(vec![
        ("modelnet partial 0", partial.source, partial.target),
        (
            "bunny 000 onto 045",
            scan("bun000.ply.gz"),
            scan("bun045.ply.gz"),
        ),
        (
            "redkitchen 21 onto 6",
            fragment("cloud_bin_21.ply.gz"),
            fragment("cloud_bin_6.ply.gz"),
        ),
    ])
}

#[test]
fn the_default_builds_one_tree_per_cloud_it_searches() {
    let Some(pairs) = pairs() else {
        eprintln!("skipped: ../shared/data (ModelNet40, stanford/bunny) is absent");
        return;
    };
    assert!(watch_index_builds(record));
    let mut method = MethodOptions::default().build().unwrap();
    for (name, source, target) in pairs {
        BUILT.lock().unwrap().clear();
        let found = method.register(&source, &target).unwrap();
        let built = BUILT.lock().unwrap().clone();
        let mut per_cloud: HashMap<(usize, u64), usize> = HashMap::new();
        for tree in &built {
            *per_cloud.entry(*tree).or_default() += 1;
        }
        let again: Vec<_> = per_cloud.iter().filter(|(_, &n)| n > 1).collect();
        assert!(
            again.is_empty(),
            "{name}: {} trees over {} clouds; built more than once ((points, hash): times): \
             {again:?}; candidates {:?}",
            built.len(),
            per_cloud.len(),
            found.candidates
        );
        // The pair in the default's frame is searched (its score, its check) at least.
        assert!(built.len() >= 2, "{name}: {} trees", built.len());
        if name.starts_with("redkitchen") {
            let ran: Vec<&str> = found.candidates.iter().map(|c| c.method.as_str()).collect();
            assert!(
                ran.contains(&"sc2+refine"),
                "{name}: the scene stage did not run: {ran:?}"
            );
        }
        eprintln!("{name}: {} trees, one per cloud", built.len());
    }
}
