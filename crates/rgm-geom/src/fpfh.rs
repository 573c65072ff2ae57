//! FPFH features (Rusu, Blodow & Beetz 2009) as Open3D's `compute_fpfh_feature` computes them.
//!
//! 1. Neighbours of each point: the at most `max_nn` nearest strictly within `radius`, sorted;
//!    the first (the point itself) is skipped.
//! 2. SPFH: for each neighbour, Open3D's pair features (φ-like angle α ∈ [−π, π], φ ∈ [−1, 1],
//!    θ ∈ [−1, 1] — see [`pair_features`]) are binned into 11 bins each, every pair adding
//!    `100 / (neighbours − 1)`: three 11-bin histograms, 33 values summing to 300.
//! 3. FPFH: the neighbours' SPFHs weighted by 1 / squared distance (zero distances skipped),
//!    each 11-bin block rescaled to sum to 100, plus the point's own SPFH.
//!
//! A point without neighbours other than itself gets an all-zero feature, as in Open3D.
//!
//! Every operation follows Open3D's order (dot products x + y + z, the 1/d² weights divided in,
//! block sums accumulated neighbour by neighbour), and with [`crate::normals`]' Open3D-exact
//! normals the features of ModelNet40 `airplane_0627` equal Open3D 0.20's bit for bit. That
//! matters: where two neighbours share a normal, Open3D's swap test compares equal angles and
//! decides the sign of θ on the last bit.

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use crate::knn::{KnnIndex, Neighbourhoods};
use crate::normals::{estimate_normals, normals_from_neighbourhoods, NormalsConfig};

/// Bins per pair feature.
const BINS: usize = 11;
/// Length of one feature: three 11-bin histograms.
pub const FPFH_LEN: usize = 3 * BINS;

/// One point's FPFH descriptor.
pub type Fpfh = [f64; FPFH_LEN];

/// Settings of [`compute_fpfh`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FpfhConfig {
    /// Neighbourhood radius (default 0.4 for shapes in the unit sphere: the issue's Open3D setup).
    pub radius: f64,
    /// Most neighbours, nearest first (default 100, the usual Open3D setting).
    pub max_nn: usize,
}

impl Default for FpfhConfig {
    fn default() -> Self {
        Self {
            radius: 0.4,
            max_nn: 100,
        }
    }
}

/// Open3D's pair features of (p1, n1) and (p2, n2): `[α, φ, θ, d]`. The pair is swapped (and
/// the direction negated) when that makes the angle between the first normal and the line
/// smaller, so the features do not depend on which point is the source. All zero when the
/// points coincide or when the line is parallel to the chosen first normal.
pub fn pair_features(
    p1: &Point3<f64>,
    n1: &Vector3<f64>,
    p2: &Point3<f64>,
    n2: &Vector3<f64>,
) -> [f64; 4] {
    let [alpha_sine, alpha_cosine, phi, theta, d] = pair_terms(p1, n1, p2, n2);
    [alpha_sine.atan2(alpha_cosine), phi, theta, d]
}

/// [`pair_features`] before α's angle is taken: `[w·n, u·n, φ, θ, d]`, α being the atan2 of
/// the first two (all zero where the features are).
#[inline]
fn pair_terms(
    p1: &Point3<f64>,
    n1: &Vector3<f64>,
    p2: &Point3<f64>,
    n2: &Vector3<f64>,
) -> [f64; 5] {
    let mut dp = p2 - p1;
    let d = dot(&dp, &dp).sqrt();
    if d == 0.0 {
        return [0.0; 5];
    }
    let angle1 = dot(n1, &dp) / d;
    let angle2 = dot(n2, &dp) / d;
    // Open3D writes `acos|a₁| > acos|a₂|`; acos is decreasing, so that is `|a₁| < |a₂|` — and
    // on 1-ulp ties (where libm's acos returns equal values) Open3D's build decides as `<`.
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

/// `a · b`, summed x, y, z in that order (as Eigen does for 3-vectors: Open3D's features are
/// reproduced to the last bit).
#[inline]
fn dot(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    a.x * b.x + a.y * b.y + a.z * b.z
}

/// The bin of `value` in [lo, lo + width) split into 11, clamped to the valid bins: the floor,
/// as the cast's truncation towards zero and saturation at 0 give it for the valid bins (and a
/// libm `floor` call is costly).
#[inline]
fn bin(value: f64, lo: f64, width: f64) -> usize {
    ((BINS as f64 * (value - lo) / width) as usize).min(BINS - 1)
}

/// `bin(y.atan2(x), −π, 2π)`, α's bin, without libm's atan2 (a quarter of FPFH's time) where a
/// polynomial arctangent proves it: that is within 4.4e-8 rad of the angle (and so within
/// 7.7e-8 of its place among the bins), and where it lies more than 1e-6 from a bin's edge the
/// bin is the one libm's angle falls in, to the last bit of the features. Within 1e-6 of an
/// edge (about two pairs in a million), for both zeros and for NaN, libm decides.
#[inline]
fn alpha_bin(y: f64, x: f64) -> usize {
    use std::f64::consts::{FRAC_PI_2, PI};
    // atan(a) ≈ a·P(a²) on [0, 1]: least squares at Chebyshev nodes, weighted towards the
    // largest error; 4.31e-8 at most on a grid of 2·10⁷ points (`docs/speed.md`).
    const P: [f64; 8] = [
        0.9999992490880176,
        -0.33329538038522993,
        0.1994308118814019,
        -0.13892041200850516,
        0.09601656395261901,
        -0.055381697869528415,
        0.021509254242414864,
        -0.003960257233014637,
    ];
    let (ax, ay) = (x.abs(), y.abs());
    // NaN for two zeros, and where x or y is NaN made so (`min` and `max` pass a NaN over):
    // libm below.
    let a = ax.min(ay) / ax.max(ay) + (x + y) * 0.0;
    // P(s) by Estrin's scheme: a chain of four steps where Horner's has eight (the pairs'
    // work overlaps only so far; the chain is what each pair waits on).
    let s = a * a;
    let (s2, s4) = (s * s, s * s * (s * s));
    let low = (P[0] + P[1] * s) + s2 * (P[2] + P[3] * s);
    let high = (P[4] + P[5] * s) + s2 * (P[6] + P[7] * s);
    let turned = a * (low + s4 * high);
    // The octant and the half-plane without branches (the signs are a coin toss each pair):
    // π/2 − angle where |y| > |x|, π − that where x < 0, negated where y is.
    let steep = (ay > ax) as u8 as f64;
    let turned = turned + steep * (FRAC_PI_2 - 2.0 * turned);
    let back = x.is_sign_negative() as u8 as f64;
    let angle = (turned + back * (PI - 2.0 * turned)).copysign(y);
    let place = (angle + PI) * (BINS as f64 / (2.0 * PI));
    // The cast truncates (a libm `floor` call is costly) and takes a NaN to 0, its fraction
    // staying NaN.
    let below = place as usize;
    let fraction = place - below as f64;
    if fraction > 1e-6 && fraction < 1.0 - 1e-6 {
        below.min(BINS - 1)
    } else {
        bin(y.atan2(x), -PI, 2.0 * PI)
    }
}

/// FPFH features of a bare cloud (`index` must index `points`): normals by
/// [`estimate_normals`], then [`compute_fpfh`], sharing one neighbour search when the normals'
/// neighbourhood fits inside FPFH's (the defaults). // (N, 33)
pub fn features(
    points: &[Point3<f64>],
    index: &KnnIndex,
    normals: &NormalsConfig,
    fpfh: &FpfhConfig,
) -> Vec<Fpfh> {
    let neighbourhoods = Neighbourhoods::hybrid(index, points, fpfh.radius, fpfh.max_nn);
    let normal_vectors = if normals.radius <= fpfh.radius && normals.max_nn <= fpfh.max_nn {
        normals_from_neighbourhoods(points, &neighbourhoods, normals)
    } else {
        estimate_normals(points, index, normals)
    };
    fpfh_from_neighbourhoods(points, &normal_vectors, &neighbourhoods)
}

/// FPFH features of `points` with unit `normals`; `index` must index `points`. // (N, 33)
pub fn compute_fpfh(
    points: &[Point3<f64>],
    normals: &[Vector3<f64>],
    index: &KnnIndex,
    config: &FpfhConfig,
) -> Vec<Fpfh> {
    let neighbourhoods = Neighbourhoods::hybrid(index, points, config.radius, config.max_nn);
    fpfh_from_neighbourhoods(points, normals, &neighbourhoods)
}

/// FPFH from the points' hybrid neighbourhoods (as searched, self first). // (N, 33)
fn fpfh_from_neighbourhoods(
    points: &[Point3<f64>],
    normals: &[Vector3<f64>],
    neighbourhoods: &Neighbourhoods,
) -> Vec<Fpfh> {
    let n = points.len();
    let around = |i: usize| neighbourhoods.get(i);

    // Each point's histograms are its own: the points run side by side.
    let mut spfh = vec![[0.0; FPFH_LEN]; n]; // (N, 33)
    spfh.par_iter_mut().enumerate().for_each(|(i, hist)| {
        let nb = around(i);
        if nb.len() < 2 {
            return;
        }
        let increment = 100.0 / (nb.len() - 1) as f64;
        for &(j, _) in &nb[1..] {
            let [alpha_sine, alpha_cosine, phi, theta, _] =
                pair_terms(&points[i], &normals[i], &points[j], &normals[j]);
            hist[alpha_bin(alpha_sine, alpha_cosine)] += increment;
            hist[BINS + bin(phi, -1.0, 2.0)] += increment;
            hist[2 * BINS + bin(theta, -1.0, 2.0)] += increment;
        }
    });

    let mut fpfh = vec![[0.0; FPFH_LEN]; n]; // (N, 33)
    fpfh.par_iter_mut().enumerate().for_each(|(i, out)| {
        let nb = around(i);
        if nb.len() >= 2 {
            weigh_neighbours(out, &spfh[i], &nb[1..], &spfh);
        }
    });
    fpfh
}

/// One point's FPFH into `out` (zero): its `own` SPFH plus its neighbours' (index, squared
/// distance) SPFHs `spfh` weighted as step 3 says.
fn weigh_neighbours(out: &mut Fpfh, own: &Fpfh, neighbours: &[(usize, f64)], spfh: &[Fpfh]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2.
        return unsafe { weigh_neighbours_avx2(out, own, neighbours, spfh) };
    }
    weigh_neighbours_any(out, own, neighbours, spfh)
}

/// [`weigh_neighbours`] compiled with AVX2: the same operations (never fused), wider vectors.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn weigh_neighbours_avx2(
    out: &mut Fpfh,
    own: &Fpfh,
    neighbours: &[(usize, f64)],
    spfh: &[Fpfh],
) {
    weigh_neighbours_any(out, own, neighbours, spfh)
}

/// [`weigh_neighbours`] for any CPU.
#[inline(always)]
fn weigh_neighbours_any(out: &mut Fpfh, own: &Fpfh, neighbours: &[(usize, f64)], spfh: &[Fpfh]) {
    // Σ SPFH_j / d²_j over the neighbours (a point coinciding with this one is skipped), and
    // each block's total, accumulated in Open3D's order.
    let mut block_sums = [0.0; 3];
    let mut weighted = [0.0; FPFH_LEN]; // (33,)
    for &(j, d2) in neighbours {
        if d2 == 0.0 {
            continue;
        }
        // The 33 divisions and additions into `out` are independent (vector instructions
        // do them); each block's sum is one chain, in bin order.
        for (w, s) in weighted.iter_mut().zip(&spfh[j]) {
            *w = s / d2;
        }
        for (o, w) in out.iter_mut().zip(&weighted) {
            *o += w;
        }
        for (sum, block) in block_sums.iter_mut().zip(weighted.chunks_exact(BINS)) {
            for w in block {
                *sum += w;
            }
        }
    }
    // Each block rescaled to sum to 100, plus the point's own SPFH.
    for ((block, own), sum) in out
        .chunks_exact_mut(BINS)
        .zip(own.chunks_exact(BINS))
        .zip(block_sums)
    {
        let scale = if sum != 0.0 { 100.0 / sum } else { 0.0 };
        for (o, s) in block.iter_mut().zip(own) {
            *o = *o * scale + s;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
