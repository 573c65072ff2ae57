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
    /// Neighbourhood radius (default 0.4 for shapes in the unit sphere: the Open3D setup).
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
    // The pair in the first lane; the others hold (p1, n1) again.
    let mut p = [[p1.x; LANES], [p1.y; LANES], [p1.z; LANES]];
    let mut n = [[n1.x; LANES], [n1.y; LANES], [n1.z; LANES]];
    for axis in 0..3 {
        p[axis][0] = p2[axis];
        n[axis][0] = n2[axis];
    }
    let [alpha_sine, alpha_cosine, phi, theta, d] = pair_terms((p1, n1), &p, &n);
    [alpha_sine[0].atan2(alpha_cosine[0]), phi[0], theta[0], d[0]]
}

/// The bin of `value` in [lo, lo + width) split into 11, clamped to the valid bins: the floor,
/// as the cast's truncation towards zero and saturation at 0 give it for the valid bins (and a
/// libm `floor` call is costly).
#[inline]
fn bin(value: f64, lo: f64, width: f64) -> usize {
    bin_at(bin_place(value, lo, width))
}

/// Where `value` lies among the bins of [`bin`] (bin k spans [k, k + 1)).
#[inline(always)]
fn bin_place(value: f64, lo: f64, width: f64) -> f64 {
    BINS as f64 * (value - lo) / width
}

/// The bin of a place: the cast truncates towards zero and saturates at 0 (a NaN too), the
/// last bin takes what lies beyond it.
#[inline(always)]
fn bin_at(place: f64) -> usize {
    (place as usize).min(BINS - 1)
}

/// Where atan2(y, x) lies among α's bins (bin k spans [k, k + 1)), from a polynomial
/// arctangent instead of libm's atan2 (a quarter of FPFH's time): within 4.4e-8 rad of the
/// angle, and so within 7.7e-8 of its place, which [`alpha_bin_at`] turns into libm's bin to
/// the last bit of the features. Branch-free, so that [`add_pairs`] computes it for several
/// pairs at once.
#[inline(always)]
fn alpha_place(y: f64, x: f64) -> f64 {
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
    // libm decides those ([`alpha_bin_at`]).
    let a = ax.min(ay) / ax.max(ay) + (x + y) * 0.0;
    // P(s) by Estrin's scheme: a chain of four steps where Horner's has eight.
    let s = a * a;
    let (s2, s4) = (s * s, s * s * (s * s));
    let low = (P[0] + P[1] * s) + s2 * (P[2] + P[3] * s);
    let high = (P[4] + P[5] * s) + s2 * (P[6] + P[7] * s);
    let turned = a * (low + s4 * high);
    // The octant and the half-plane without branches (the signs are a coin toss each pair):
    // π/2 − angle where |y| > |x|, π − that where x < 0, negated where y is.
    let steep = if ay > ax { 1.0 } else { 0.0 };
    let turned = turned + steep * (FRAC_PI_2 - 2.0 * turned);
    let back = if x.is_sign_negative() { 1.0 } else { 0.0 };
    let angle = (turned + back * (PI - 2.0 * turned)).copysign(y);
    (angle + PI) * (BINS as f64 / (2.0 * PI))
}

/// α's bin, `bin(y.atan2(x), −π, 2π)`, from its [`alpha_place`] where that lies more than
/// 1e-6 from a bin's edge (the bin libm's angle falls in); nearer (about two pairs in a
/// million), for both zeros and for NaN, from libm's atan2.
#[inline]
fn alpha_bin_at(place: f64, y: f64, x: f64) -> usize {
    use std::f64::consts::PI;
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

/// Pairs whose features [`add_pairs`] computes side by side: one AVX-512 register of f64.
const LANES: usize = 8;

/// Adds `increment` to the three bins of the pair features of (p1, n1) with each of
/// `neighbours` (indices into `points` and `normals`) in `hist`: [`LANES`] pairs at a time, each
/// lane doing [`pair_features`]' operations ([`pair_terms`]), so that every bin is the one it
/// gives. The order the pairs are added in does not matter: every
/// addition adds the same `increment`.
fn add_pairs(
    hist: &mut Fpfh,
    (p1, n1): (&Point3<f64>, &Vector3<f64>),
    neighbours: &[(usize, f64)],
    (points, normals): (&[Point3<f64>], &[Vector3<f64>]),
    increment: f64,
) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx512f") {
        // SAFETY: the CPU has AVX-512F.
        return unsafe {
            add_pairs_avx512(hist, (p1, n1), neighbours, (points, normals), increment)
        };
    }
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2.
        return unsafe { add_pairs_avx2(hist, (p1, n1), neighbours, (points, normals), increment) };
    }
    add_pairs_any(hist, (p1, n1), neighbours, (points, normals), increment)
}

/// [`add_pairs`] compiled with AVX-512: the same operations, eight lanes wide.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn add_pairs_avx512(
    hist: &mut Fpfh,
    centre: (&Point3<f64>, &Vector3<f64>),
    neighbours: &[(usize, f64)],
    cloud: (&[Point3<f64>], &[Vector3<f64>]),
    increment: f64,
) {
    add_pairs_any(hist, centre, neighbours, cloud, increment)
}

/// [`add_pairs`] compiled with AVX2 (the processors without AVX-512): the same operations,
/// four lanes wide.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn add_pairs_avx2(
    hist: &mut Fpfh,
    centre: (&Point3<f64>, &Vector3<f64>),
    neighbours: &[(usize, f64)],
    cloud: (&[Point3<f64>], &[Vector3<f64>]),
    increment: f64,
) {
    add_pairs_any(hist, centre, neighbours, cloud, increment)
}

/// [`add_pairs`] for any CPU.
#[inline(always)]
fn add_pairs_any(
    hist: &mut Fpfh,
    (p1, n1): (&Point3<f64>, &Vector3<f64>),
    neighbours: &[(usize, f64)],
    (points, normals): (&[Point3<f64>], &[Vector3<f64>]),
    increment: f64,
) {
    for chunk in neighbours.chunks(LANES) {
        // The neighbours' points and normals by axis; a lane past the chunk's end holds the
        // centre itself (its terms are zero, and it is not added). // (3, LANES) each
        let mut p = [[p1.x; LANES], [p1.y; LANES], [p1.z; LANES]];
        let mut n = [[n1.x; LANES], [n1.y; LANES], [n1.z; LANES]];
        for (k, &(j, _)) in chunk.iter().enumerate() {
            for axis in 0..3 {
                p[axis][k] = points[j][axis];
                n[axis][k] = normals[j][axis];
            }
        }
        let [alpha_sine, alpha_cosine, phi, theta, _] = pair_terms((p1, n1), &p, &n);
        let mut places = [[0.0; LANES]; 3];
        for k in 0..LANES {
            places[0][k] = alpha_place(alpha_sine[k], alpha_cosine[k]);
            places[1][k] = bin_place(phi[k], -1.0, 2.0);
            places[2][k] = bin_place(theta[k], -1.0, 2.0);
        }
        for k in 0..chunk.len() {
            hist[alpha_bin_at(places[0][k], alpha_sine[k], alpha_cosine[k])] += increment;
            hist[BINS + bin_at(places[1][k])] += increment;
            hist[2 * BINS + bin_at(places[2][k])] += increment;
        }
    }
}

/// [`pair_features`] before α's angle is taken, for (p1, n1) with each lane's point and normal:
/// `[w·n, u·n, φ, θ, d]`, α being the atan2 of the first two (all zero where the features
/// are). Each lane does Open3D's operations in its order, never fused, its branches taken as
/// selections, so that eight lanes compute side by side what one pair would. // (5, LANES)
#[inline(always)]
fn pair_terms(
    (p1, n1): (&Point3<f64>, &Vector3<f64>),
    p: &[[f64; LANES]; 3],
    n: &[[f64; LANES]; 3],
) -> [[f64; LANES]; 5] {
    let mut out = [[0.0; LANES]; 5];
    for k in 0..LANES {
        let n2 = [n[0][k], n[1][k], n[2][k]];
        let dp = [p[0][k] - p1.x, p[1][k] - p1.y, p[2][k] - p1.z];
        let d = (dp[0] * dp[0] + dp[1] * dp[1] + dp[2] * dp[2]).sqrt();
        let angle1 = (n1.x * dp[0] + n1.y * dp[1] + n1.z * dp[2]) / d;
        let angle2 = (n2[0] * dp[0] + n2[1] * dp[1] + n2[2] * dp[2]) / d;
        // Open3D writes `acos|a₁| > acos|a₂|`; acos is decreasing, so that is `|a₁| < |a₂|` —
        // and on 1-ulp ties (where libm's acos returns equal values) Open3D's build decides as
        // `<`. Swapped, the line runs the other way and the second normal comes first.
        let swap = angle1.abs() < angle2.abs();
        let pick = |a: f64, b: f64| if swap { a } else { b };
        let dp = [
            pick(-dp[0], dp[0]),
            pick(-dp[1], dp[1]),
            pick(-dp[2], dp[2]),
        ];
        let u = [pick(n2[0], n1.x), pick(n2[1], n1.y), pick(n2[2], n1.z)];
        let other = [pick(n1.x, n2[0]), pick(n1.y, n2[1]), pick(n1.z, n2[2])];
        let theta = pick(-angle2, angle1);
        let v = cross(&dp, &u);
        let v_norm = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        let v = [v[0] / v_norm, v[1] / v_norm, v[2] / v_norm];
        let w = cross(&u, &v);
        let terms = [
            w[0] * other[0] + w[1] * other[1] + w[2] * other[2],
            u[0] * other[0] + u[1] * other[1] + u[2] * other[2],
            v[0] * other[0] + v[1] * other[1] + v[2] * other[2],
            theta,
            d,
        ];
        // Coinciding points, or a line along the first normal: all zero.
        let zero = d == 0.0 || v_norm == 0.0;
        for (o, t) in out.iter_mut().zip(terms) {
            o[k] = if zero { 0.0 } else { t };
        }
    }
    out
}

/// `a × b`, each component as nalgebra's `cross` computes it.
#[inline(always)]
fn cross(a: &[f64; 3], b: &[f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
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
        add_pairs(
            hist,
            (&points[i], &normals[i]),
            &nb[1..],
            (points, normals),
            increment,
        );
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
mod tests;
