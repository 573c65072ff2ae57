use super::*;

/// Open3D's pair terms of one pair written plainly, as [`pair_terms`]' reference:
/// `[w·n, u·n, φ, θ, d]`, dot products summed x, y, z in that order (as Eigen does for
/// 3-vectors).
fn reference_pair_terms(
    p1: &Point3<f64>,
    n1: &Vector3<f64>,
    p2: &Point3<f64>,
    n2: &Vector3<f64>,
) -> [f64; 5] {
    let dot = |a: &Vector3<f64>, b: &Vector3<f64>| a.x * b.x + a.y * b.y + a.z * b.z;
    let mut dp = p2 - p1;
    let d = dot(&dp, &dp).sqrt();
    if d == 0.0 {
        return [0.0; 5];
    }
    let angle1 = dot(n1, &dp) / d;
    let angle2 = dot(n2, &dp) / d;
    let (u, n_other, theta) = if angle1.abs() < angle2.abs() {
        dp = -dp;
        (n2, n1, -angle2)
    } else {
        (n1, n2, angle1)
    };
    let v = dp.cross(u);
    let v_norm = dot(&v, &v).sqrt();
    if v_norm == 0.0 {
        return [0.0; 5];
    }
    let v = v / v_norm;
    let w = u.cross(&v);
    let phi = dot(&v, n_other);
    [dot(&w, n_other), dot(u, n_other), phi, theta, d]
}

/// α's bin as the features take it.
fn alpha_bin(y: f64, x: f64) -> usize {
    alpha_bin_at(alpha_place(y, x), y, x)
}

#[test]
fn pair_features_by_hand() {
    // p1 at the origin with normal +z, p2 at (1, 0, 0) with normal +x.
    // dp = (1,0,0): angle1 = n1·dp = 0, angle2 = 1 → acos 0 = π/2 > acos 1 = 0: swap.
    // u = n2 = +x, dp = (−1,0,0), θ = −angle2 = −1; v = dp × u = 0 → all zero.
    let o = Point3::origin();
    let x = Point3::new(1.0, 0.0, 0.0);
    assert_eq!(
        pair_features(&o, &Vector3::z(), &x, &Vector3::x()),
        [0.0; 4]
    );
    // Normals +z and +y, dp = (1,0,0): angle1 = angle2 = 0, no swap; u = +z, θ = 0,
    // v = dp × u = (1,0,0)×(0,0,1) = (0,−1,0), w = u × v = (0,0,1)×(0,−1,0) = (1,0,0).
    // φ = v·n2 = −1, α = atan2(w·n2, u·n2) = atan2(0, 0) = 0, d = 1.
    assert_eq!(
        pair_features(&o, &Vector3::z(), &x, &Vector3::y()),
        [0.0, -1.0, 0.0, 1.0]
    );
    // Normals +z and (0, 1, 1)/√2 at distance 2: no swap (angles 0 and 0);
    // φ = v·n2 = −1/√2, α = atan2(w·n2, u·n2) = atan2(0, 1/√2) = 0.
    let n2 = Vector3::new(0.0, 1.0, 1.0).normalize();
    let f = pair_features(&o, &Vector3::z(), &Point3::new(2.0, 0.0, 0.0), &n2);
    assert!(
        (f[1] + 0.5f64.sqrt()).abs() < 1e-15 && f[0] == 0.0 && f[2] == 0.0 && f[3] == 2.0,
        "{f:?}"
    );
    // Normals +z and −z: no swap, v = (0,−1,0), w = (1,0,0), φ = 0, α = atan2(0, −1) = π.
    let f = pair_features(&o, &Vector3::z(), &x, &(-Vector3::z()));
    assert!(
        (f[0] - std::f64::consts::PI).abs() < 1e-15 && f[1] == 0.0,
        "{f:?}"
    );
    // Coincident points: zero.
    assert_eq!(
        pair_features(&o, &Vector3::z(), &o, &Vector3::y()),
        [0.0; 4]
    );
}

#[test]
fn pair_features_do_not_depend_on_the_order() {
    let (p1, p2) = (Point3::new(0.1, 0.2, 0.3), Point3::new(0.5, -0.1, 0.2));
    let (n1, n2) = (
        Vector3::new(0.2, 0.9, 0.1).normalize(),
        Vector3::new(-0.5, 0.3, 0.8).normalize(),
    );
    let a = pair_features(&p1, &n1, &p2, &n2);
    let b = pair_features(&p2, &n2, &p1, &n1);
    for (x, y) in a.iter().zip(&b) {
        assert!((x - y).abs() < 1e-12, "{a:?} vs {b:?}");
    }
}

#[test]
fn bins_split_the_range_in_eleven_and_clamp() {
    assert_eq!(bin(-1.0, -1.0, 2.0), 0);
    assert_eq!(bin(1.0, -1.0, 2.0), 10);
    assert_eq!(bin(0.0, -1.0, 2.0), 5);
    assert_eq!(bin(-1.0 + 2.0 / 11.0 - 1e-9, -1.0, 2.0), 0);
    assert_eq!(bin(-1.0 + 2.0 / 11.0 + 1e-9, -1.0, 2.0), 1);
    assert_eq!(
        bin(
            -std::f64::consts::PI,
            -std::f64::consts::PI,
            2.0 * std::f64::consts::PI
        ),
        0
    );
    assert_eq!(
        bin(
            std::f64::consts::PI,
            -std::f64::consts::PI,
            2.0 * std::f64::consts::PI
        ),
        10
    );
}

/// The polynomial's bins are libm's: on a million random directions, on directions a
/// hair either side of every bin edge, and on the zeros' and NaN's.
#[test]
fn alpha_bins_are_those_of_libms_atan2() {
    use rand::{rngs::StdRng, Rng, SeedableRng};
    use std::f64::consts::PI;
    let libm = |y: f64, x: f64| bin(y.atan2(x), -PI, 2.0 * PI);
    let mut rng = StdRng::seed_from_u64(7);
    for _ in 0..1_000_000 {
        let (y, x) = (rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0));
        assert_eq!(alpha_bin(y, x), libm(y, x), "atan2({y}, {x})");
    }
    for edge in 0..=BINS {
        let at = -PI + 2.0 * PI * edge as f64 / BINS as f64;
        for off in [0.0, 1e-15, 1e-12, 1e-9, 1e-7, 5e-7, 1e-6, 2e-6, 1e-5] {
            for angle in [at - off, at + off] {
                let length = rng.gen_range(0.1..1.0);
                let (y, x) = (length * angle.sin(), length * angle.cos());
                assert_eq!(alpha_bin(y, x), libm(y, x), "atan2({y}, {x})");
            }
        }
    }
    for (y, x) in [
        (0.0, 0.0),
        (-0.0, 0.0),
        (0.0, -0.0),
        (-0.0, -0.0),
        (0.0, -1.0),
    ]
    .into_iter()
    .chain([(-0.0, -1.0), (0.5, f64::NAN), (f64::NAN, 0.5)])
    {
        assert_eq!(alpha_bin(y, x), libm(y, x), "atan2({y}, {x})");
    }
}

/// Eight pairs side by side give the plain reference's values to the bit: random pairs, pairs
/// that swap and pairs that do not, a coinciding point, a line along the normal, and the
/// 1-ulp tie of the swap test.
#[test]
fn pairs_side_by_side_are_the_references_to_the_bit() {
    use rand::{rngs::StdRng, Rng, SeedableRng};
    let mut rng = StdRng::seed_from_u64(11);
    let unit = |rng: &mut StdRng| {
        Vector3::new(
            rng.gen_range(-1.0..1.0),
            rng.gen_range(-1.0..1.0),
            rng.gen_range(-1.0..1.0),
        )
        .normalize()
    };
    for round in 0..2000 {
        let p1 = Point3::new(rng.gen_range(-1.0..1.0), 0.3, rng.gen_range(-1.0..1.0));
        let n1 = unit(&mut rng);
        let mut others: Vec<(Point3<f64>, Vector3<f64>)> = (0..LANES)
            .map(|_| {
                let offset = unit(&mut rng) * rng.gen_range(0.01..0.5);
                (p1 + offset, unit(&mut rng))
            })
            .collect();
        if round % 4 == 0 {
            others[1] = (p1, unit(&mut rng)); // coinciding
            others[2] = (p1 + n1 * 0.2, n1); // along the normal
            others[3] = (p1 + Vector3::new(0.1, 0.0, 0.0), n1); // shared normal: a tie
        }
        let mut p = [[0.0; LANES]; 3];
        let mut n = [[0.0; LANES]; 3];
        for (k, (q, m)) in others.iter().enumerate() {
            for axis in 0..3 {
                p[axis][k] = q[axis];
                n[axis][k] = m[axis];
            }
        }
        let lanes = pair_terms((&p1, &n1), &p, &n);
        for (k, (q, m)) in others.iter().enumerate() {
            let one = reference_pair_terms(&p1, &n1, q, m);
            let side = [0, 1, 2, 3, 4].map(|t| lanes[t][k]);
            assert_eq!(
                side.map(f64::to_bits),
                one.map(f64::to_bits),
                "round {round}, lane {k}"
            );
        }
    }
}

#[test]
fn three_points_by_hand() {
    // Three points on the x axis, 1 apart, normals +z, radius 1.5: the ends see only the
    // middle. Every pair, either direction, has α = φ = θ = 0 (v = ∓y, w = ±x, n2 = +z), so
    // bin 5 of each block. SPFH: 100 at bins 5, 16, 27 for every point (an end: one pair of
    // +100; the middle: two of +50). FPFH: the neighbours' SPFHs weighted by 1/1², each
    // block rescaled to 100, plus the own 100 → 200 at bins 5, 16, 27 for every point.
    let points = vec![
        Point3::new(0.0, 0.0, 0.0),
        Point3::new(1.0, 0.0, 0.0),
        Point3::new(2.0, 0.0, 0.0),
    ];
    let normals = vec![Vector3::z(); 3];
    let config = FpfhConfig {
        radius: 1.5,
        max_nn: 100,
    };
    let f = compute_fpfh(&points, &normals, &KnnIndex::new(&points), &config);
    for feature in &f {
        for (c, v) in feature.iter().enumerate() {
            let expected = if c % BINS == 5 { 200.0 } else { 0.0 };
            assert!((v - expected).abs() < 1e-12, "bin {c}: {v}");
        }
    }
}

/// Pinned from Open3D 0.20 on ModelNet40 `airplane_0627`, normals as in
/// `normals::tests::normals_match_open3d`. On that shape all 1,024 features agree with
/// Open3D's bit for bit (checked against the full array); three are pinned:
///
/// ```python
/// f = o3d.pipelines.registration.compute_fpfh_feature(pcd, o3d.geometry.KDTreeSearchParamHybrid(radius=0.4, max_nn=100))
/// np.asarray(f.data).T[[0, 2, 500]]
/// ```
#[test]
fn features_match_open3d() {
    let cloud = crate::testing::airplane();
    let f = features(
        &cloud.points,
        &KnnIndex::new(&cloud.points),
        &NormalsConfig::default(),
        &FpfhConfig::default(),
    );
    let pinned: [(usize, [f64; 33]); 3] = [
        (
            0,
            [
                8.8848057954148,
                16.547166721833257,
                13.548610693741033,
                15.412833186237904,
                28.156744002453046,
                44.33389746245699,
                24.46009754770327,
                21.89519059932341,
                14.240524337787551,
                6.281950432485925,
                6.238179220562577,
                34.651038608212424,
                21.080500139720016,
                16.371082937158562,
                22.69462674181578,
                23.84562397712242,
                24.942413617853994,
                18.11662441901884,
                15.553120479879016,
                8.657395634162508,
                8.677736285418915,
                5.409837159637393,
                13.327774515907588,
                22.607298225610784,
                29.8741421988707,
                24.700521007671313,
                12.552800783686685,
                1.2939132736241332,
                8.695210919267126,
                14.385621074617367,
                15.168534767226,
                36.406813619950086,
                20.987369613568212,
            ],
        ),
        (
            2,
            [
                7.055836172733404,
                21.01895107880684,
                2.961751619088029,
                1.441664595946302,
                6.20663579187719,
                40.18215665634877,
                42.278356720166926,
                22.830854160685917,
                28.219137127909573,
                24.033237595369734,
                3.7714184810674025,
                5.159091501217923,
                17.043120792245993,
                23.443138026531955,
                31.00511176500745,
                20.22971238997926,
                21.81774088197744,
                13.298720409404812,
                24.08450726771084,
                17.777776233168886,
                17.496056792967707,
                8.645023939787656,
                37.98156035690336,
                36.940088403829094,
                29.378943188852034,
                30.65998927718544,
                28.469593485773466,
                17.655797716293584,
                4.92282130282062,
                3.5763644372324337,
                3.886398519026251,
                4.295958021499601,
                2.232485290584233,
            ],
        ),
        (
            500,
            [
                16.69849196277767,
                3.5856227217027223,
                15.090409822193003,
                5.515576056527119,
                10.276730046743094,
                67.55232907243109,
                9.447361865009638,
                14.626577251138706,
                21.309424740365067,
                9.388155826034488,
                26.509320635077493,
                53.78067478799315,
                10.416708971814023,
                2.661529064577639,
                6.017929503269723,
                27.106659502124447,
                38.3511947117924,
                32.1847564843135,
                6.356419319103762,
                5.709976963782962,
                6.716235910754604,
                10.697914780473864,
                10.327353774709692,
                8.005411884058566,
                18.604473705105317,
                22.009276340434738,
                30.743884174794275,
                12.350140142043337,
                33.047015566212146,
                30.137720900890717,
                13.975275265592684,
                12.660175097372276,
                8.139273148786272,
            ],
        ),
    ];
    for (i, expected) in pinned {
        for (c, (got, want)) in f[i].iter().zip(&expected).enumerate() {
            assert!(
                (got - want).abs() < 1e-12,
                "point {i} bin {c}: {got} vs {want}"
            );
        }
    }
}

#[test]
fn features_are_invariant_to_rigid_motion() {
    use crate::testing::box_surface;
    use crate::RigidTransform;
    use rand::{rngs::StdRng, SeedableRng};
    let cloud = box_surface(400, 6);
    let pose = RigidTransform::random(&mut StdRng::seed_from_u64(3), 45.0, 0.5);
    let moved = cloud.transformed(&pose);
    let of = |c: &crate::PointCloud| {
        features(
            &c.points,
            &KnnIndex::new(&c.points),
            &NormalsConfig::default(),
            &FpfhConfig::default(),
        )
    };
    let (a, b) = (of(&cloud), of(&moved));
    let mut max_diff: f64 = 0.0;
    for (x, y) in a.iter().zip(&b) {
        assert!(
            (x.iter().sum::<f64>() - 600.0).abs() < 1e-9,
            "each block sums to 200"
        );
        for (u, v) in x.iter().zip(y) {
            max_diff = max_diff.max((u - v).abs());
        }
    }
    // Bins may flip for values on a bin edge; that moves at most a few percent.
    assert!(max_diff < 5.0, "max difference {max_diff}");
}

/// Every build of the side-by-side pairs this processor runs adds the same histogram: AVX-512
/// (where there is one), AVX2 (the processors without) and the plain one.
#[test]
fn every_build_of_the_pairs_adds_the_same_histogram() {
    use rand::{rngs::StdRng, Rng, SeedableRng};
    let mut rng = StdRng::seed_from_u64(3);
    let points: Vec<Point3<f64>> = (0..300)
        .map(|_| Point3::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), 0.1))
        .collect();
    let normals: Vec<Vector3<f64>> = (0..300)
        .map(|_| Vector3::new(rng.gen_range(-0.3..0.3), rng.gen_range(-0.3..0.3), 1.0).normalize())
        .collect();
    let neighbours: Vec<(usize, f64)> = (1..300).map(|j| (j, 0.0)).collect();
    let centre = (&points[0], &normals[0]);
    let mut plain = [0.0; FPFH_LEN];
    add_pairs_any(&mut plain, centre, &neighbours, (&points, &normals), 0.5);
    assert_eq!(plain.iter().sum::<f64>(), 3.0 * 0.5 * 299.0);
    #[cfg(target_arch = "x86_64")]
    {
        let mut builds = Vec::new();
        if std::arch::is_x86_feature_detected!("avx2") {
            let mut hist = [0.0; FPFH_LEN];
            // SAFETY: the CPU has AVX2.
            unsafe { add_pairs_avx2(&mut hist, centre, &neighbours, (&points, &normals), 0.5) };
            builds.push(hist);
        }
        if std::arch::is_x86_feature_detected!("avx512f") {
            let mut hist = [0.0; FPFH_LEN];
            // SAFETY: the CPU has AVX-512F.
            unsafe { add_pairs_avx512(&mut hist, centre, &neighbours, (&points, &normals), 0.5) };
            builds.push(hist);
        }
        for hist in builds {
            assert_eq!(hist, plain);
        }
    }
}
