//! rgm-geom's and rgm-registration's hot paths at RGM's sizes (N = 717 partial, 1,024 full; K = 20): the kNN graph,
//! weighted Kabsch, and the classical baselines ICP and FPFH + FGR on a 717-point pair; the
//! searches of a dense scan pair (40,000 points: the nearest within a radius, whether any point
//! lies within it, the hybrid 30, the refinement's normals); and the scene stage's global estimators
//! (RANSAC, SC²) on a 20,000-point room pair.
//!
//! Run: `cargo bench -p rgm-benches --bench geom -- --warm-up-time 1 --measurement-time 3`

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use rand::{rngs::StdRng, SeedableRng};
use rgm_benches::{unit_ball_points, SIZES};
use rgm_geom::fpfh::{features, FpfhConfig};
use rgm_geom::normals::{normals_within, NormalsConfig, WithinConfig};
use rgm_geom::testing::room_points;
use rgm_geom::{kabsch, knn_graph, KnnIndex, Point3, PointCloud, RigidTransform, Vector3};
use rgm_registration::methods::fgr::{self, FgrConfig};
use rgm_registration::methods::{icp, ransac, refine, sc2};

const K: usize = 20;

/// A partial-overlap pair like the protocol's: 1,024 points on an ellipsoid (semi-axes 1, 0.6,
/// 0.3, no symmetry axis), each cloud cropped to its 717 points farthest along its own direction,
/// the source moved by a 45°-class pose. Returns (source, target).
fn partial_pair() -> (PointCloud, PointCloud) {
    let shape: Vec<Point3<f64>> = unit_ball_points(1024, 7)
        .iter()
        .map(|p| {
            let d = p.coords.normalize();
            Point3::new(d.x, 0.6 * d.y, 0.3 * d.z)
        })
        .collect();
    let crop = |dir: [f64; 3]| {
        let mut by_height: Vec<(f64, Point3<f64>)> = shape
            .iter()
            .map(|p| (p.x * dir[0] + p.y * dir[1] + p.z * dir[2], *p))
            .collect();
        by_height.sort_by(|a, b| b.0.total_cmp(&a.0));
        PointCloud::new(by_height[..717].iter().map(|h| h.1).collect())
    };
    let pose = RigidTransform::random(&mut StdRng::seed_from_u64(3), 45.0, 0.5);
    (
        crop([0.6, 0.8, 0.0]).transformed(&pose),
        crop([0.0, 0.6, 0.8]),
    )
}

fn knn(c: &mut Criterion) {
    let mut group = c.benchmark_group("knn_graph_k20");
    for n in SIZES {
        let points = unit_ball_points(n, 1);
        group.bench_function(BenchmarkId::from_parameter(n), |b| {
            b.iter(|| knn_graph(&points, K).unwrap())
        });
    }
    group.finish();
}

/// The kNN graph of `knn_graph` on kiddo 5's `ImmutableKdTree`. kiddo orders neighbours by
/// distance only, so ties at the k-th distance could keep any of the tied points; `knn_graph`
/// keeps the lowest indices. So: the k + 1 nearest, and when the (k + 1)-th is as near as the
/// k-th, every point within that distance (`within`, inclusive); then sorted by distance and
/// index.
fn kiddo_knn_graph(points: &[Point3<f64>], k: usize) -> Vec<usize> {
    use kiddo::{ImmutableKdTree, SquaredEuclidean};
    let rows: Vec<[f64; 3]> = points.iter().map(|p| [p.x, p.y, p.z]).collect();
    let tree: ImmutableKdTree<f64, 3> = ImmutableKdTree::new_from_slice(&rows);
    let mut graph = Vec::with_capacity(points.len() * k);
    let qty = std::num::NonZero::new(k + 1).unwrap();
    for (i, q) in rows.iter().enumerate() {
        let mut row: Vec<(f64, u64)> = tree
            .nearest_n::<SquaredEuclidean>(q, qty)
            .into_iter()
            .map(|n| (n.distance, n.item))
            .collect();
        if row.len() == k + 1 && row[k].0 == row[k - 1].0 {
            row = tree
                .within::<SquaredEuclidean>(q, row[k].0)
                .into_iter()
                .map(|n| (n.distance, n.item))
                .collect();
        }
        row.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        graph.push(i);
        graph.extend(
            row.iter()
                .map(|n| n.1 as usize)
                .filter(|&j| j != i)
                .take(k - 1),
        );
    }
    graph
}

fn knn_kiddo(c: &mut Criterion) {
    let mut group = c.benchmark_group("knn_graph_k20_kiddo5");
    for n in SIZES {
        let points = unit_ball_points(n, 1);
        assert_eq!(kiddo_knn_graph(&points, K), knn_graph(&points, K).unwrap());
        group.bench_function(BenchmarkId::from_parameter(n), |b| {
            b.iter(|| kiddo_knn_graph(&points, K))
        });
    }
    group.finish();
}

fn kabsch_717(c: &mut Criterion) {
    let source = unit_ball_points(717, 2);
    let pose = RigidTransform::random(&mut StdRng::seed_from_u64(4), 45.0, 0.5);
    let target: Vec<_> = source.iter().map(|p| pose.apply(p)).collect();
    let weights = vec![1.0; 717];
    c.bench_function("kabsch/717", |b| {
        b.iter(|| kabsch(&source, &target, &weights).unwrap())
    });
}

fn registration(c: &mut Criterion) {
    let (source, target) = partial_pair();
    let mut group = c.benchmark_group("registration_717");
    group.sample_size(20);
    group.bench_function("icp", |b| {
        b.iter(|| icp::register(&source, &target, &icp::IcpConfig::default()).unwrap())
    });
    // The refinement from the identity: the same 45°-class start as ICP's, so every stage runs
    // its full iterations (the worst case after a global method).
    group.bench_function("refine", |b| {
        b.iter(|| {
            refine::refine(
                &source,
                &target,
                &RigidTransform::identity(),
                &refine::RefineConfig::default(),
            )
            .unwrap()
        })
    });
    group.bench_function("normals_fpfh_one_cloud", |b| {
        b.iter(|| {
            features(
                &source.points,
                &KnnIndex::new(&source.points),
                &NormalsConfig::default(),
                &FpfhConfig::default(),
            )
        })
    });
    group.bench_function("fpfh_fgr_pair", |b| {
        b.iter(|| fgr::register(&source, &target, &fgr::FgrConfig::default()).unwrap())
    });
    group.finish();
}

/// The searches a dense scan pair spends most of its time in (issue 57): each of 40,000 points
/// of one sampling of a room corner (its spacing ≈ 1.5 cm) moved by 1 cm, its nearest point of
/// another sampling within 6 cm (the refinement's correspondences and the judges' overlap
/// scores), and its 30 nearest within 12 cm (Open3D's hybrid neighbourhood, FPFH's normals);
/// and the normals of the refinement at the scans' resolution of the other sampling's own
/// points, from every neighbour within 5.4 cm (3.6 spacings, `normals_within`).
fn knn_dense(c: &mut Criterion) {
    let target = room_points(40_000, 2);
    let index = KnnIndex::new(&target);
    let shift = Vector3::new(0.006, -0.006, 0.006);
    let queries: Vec<Point3<f64>> = room_points(40_000, 1).iter().map(|p| p + shift).collect();
    let mut group = c.benchmark_group("knn_dense_40k");
    group.sample_size(10);
    group.bench_function("nearest_within", |b| {
        b.iter(|| {
            queries
                .iter()
                .filter_map(|q| index.nearest_within(q, 0.06))
                .count()
        })
    });
    group.bench_function("any_within", |b| {
        b.iter(|| queries.iter().filter(|q| index.any_within(q, 0.06)).count())
    });
    group.bench_function("hybrid_30", |b| {
        let mut found = Vec::with_capacity(30);
        b.iter(|| {
            let mut total = 0;
            for q in &queries {
                index.hybrid_squared_into(q, 0.12, 30, &mut found);
                total += found.len();
            }
            total
        })
    });
    group.bench_function("normals_within_3_6_spacings", |b| {
        let which: Vec<usize> = (0..target.len()).collect();
        let config = WithinConfig {
            radius: 0.054,
            sparse: NormalsConfig {
                radius: 0.12,
                max_nn: 30,
            },
        };
        b.iter(|| normals_within(&target, &index, &which, &config))
    });
    group.finish();
}

/// The global estimators of the scene stage on a room pair (two samplings of one room corner,
/// 20,000 points each, the source moved by a 45°-class pose): thinning, features, matching,
/// the estimate and the refinement on the thinned pair.
fn scene(c: &mut Criterion) {
    let pose = RigidTransform::random(&mut StdRng::seed_from_u64(5), 45.0, 1.0);
    let source = PointCloud::new(room_points(20_000, 1)).transformed(&pose.inverse());
    let target = PointCloud::new(room_points(20_000, 2));
    let mut group = c.benchmark_group("scene_20k");
    group.sample_size(10);
    group.bench_function("ransac", |b| {
        b.iter(|| ransac::register(&source, &target, &ransac::RansacConfig::default()).unwrap())
    });
    group.bench_function("sc2", |b| {
        b.iter(|| sc2::register(&source, &target, &sc2::Sc2Config::default()).unwrap())
    });
    group.finish();
}

/// Farthest-point sampling of 1,024 of 40,000 points (the thinning by cells of a dense pair):
/// a room's random sampling in the order drawn, and the same points in scan-like strips (sorted
/// by 5 cm bands of x, then y), whose runs of consecutive points lie close together.
fn farthest_points(c: &mut Criterion) {
    let random = PointCloud::new(room_points(40_000, 2));
    let mut strips = random.points.clone();
    strips.sort_by(|a, b| {
        ((a.x * 20.0).floor())
            .total_cmp(&(b.x * 20.0).floor())
            .then(a.y.total_cmp(&b.y))
    });
    let strips = PointCloud::new(strips);
    let mut group = c.benchmark_group("farthest_points_40k");
    group.sample_size(10);
    group.bench_function("random_order", |b| {
        b.iter(|| random.farthest_point_indices(1024))
    });
    group.bench_function("strips", |b| b.iter(|| strips.farthest_point_indices(1024)));
    group.finish();
}

/// FGR's and the scene stage's mutual matching of FPFH features, brute force, at the scene
/// stage's most points (5,000 per cloud; the features of two samplings of one room).
fn feature_matching(c: &mut Criterion) {
    let of = |seed| {
        let cloud = PointCloud::new(room_points(5000, seed));
        let config = FgrConfig::default();
        features(
            &cloud.points,
            &KnnIndex::new(&cloud.points),
            &config.normals,
            &config.fpfh,
        )
    };
    let (source, target) = (of(1), of(2));
    let mut group = c.benchmark_group("fpfh_matching");
    group.sample_size(10);
    group.bench_function("mutual_5000", |b| {
        b.iter(|| fgr::mutual_matches(&source, &target))
    });
    group.finish();
}

criterion_group!(
    benches,
    knn,
    knn_kiddo,
    knn_dense,
    kabsch_717,
    registration,
    scene,
    feature_matching,
    farthest_points
);
criterion_main!(benches);
