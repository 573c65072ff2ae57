//! The training-data pack: ModelNet40 shapes quantised to one `u32` per point, so that the
//! training split (7,863 shapes of 1,024 points) fits in ≈ 31 MiB and travels to a GPU machine
//! with the working tree (`cargo xtask pack-modelnet` writes it as a safetensors file;
//! `docs/training/gpu.md` describes the file).
//!
//! Each point is one word `w`: x in bits 0–10, y in bits 11–21, z in bits 22–31
//! ([`BITS`], [`SHIFTS`]). Per shape and axis, with `lo` the shape's minimum on that axis,
//! `extent` its maximum minus `lo` (rounded to f32) and `M = 2^b − 1` ([`levels`]):
//!
//! - encoding: `q = round((v − lo) / extent · M)` computed in f64, clamped to `0..=M`
//!   (`q = 0` where `extent == 0`);
//! - decoding ([`decode_point`], the formula [`DECODE`] that the file's metadata states):
//!   `v = lo + f32(q) · (extent · R)` with `R = f32(1 / M)` (the float32 nearest `1/M`), each
//!   operation in float32 and rounded on its own (two products and a sum; no fused
//!   multiply-add). PyTorch's `lo + q.float() * (extent * (1.0 / M))` computes exactly that on
//!   the CPU and on CUDA. A division is not in the formula because PyTorch's CUDA kernel divides
//!   a tensor by a Python number as a product with its float32 reciprocal, and its CPU kernel
//!   divides: `extent / M` would differ by a rounding between the two devices.
//!
//! The decoded value is within `extent / (2M)` of the stored one, plus float32 rounding
//! ([`error_bound`]): for shapes in the unit sphere (extent ≤ 2), 0.00049 in x and y and
//! 0.00098 in z — far below the protocol's jitter (σ = 0.01). [`Pack::max_error`] measures the
//! error of every coordinate and refuses one beyond its bound.

use crate::{DataError, Result, Shape};

/// The metadata's `format`.
pub const FORMAT: &str = "rgm-modelnet-pack";
/// The metadata's `version`.
pub const VERSION: &str = "1";
/// Bits of x, y, z in a word.
pub const BITS: [u32; 3] = [11, 11, 10];
/// The metadata's `bits`: [`BITS`] as written in the file.
pub const BITS_TEXT: &str = "11,11,10";
/// First bit of x, y, z in a word.
pub const SHIFTS: [u32; 3] = [0, BITS[0], BITS[0] + BITS[1]];
/// The decoding formula, as the metadata's `decode` states it ([`decode_point`] computes it).
pub const DECODE: &str = "qx = w & 2047; qy = (w >> 11) & 2047; qz = (w >> 22) & 1023; \
    v = lo + float32(q) * (extent * R) with R = float32(1 / (2^b - 1)), the float32 nearest \
    1/2047, 1/2047, 1/1023 for x, y, z; every operation in float32, rounded on its own \
    (no fused multiply-add)";

/// `2^b − 1` of `axis`: the largest quantised value (2047, 2047, 1023).
pub const fn levels(axis: usize) -> u32 {
    (1 << BITS[axis]) - 1
}

/// The quantised coordinates of a word: `(w >> SHIFTS[a]) & levels(a)`.
pub fn unpack(word: u32) -> [u32; 3] {
    std::array::from_fn(|a| (word >> SHIFTS[a]) & levels(a))
}

/// The word of quantised coordinates `q` (each at most [`levels`] of its axis).
pub fn pack_word(q: [u32; 3]) -> u32 {
    debug_assert!((0..3).all(|a| q[a] <= levels(a)), "{q:?}");
    (0..3).fold(0, |w, a| w | (q[a] << SHIFTS[a]))
}

/// `R` of `axis`: the float32 nearest `1 / (2^b − 1)`.
pub fn reciprocal(axis: usize) -> f32 {
    (1.0 / f64::from(levels(axis))) as f32
}

/// One coordinate decoded: `lo + f32(q) · (extent · R)` with `R` = [`reciprocal`], in float32
/// (three operations, each rounded; Rust does not fuse them).
pub fn decode_coordinate(q: u32, lo: f32, extent: f32, axis: usize) -> f32 {
    lo + q as f32 * (extent * reciprocal(axis))
}

/// One point decoded from its word and its shape's `lo` and `extent` ([`DECODE`]).
pub fn decode_point(word: u32, lo: [f32; 3], extent: [f32; 3]) -> [f32; 3] {
    let q = unpack(word);
    std::array::from_fn(|a| decode_coordinate(q[a], lo[a], extent[a], a))
}

/// The largest error a coordinate of `axis` may have after a round trip, for a shape with
/// this `lo` and `extent`: half a quantisation step, `extent / (2(2^b − 1))`, plus
/// `2⁻²¹ · (|lo| + extent)` for the float32 roundings (`R`, the three operations of the
/// decoding and the stored extent, at most 2⁻²⁴ relative each).
pub fn error_bound(lo: f32, extent: f32, axis: usize) -> f64 {
    let (lo, extent) = (f64::from(lo), f64::from(extent));
    extent / (2.0 * f64::from(levels(axis))) + (lo.abs() + extent) * 2f64.powi(-21)
}

/// The error bound for any shape within the unit sphere (|lo| ≤ 1, extent ≤ 2) on its
/// coarsest axis (z): ≈ 0.000979.
pub fn unit_sphere_error_bound() -> f64 {
    error_bound(-1.0, 2.0, 2)
}

/// One shape encoded: its words (one per point, in order) and per-axis `lo` and `extent`.
#[derive(Clone, Debug, PartialEq)]
pub struct EncodedShape {
    /// One word per point. // (P,)
    pub words: Vec<u32>,
    /// Minimum of each axis. // (3,)
    pub lo: [f32; 3],
    /// Maximum minus minimum of each axis, rounded to f32. // (3,)
    pub extent: [f32; 3],
}

impl EncodedShape {
    /// The points decoded. // (P, 3)
    pub fn decode(&self) -> Vec<[f32; 3]> {
        decode_words(&self.words, self.lo, self.extent)
    }
}

/// The points of one shape's `words`, decoded with its `lo` and `extent`. // (P, 3)
fn decode_words(words: &[u32], lo: [f32; 3], extent: [f32; 3]) -> Vec<[f32; 3]> {
    words.iter().map(|&w| decode_point(w, lo, extent)).collect()
}

fn pack_error(why: impl Into<String>) -> DataError {
    DataError::Pack { why: why.into() }
}

/// Encodes the points of the shape `name` (named in errors): refuses an empty shape, a
/// non-finite coordinate and an extent that overflows float32.
pub fn encode_shape(name: &str, points: &[[f32; 3]]) -> Result<EncodedShape> {
    if points.is_empty() {
        return Err(pack_error(format!("shape {name} has no point")));
    }
    if let Some(i) = points.iter().position(|p| p.iter().any(|v| !v.is_finite())) {
        return Err(pack_error(format!(
            "shape {name}: point {i} has a non-finite coordinate {:?}",
            points[i]
        )));
    }
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in points {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let extent: [f32; 3] = std::array::from_fn(|a| hi[a] - lo[a]);
    if extent.iter().any(|e| !e.is_finite()) {
        return Err(pack_error(format!(
            "shape {name}: extent {extent:?} overflows float32"
        )));
    }
    let words = points
        .iter()
        .map(|p| {
            pack_word(std::array::from_fn(|a| {
                if extent[a] == 0.0 {
                    return 0;
                }
                let m = f64::from(levels(a));
                let t = (f64::from(p[a]) - f64::from(lo[a])) / f64::from(extent[a]);
                (t * m).round().clamp(0.0, m) as u32
            }))
        })
        .collect();
    Ok(EncodedShape { words, lo, extent })
}

/// Shapes packed: `S` shapes of `P` points each, in the order given.
#[derive(Clone, Debug, PartialEq)]
pub struct Pack {
    /// Points per shape (`P`).
    pub points_per_shape: usize,
    /// One word per point, shape after shape. // (S, P)
    pub words: Vec<u32>,
    /// Per-shape minimum of each axis. // (S, 3)
    pub lo: Vec<[f32; 3]>,
    /// Per-shape maximum minus minimum of each axis. // (S, 3)
    pub extent: Vec<[f32; 3]>,
    /// Category labels. // (S,)
    pub labels: Vec<u8>,
}

impl Pack {
    /// Encodes `shapes` in order; each must have exactly `points_per_shape` points (a shape
    /// with another count is refused by name) and a label below 256.
    pub fn encode(shapes: &[&Shape], points_per_shape: usize) -> Result<Self> {
        let mut pack = Pack {
            points_per_shape,
            words: Vec::with_capacity(shapes.len() * points_per_shape),
            lo: Vec::with_capacity(shapes.len()),
            extent: Vec::with_capacity(shapes.len()),
            labels: Vec::with_capacity(shapes.len()),
        };
        for shape in shapes {
            if shape.points.len() != points_per_shape {
                return Err(pack_error(format!(
                    "shape {} has {} points, not {points_per_shape}",
                    shape.name,
                    shape.points.len()
                )));
            }
            let label = u8::try_from(shape.label).map_err(|_| {
                pack_error(format!(
                    "shape {} has label {}, beyond a byte",
                    shape.name, shape.label
                ))
            })?;
            let encoded = encode_shape(&shape.name, &shape.points)?;
            pack.words.extend_from_slice(&encoded.words);
            pack.lo.push(encoded.lo);
            pack.extent.push(encoded.extent);
            pack.labels.push(label);
        }
        Ok(pack)
    }

    /// Number of shapes (`S`).
    pub fn len(&self) -> usize {
        self.labels.len()
    }

    /// Whether the pack holds no shape.
    pub fn is_empty(&self) -> bool {
        self.labels.is_empty()
    }

    /// The points of shape `s`, decoded. // (P, 3)
    pub fn decode_shape(&self, s: usize) -> Vec<[f32; 3]> {
        let p = self.points_per_shape;
        decode_words(&self.words[s * p..(s + 1) * p], self.lo[s], self.extent[s])
    }

    /// The largest absolute error of each axis over every coordinate, the pack decoded against
    /// `shapes` (the shapes it was made of, in order). Refuses other shapes (count, label or
    /// point count) and any coordinate beyond its [`error_bound`], naming it.
    pub fn max_error(&self, shapes: &[&Shape]) -> Result<[f64; 3]> {
        if shapes.len() != self.len() {
            return Err(pack_error(format!(
                "the pack holds {} shapes, the data {}",
                self.len(),
                shapes.len()
            )));
        }
        let mut max = [0f64; 3];
        for (s, shape) in shapes.iter().enumerate() {
            if usize::from(self.labels[s]) != shape.label {
                return Err(pack_error(format!(
                    "shape {s} ({}): label {} in the pack, {} in the data",
                    shape.name, self.labels[s], shape.label
                )));
            }
            if shape.points.len() != self.points_per_shape {
                return Err(pack_error(format!(
                    "shape {s} ({}) has {} points, the pack {}",
                    shape.name,
                    shape.points.len(),
                    self.points_per_shape
                )));
            }
            let (lo, extent) = (self.lo[s], self.extent[s]);
            let bound: [f64; 3] = std::array::from_fn(|a| error_bound(lo[a], extent[a], a));
            for (i, (decoded, original)) in
                self.decode_shape(s).iter().zip(&shape.points).enumerate()
            {
                for a in 0..3 {
                    let err = (f64::from(decoded[a]) - f64::from(original[a])).abs();
                    if err > bound[a] || err.is_nan() {
                        return Err(pack_error(format!(
                            "shape {s} ({}), point {i}, axis {a}: decoded {} for {}, an error \
                             of {err} beyond the bound {}",
                            shape.name, decoded[a], original[a], bound[a]
                        )));
                    }
                    max[a] = max[a].max(err);
                }
            }
        }
        Ok(max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 1,024 points of a deterministic cloud in the unit sphere (a Fibonacci lattice of
    /// varying radius).
    fn synthetic(n: usize) -> Vec<[f32; 3]> {
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        (0..n)
            .map(|i| {
                let z = 1.0 - (2 * i + 1) as f64 / n as f64;
                let r = (1.0 - z * z).sqrt();
                let radius = 0.3 + 0.7 * ((i * 7919) % 1000) as f64 / 999.0;
                let phi = golden * i as f64;
                [
                    (radius * r * phi.cos()) as f32,
                    (radius * r * phi.sin()) as f32,
                    (radius * z) as f32,
                ]
            })
            .collect()
    }

    fn shape(name: &str, label: usize, points: Vec<[f32; 3]>) -> Shape {
        Shape {
            name: name.into(),
            label,
            points,
        }
    }

    #[test]
    fn round_trip_is_within_the_bound() {
        let a = shape("a", 3, synthetic(1024));
        // Off-centre and flat in y: each axis has its own lo and extent.
        let b = shape(
            "b",
            39,
            synthetic(1024)
                .iter()
                .map(|p| [p[0] * 0.5 + 0.4, p[1] * 0.01, p[2] - 0.2])
                .collect(),
        );
        let pack = Pack::encode(&[&a, &b], 1024).unwrap();
        assert_eq!(pack.len(), 2);
        assert_eq!(pack.labels, [3, 39]);
        let max = pack.max_error(&[&a, &b]).unwrap();
        // Half a step of the largest extent (< 2): 1/2047 in x, y and 1/1023 in z.
        assert!(max[0] <= 1.0 / 2047.0 && max[1] <= 1.0 / 2047.0, "{max:?}");
        assert!(max[2] <= 1.0 / 1023.0 && max[2] > max[0], "{max:?}");
        assert!(max.iter().all(|&e| e <= unit_sphere_error_bound()));
        // The extremes are exact: lo decodes to itself, lo + extent to the maximum.
        let decoded = pack.decode_shape(1);
        for a in 0..3 {
            let lo = b.points.iter().map(|p| p[a]).fold(f32::INFINITY, f32::min);
            let hi = b
                .points
                .iter()
                .map(|p| p[a])
                .fold(f32::NEG_INFINITY, f32::max);
            assert_eq!(pack.lo[1][a], lo);
            assert!(decoded.iter().any(|p| p[a] == lo));
            let top = decoded
                .iter()
                .map(|p| p[a])
                .fold(f32::NEG_INFINITY, f32::max);
            assert!((f64::from(top) - f64::from(hi)).abs() <= 1e-6, "{top} {hi}");
        }
        // Another set of shapes is refused: a changed point beyond its bound, a changed label.
        let mut moved = b.clone();
        moved.points[5][2] += 0.01;
        let err = pack.max_error(&[&a, &moved]).unwrap_err().to_string();
        assert!(err.contains("shape 1 (b), point 5, axis 2"), "{err}");
        let relabelled = shape("b", 38, b.points.clone());
        let err = pack.max_error(&[&a, &relabelled]).unwrap_err().to_string();
        assert!(
            err.contains("label 39 in the pack, 38 in the data"),
            "{err}"
        );
    }

    #[test]
    fn bit_layout_of_a_known_point() {
        // lo = (0, 0, 0), extent = (2, 2, 2) (set by the two corners): the point (0.5, 1, 2)
        // quantises to x = round(0.25 · 2047) = 512, y = round(0.5 · 2047) = 1024 (1023.5
        // rounds away from zero), z = 1023.
        let points = [[0.0, 0.0, 0.0], [2.0, 2.0, 2.0], [0.5, 1.0, 2.0]];
        let encoded = encode_shape("known", &points).unwrap();
        assert_eq!(encoded.lo, [0.0; 3]);
        assert_eq!(encoded.extent, [2.0; 3]);
        assert_eq!(encoded.words[0], 0);
        assert_eq!(encoded.words[1], 0xFFFF_FFFF);
        assert_eq!(encoded.words[2], 512 | (1024 << 11) | (1023 << 22));
        assert_eq!(encoded.words[2], 0xFFE0_0200);
        assert_eq!(unpack(encoded.words[2]), [512, 1024, 1023]);
        // Decoded with the stated formula, in f32.
        let p = decode_point(encoded.words[2], encoded.lo, encoded.extent);
        assert_eq!(p[0], 512.0f32 * (2.0f32 * (1.0f32 / 2047.0f32)));
        assert_eq!(p[1], 1024.0f32 * (2.0f32 * (1.0f32 / 2047.0f32)));
        assert_eq!(p[2], 1023.0f32 * (2.0f32 * (1.0f32 / 1023.0f32)));
        assert!((p[2] - 2.0).abs() <= f32::EPSILON * 2.0);
        // R rounded from a double (Rust, a Python number handed to torch) is the float32
        // division 1 / M (PyTorch's CUDA reciprocal): no double rounding for these M.
        assert_eq!(reciprocal(0), 1.0f32 / 2047.0f32);
        assert_eq!(reciprocal(2), 1.0f32 / 1023.0f32);
        assert_eq!(reciprocal(2).to_bits(), 0x3A80_2008);
        assert_eq!(pack_word([2047, 0, 0]), 0x7FF);
        assert_eq!(pack_word([0, 2047, 0]), 0x7FF << 11);
        assert_eq!(pack_word([0, 0, 1023]), 0x3FF << 22);
    }

    #[test]
    fn a_flat_axis_stores_extent_zero() {
        let points: Vec<[f32; 3]> = synthetic(1024)
            .iter()
            .map(|p| [p[0], -0.25, p[2]])
            .collect();
        let encoded = encode_shape("flat", &points).unwrap();
        assert_eq!(encoded.lo[1], -0.25);
        assert_eq!(encoded.extent[1], 0.0);
        assert!(encoded.words.iter().all(|&w| unpack(w)[1] == 0));
        assert!(encoded.decode().iter().all(|p| p[1] == -0.25));
        // A single point: every axis flat, decoded exactly.
        let one = encode_shape("one", &[[0.1, 0.2, 0.3]]).unwrap();
        assert_eq!((one.words[0], one.extent), (0, [0.0; 3]));
        assert_eq!(one.decode(), [[0.1, 0.2, 0.3]]);
    }

    #[test]
    fn refuses_a_wrong_point_count_and_bad_shapes() {
        let good = shape("good", 0, synthetic(1024));
        let short = shape("chair_0042", 8, synthetic(1000));
        let err = Pack::encode(&[&good, &short], 1024)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("shape chair_0042 has 1000 points, not 1024"),
            "{err}"
        );
        let mut bad = synthetic(1024);
        bad[7][1] = f32::NAN;
        let err = Pack::encode(&[&shape("nan", 0, bad)], 1024)
            .unwrap_err()
            .to_string();
        assert!(err.contains("shape nan: point 7 has a non-finite"), "{err}");
        let err = Pack::encode(&[&shape("big", 256, synthetic(1024))], 1024)
            .unwrap_err()
            .to_string();
        assert!(err.contains("shape big has label 256"), "{err}");
        let err = encode_shape("huge", &[[-3e38, 0.0, 0.0], [3e38, 0.0, 0.0]])
            .unwrap_err()
            .to_string();
        assert!(err.contains("overflows float32"), "{err}");
    }
}
