use super::*;
use crate::testing::uniform_cube;
use nalgebra::Vector3;
use rand::{rngs::StdRng, SeedableRng};

fn random_cloud(n: usize, seed: u64) -> Vec<Point3<f64>> {
    uniform_cube(n, &mut StdRng::seed_from_u64(seed))
}

#[test]
fn subtrees_built_side_by_side_make_the_same_tree() {
    let cloud = random_cloud(5 * SIDE_BY_SIDE_POINTS, 41);
    let one_by_one = || {
        let mut points = tree_points(&cloud);
        let mut nodes = Vec::new();
        build(&mut nodes, &mut points, 0, usize::MAX);
        (format!("{nodes:?}"), points)
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap();
    let index = pool.install(|| KnnIndex::new(&cloud));
    let (nodes, points) = one_by_one();
    assert_eq!(format!("{:?}", index.nodes), nodes);
    let ids: Vec<u32> = points.iter().map(|&(_, i)| i).collect();
    assert_eq!(index.ids, ids);
    for axis in 0..3 {
        let coords: Vec<f64> = points.iter().map(|(p, _)| p[axis]).collect();
        assert_eq!(index.xyz[axis], coords);
    }
}

/// Every point with its distance to `q`, sorted by distance then index.
fn brute_force(points: &[Point3<f64>], q: &Point3<f64>) -> Vec<(usize, f64)> {
    let mut all: Vec<(usize, f64)> = points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let d = [p.x - q.x, p.y - q.y, p.z - q.z];
            (i, d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        })
        .collect();
    sort_by_distance_then_index(&mut all);
    all.into_iter().map(|(i, d2)| (i, d2.sqrt())).collect()
}

#[test]
fn queries_match_brute_force_on_random_clouds() {
    for seed in 0..5 {
        let points = random_cloud(300 + 50 * seed as usize, seed);
        let index = KnnIndex::new(&points);
        assert_eq!(index.len(), points.len());
        for q in random_cloud(40, 100 + seed) {
            let all = brute_force(&points, &q);
            assert_eq!(index.nearest(&q), all[0]);
            for r in [0.02, 0.1, 0.5] {
                let expected = (all[0].1 < r).then_some(all[0]);
                assert_eq!(index.nearest_within(&q, r), expected, "radius {r}");
            }
            // The nearest's and the fourth's own distances too: a radius at a point itself.
            for r in [0.02, 0.1, 0.5, all[0].1, all[3].1] {
                let nearest = index.nearest_within(&q, r);
                assert_eq!(index.any_within(&q, r), nearest.is_some(), "radius {r}");
            }
            for k in [1, 7, 20] {
                assert_eq!(index.k_nearest(&q, k), all[..k].to_vec());
            }
            let inside: Vec<_> = all.iter().copied().filter(|n| n.1 < 0.3).collect();
            assert_eq!(index.within_radius(&q, 0.3), inside);
            let hybrid: Vec<_> = inside.iter().copied().take(10).collect();
            assert_eq!(index.hybrid(&q, 0.3, 10), hybrid);
        }
    }
}

#[test]
fn any_within_ends_at_the_first_point_found() {
    let points = random_cloud(20_000, 12);
    let index = KnnIndex::new(&points);
    let offers = |search: &dyn Fn()| {
        OFFERS.with(|n| n.set(0));
        search();
        OFFERS.with(|n| n.get())
    };
    let (mut any, mut nearest) = (0, 0);
    for q in &points[..200] {
        assert!(index.any_within(q, 0.2));
        any += offers(&|| assert!(index.any_within(q, 0.2)));
        nearest += offers(&|| assert!(index.nearest_within(q, 0.2).is_some()));
    }
    // Each query finds itself in its own leaf and stops there: one offer each, where the
    // nearest's search goes on to the points and cells that could still be nearer.
    assert_eq!(any, 200);
    assert!(nearest > any, "{nearest} offers");
    // With nothing within reach it finds nothing, as the nearest's search does.
    let far = Point3::new(3.0, 3.0, 3.0);
    assert!(!index.any_within(&far, 0.5));
    assert_eq!(index.nearest_within(&far, 0.5), None);
}

/// Points on a surface fill little of the cells a split leaves: a search prunes by each node's
/// tight box, so a query farther than its radius from a plane of points visits no leaf, and
/// one just above it only the leaves under it.
#[test]
fn a_search_skips_the_space_around_a_surface() {
    // A 100 × 100 grid at spacing 0.01 on z = 0.
    let points: Vec<_> = (0..10_000)
        .map(|i| Point3::new((i % 100) as f64 * 0.01, (i / 100) as f64 * 0.01, 0.0))
        .collect();
    let index = KnnIndex::new(&points);
    let leaves = |search: &dyn Fn()| {
        LEAVES.with(|n| n.set(0));
        search();
        LEAVES.with(|n| n.get())
    };
    let above = Point3::new(0.503, 0.497, 0.3);
    assert_eq!(leaves(&|| assert!(!index.any_within(&above, 0.2))), 0);
    assert_eq!(
        leaves(&|| assert_eq!(index.nearest_within(&above, 0.2), None)),
        0
    );
    // 0.05 above the grid point (0.5, 0.5): the nearest within 0.1, from the few leaves whose
    // boxes reach that far.
    let near = Point3::new(0.5, 0.5, 0.05);
    let visited = leaves(&|| {
        let (i, d) = index.nearest_within(&near, 0.1).unwrap();
        assert_eq!((i, d), (50 * 100 + 50, 0.05));
    });
    assert!((1..=4).contains(&visited), "{visited} leaves");
}

#[test]
fn many_identical_points_do_not_panic_and_ties_go_by_index() {
    let mut points = vec![Point3::new(0.5, -0.25, 0.125); 200];
    points.extend(random_cloud(50, 9));
    let index = KnnIndex::new(&points);
    let q = Point3::new(0.5, -0.25, 0.125);
    let got = index.k_nearest(&q, 20);
    assert_eq!(got, (0..20).map(|i| (i, 0.0)).collect::<Vec<_>>());
    assert_eq!(index.nearest(&q), (0, 0.0));
    assert_eq!(index.within_radius(&q, 1e-9).len(), 200);
    let graph = knn_graph(&points, 5).unwrap();
    // Point 7's own row starts with itself, then the lowest other indices at distance 0.
    assert_eq!(&graph[7 * 5..8 * 5], &[7, 0, 1, 2, 3]);
}

/// The candidates `search` offers.
fn offers(search: impl FnOnce()) -> usize {
    OFFERS.with(|n| n.set(0));
    search();
    OFFERS.with(|n| n.get())
}

/// Issue 59, E2: a query at a place shared by k points visited every one of them (each
/// cell tied with the best distance may still hold a lower index): a LiDAR sweep with 50k
/// zero returns went from 2.3 s to 58 s. The answers stay those of brute force.
#[test]
fn copies_of_one_point_cost_a_query_what_it_returns_not_their_number() {
    let mut points = random_cloud(3000, 12);
    // 30 % of the points at the origin, their indices spread through the cloud.
    for i in (0..points.len()).step_by(3) {
        points[i] = Point3::origin();
    }
    points.extend(vec![Point3::new(0.25, 0.25, 0.25); 20_000]);
    let index = KnnIndex::new(&points);
    for q in [
        Point3::origin(),
        Point3::new(0.25, 0.25, 0.25),
        Point3::new(0.1, -0.2, 0.3),
    ] {
        let all = brute_force(&points, &q);
        for k in [1, 10, 30] {
            let mut got = Vec::new();
            let cost = offers(|| got = index.k_nearest(&q, k));
            assert_eq!(got, all[..k].to_vec());
            // Before: at least the copies there (1,000 at the origin, 20,000 at the other).
            assert!(cost < 1000, "{cost} offers for k = {k} at {q}");
        }
        assert_eq!(index.nearest(&q), all[0]);
        let hybrid: Vec<_> = all.iter().copied().filter(|n| n.1 < 0.1).take(30).collect();
        assert_eq!(index.hybrid(&q, 0.1, 30), hybrid);
        let inside: Vec<_> = all.iter().copied().filter(|n| n.1 < 0.05).collect();
        assert_eq!(index.within_radius(&q, 0.05), inside);
    }
    // Nothing but copies: one node, a query's cost its k.
    let same = KnnIndex::new(&vec![Point3::new(1.0, 2.0, 3.0); 100_000]);
    let q = Point3::new(1.0, 2.0, 3.0);
    let cost = offers(|| {
        assert_eq!(
            same.k_nearest(&q, 5),
            (0..5).map(|i| (i, 0.0)).collect::<Vec<_>>()
        );
    });
    assert!(cost <= 11, "{cost}");
    assert_eq!(offers(|| assert_eq!(same.nearest(&q), (0, 0.0))), 2);
}

#[test]
fn grid_with_shared_coordinates_and_ties_matches_brute_force() {
    // A 6×6×6 lattice: every coordinate shared by 36 points, distances tied everywhere.
    let points: Vec<Point3<f64>> = (0..216)
        .map(|i| Point3::new((i % 6) as f64, (i / 6 % 6) as f64, (i / 36) as f64))
        .collect();
    let index = KnnIndex::new(&points);
    for q in points
        .iter()
        .step_by(7)
        .chain([Point3::new(2.5, 2.5, 2.5)].iter())
    {
        let all = brute_force(&points, q);
        for k in [1, 5, 27] {
            assert_eq!(index.k_nearest(q, k), all[..k].to_vec());
        }
        let inside: Vec<_> = all.iter().copied().filter(|n| n.1 < 1.5).collect();
        assert_eq!(index.within_radius(q, 1.5), inside);
    }
}

#[test]
fn knn_graph_rows_are_self_then_brute_force_order() {
    let points = random_cloud(120, 3);
    let k = 6;
    let graph = knn_graph(&points, k).unwrap();
    assert_eq!(graph.len(), points.len() * k);
    for (i, p) in points.iter().enumerate() {
        let expected: Vec<usize> = brute_force(&points, p)
            .iter()
            .take(k)
            .map(|n| n.0)
            .collect();
        assert_eq!(&graph[i * k..(i + 1) * k], expected.as_slice(), "row {i}");
    }
}

#[test]
fn knn_graph_rejects_bad_input() {
    let points = random_cloud(4, 1);
    assert_eq!(
        knn_graph(&points, 5),
        Err(GeomError::TooFewPoints {
            op: "knn_graph",
            needed: 5,
            got: 4
        })
    );
    let mut bad = points.clone();
    bad[2].y = f64::NAN;
    assert_eq!(
        knn_graph(&bad, 2),
        Err(GeomError::NonFinite { op: "knn_graph" })
    );
    assert_eq!(knn_graph(&points, 4).unwrap().len(), 16);
}

#[test]
fn empty_index_answers_nothing() {
    let index = KnnIndex::new(&[]);
    assert!(index.is_empty());
    let q = Point3::origin();
    assert_eq!(index.nearest(&q), (usize::MAX, f64::INFINITY));
    assert!(index.k_nearest(&q, 3).is_empty());
    assert!(index.within_radius(&q, 1.0).is_empty());
}

#[test]
fn k_larger_than_the_cloud_returns_all() {
    let points = random_cloud(5, 2);
    let q = Point3::new(0.1, 0.2, 0.3);
    assert_eq!(
        KnnIndex::new(&points).k_nearest(&q, 50),
        brute_force(&points, &q)
    );
}

#[test]
fn a_search_from_a_guess_finds_what_one_without_finds() {
    // The lattice of ties (a guess tied with the answer but of a higher index must lose), then
    // random points; guesses near and far, tied, beyond the radius and out of range.
    let lattice: Vec<Point3<f64>> = (0..216)
        .map(|i| Point3::new((i % 6) as f64, (i / 6 % 6) as f64, (i / 36) as f64) * 0.1)
        .collect();
    for points in [lattice, random_cloud(2000, 21)] {
        let index = KnnIndex::new(&points);
        let mut cheaper = 0;
        for (n, q) in random_cloud(60, 22).iter().chain(&points[..40]).enumerate() {
            let q = q * 0.5;
            for radius in [0.03, 0.1, 0.3] {
                let expected = index.nearest_within(&q, radius);
                let answer = expected.map_or(0, |(i, _)| i);
                for guess in [
                    answer,
                    answer + 1,
                    answer.saturating_sub(1),
                    0,
                    n,
                    points.len(),
                ] {
                    assert_eq!(
                        index.nearest_within_from(&q, radius, guess),
                        expected,
                        "query {n}, radius {radius}, guess {guess}"
                    );
                }
                if expected.is_some() {
                    let from = offers(|| {
                        index.nearest_within_from(&q, radius, answer);
                    });
                    let without = offers(|| {
                        index.nearest_within(&q, radius);
                    });
                    cheaper += usize::from(from < without);
                }
            }
        }
        assert!(cheaper > 20, "{cheaper} searches cheaper from their answer");
    }
}

#[test]
fn nearest_among_a_centres_neighbours_is_the_search_s_answer_or_none() {
    // The lattice of ties, then random points; queries moved from a centre by up to the reach.
    let lattice: Vec<Point3<f64>> = (0..216)
        .map(|i| Point3::new((i % 6) as f64, (i / 6 % 6) as f64, (i / 36) as f64) * 0.1)
        .collect();
    for (points, reach) in [(lattice, 0.25), (random_cloud(3000, 31), 0.1)] {
        let index = KnnIndex::new(&points);
        let mut rng = StdRng::seed_from_u64(32);
        let (mut proved, mut none_proved) = (0, 0);
        for centre in (0..points.len()).step_by(7) {
            let mut around = Vec::new();
            index.for_each_within(&points[centre], reach, |i, _| around.push(i as u32));
            for step in [0.0, 0.01, 0.05, 0.1, 0.3] {
                let shift: Vector3<f64> = uniform_cube(1, &mut rng)[0].coords * step;
                let q = points[centre] + shift;
                for radius in [0.02, 0.05, 0.5] {
                    let expected = index.nearest_within(&q, radius);
                    match nearest_among(&points, &around, centre, reach, &q, radius) {
                        Some(answer) => {
                            assert_eq!(answer, expected, "centre {centre}, step {step}");
                            proved += 1;
                            none_proved += usize::from(answer.is_none());
                        }
                        None => assert!(step > 0.0, "centre {centre}: no proof at the centre"),
                    }
                }
            }
        }
        assert!(
            proved > 300 && none_proved > 10,
            "{proved} proved, {none_proved} of none"
        );
    }
}

/// The nodes' list is made long enough at once for any tree: every size up to a few leaves,
/// larger clouds, and clouds of copies.
#[test]
fn a_tree_never_outgrows_its_nodes_list() {
    let mut sizes: Vec<usize> = (0..200).collect();
    sizes.extend([1000, 4097, 9000, 20_000]);
    for n in sizes {
        let points = random_cloud(n, n as u64);
        let index = KnnIndex::new(&points);
        assert!(
            index.nodes.len() <= most_nodes(n),
            "{n} points: {} nodes",
            index.nodes.len()
        );
        let copies = vec![Point3::new(0.5, 0.5, 0.5); n];
        assert!(KnnIndex::new(&copies).nodes.len() <= most_nodes(n));
    }
}
