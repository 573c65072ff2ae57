//! ASPRS LAS and its LASzip-compressed form LAZ, through the `las` crate (and `laz`).
//!
//! A coordinate is stored as a 32-bit integer with a scale and an offset per axis
//! (`x = scale · X + offset`), read into f64 as the format defines it: map coordinates (UTM
//! eastings near 500,000, northings in millions) keep every digit the file holds.
//!
//! Written with point format 0 and, per axis, the offset at the middle of the cloud and the
//! smallest power-of-ten scale that spans it in 32-bit integers, from the extent alone (a cloud
//! a nanometre across keeps its shape): a coordinate moves by at most half that scale, 1.25e-9
//! of the axis's extent.
//!
//! The crate allocates some buffers from sizes in the file; those sizes are checked against the
//! file's length first (`check_sizes`), so a small file cannot ask for gigabytes. The points
//! a file declares are checked against the memory this process may take
//! ([`super::check_points_fit`]), not against a ratio to its length: LASzip stores a stack of
//! identical points in a fraction of a bit each.

use std::io::{Cursor, Write};
use std::path::Path;

use rgm_geom::{Point3, PointCloud};

use super::{format_error, PointFormat, Warning};
use crate::Result;

/// Bytes of records read at a time (the crate's buffer): a record of a forged length (up to
/// 64 KiB) must not make the batch large.
const BATCH_BYTES: u64 = 1 << 17;

/// ASPRS LAS.
pub struct Las;

/// LAZ: LAS compressed by LASzip.
pub struct Laz;

impl PointFormat for Las {
    fn name(&self) -> &'static str {
        "LAS"
    }
    fn extensions(&self) -> &'static [&'static str] {
        &["las"]
    }
    fn summary(&self) -> &'static str {
        "coordinates kept exact in f64 (scale · integer + offset); written point format 0, \
         within 1.25e-9 of the cloud's extent"
    }
    fn magic(&self) -> Option<&'static [u8]> {
        Some(b"LASF")
    }
    fn parse(&self, bytes: &[u8], path: &Path, _: &mut Vec<Warning>) -> Result<Vec<Point3<f64>>> {
        parse(bytes, path, self.name())
    }
    fn write(&self, out: &mut dyn Write, cloud: &PointCloud) -> std::io::Result<()> {
        write(out, cloud, false)
    }
}

impl PointFormat for Laz {
    fn name(&self) -> &'static str {
        "LAZ"
    }
    fn extensions(&self) -> &'static [&'static str] {
        &["laz"]
    }
    fn summary(&self) -> &'static str {
        "LASzip-compressed LAS, point formats 0 to 5 (not yet 6 to 10), read and written as LAS is"
    }
    fn magic(&self) -> Option<&'static [u8]> {
        Some(b"LASF")
    }
    fn parse(&self, bytes: &[u8], path: &Path, _: &mut Vec<Warning>) -> Result<Vec<Point3<f64>>> {
        parse(bytes, path, self.name())
    }
    fn write(&self, out: &mut dyn Write, cloud: &PointCloud) -> std::io::Result<()> {
        write(out, cloud, true)
    }
}

/// The little-endian value of `N` bytes at `at`, if the file holds them.
fn le<const N: usize>(bytes: &[u8], at: usize) -> Option<u64> {
    let b: [u8; N] = bytes.get(at..at.checked_add(N)?)?.try_into().ok()?;
    Some(b.iter().rev().fold(0u64, |v, &x| (v << 8) | x as u64))
}

/// Refuses a header whose point counts, extended VLR or LAZ chunk table are larger than the
/// file could hold, before the crate allocates from them.
fn check_sizes(bytes: &[u8]) -> std::result::Result<(), String> {
    let len = bytes.len() as u64;
    let short = || "the file ends inside its 227-byte header".to_string();
    let version = (
        *bytes.get(24).ok_or_else(short)?,
        *bytes.get(25).ok_or_else(short)?,
    );
    if version.0 != 1 || version.1 > 4 {
        // Read on, a header of another layout gives counts of its other fields.
        return Err(format!(
            "LAS version {}.{} is not one rgm reads (versions 1.0 to 1.4)",
            version.0, version.1
        ));
    }
    let offset_to_points = le::<4>(bytes, 96).ok_or_else(short)?;
    let format = le::<1>(bytes, 104).ok_or_else(short)?;
    let compressed = format & 0x80 != 0;
    if compressed && format & 0x3f >= 6 {
        // laz 0.13 sizes its layer buffers from 32-bit lengths in each chunk, unchecked: a
        // forged 600-byte file takes 2 GB. Refused until those lengths are checked.
        return Err(format!(
            "point format {} in LAZ (layered compression, formats 6 to 10) is not read yet; \
             LAS of that format is, and LAZ of formats 0 to 5",
            format & 0x3f
        ));
    }
    let record = le::<2>(bytes, 105).ok_or_else(short)?;
    let mut counts = vec![le::<4>(bytes, 107).ok_or_else(short)?];
    if version >= (1, 4) {
        counts.extend(le::<8>(bytes, 247));
        let start = le::<8>(bytes, 235).unwrap_or(0);
        let evlrs = le::<4>(bytes, 243).unwrap_or(0);
        if start > 0 && evlrs > 0 {
            // The crate reads the first extended VLR: 60 bytes of header, then its data.
            let data = usize::try_from(start)
                .ok()
                .and_then(|s| le::<8>(bytes, s.checked_add(20)?));
            let room = len.saturating_sub(start).saturating_sub(60);
            match data {
                Some(n) if n <= room => {}
                _ => {
                    return Err(format!(
                        "the extended VLR at byte {start} runs past the end"
                    ))
                }
            }
        }
    }
    // LAS records take their bytes; a LAZ count is checked against memory when read.
    let room = len.saturating_sub(offset_to_points);
    for count in counts {
        if !compressed && count.saturating_mul(record) > room {
            return Err(format!(
                "{count} points of {record} bytes need more than the {room} bytes after byte \
                 {offset_to_points}"
            ));
        }
    }
    if compressed {
        // The chunk table's offset leads the point data, or ends the file (as LASzip finds it).
        let at = usize::try_from(offset_to_points).unwrap_or(usize::MAX);
        let mut table = le::<8>(bytes, at).unwrap_or(0);
        if table <= offset_to_points {
            table = bytes
                .len()
                .checked_sub(8)
                .and_then(|e| le::<8>(bytes, e))
                .unwrap_or(0);
        }
        let chunks = usize::try_from(table)
            .ok()
            .and_then(|t| le::<4>(bytes, t.checked_add(4)?));
        // The crate reserves 16 bytes a chunk; a chunk takes at least a byte of the file.
        if let Some(chunks) = chunks.filter(|&c| c > len) {
            return Err(format!(
                "a chunk table of {chunks} chunks cannot be in {len} bytes"
            ));
        }
    }
    Ok(())
}

/// The points of a LAS or LAZ file (`name` says which, for errors).
fn parse(bytes: &[u8], path: &Path, name: &'static str) -> Result<Vec<Point3<f64>>> {
    let fail = |why: String| format_error(path, name, why);
    super::check_magic(&Las, bytes, path)
        .map_err(|_| fail("missing the magic string LASF".into()))?;
    check_sizes(bytes).map_err(fail)?;
    // laz 0.13 panics on some corrupt data (a slice index past its end) instead of returning an
    // error: the panic is taken for the file's error, so that a bad file cannot end rgm.
    std::panic::catch_unwind(|| read_points(bytes, path, name)).unwrap_or_else(|panic| {
        let why = panic
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| panic.downcast_ref::<String>().cloned())
            .unwrap_or_default();
        Err(fail(format!("corrupt data (the decoder failed: {why})")))
    })
}

/// The points of a LAS or LAZ file that [`check_sizes`] passed.
fn read_points(bytes: &[u8], path: &Path, name: &'static str) -> Result<Vec<Point3<f64>>> {
    let fail = |why: String| format_error(path, name, why);
    // The crate's reader owns its source.
    let mut reader =
        las::Reader::new(Cursor::new(bytes.to_vec())).map_err(|e| fail(e.to_string()))?;
    let declared = reader.header().number_of_points();
    let record = reader.header().point_format().len() as u64;
    let batch = (BATCH_BYTES / record.max(1)).max(1);
    // Checked, not reserved: LAZ's count is not bounded by the file's size, and a forged one
    // is found out as the data ends.
    super::check_points_fit(path, declared, 0)?;
    let mut points = Vec::new();
    loop {
        let batch = reader
            .read_points(batch)
            .map_err(|e| fail(format!("point {} of {declared}: {e}", points.len() + 1)))?;
        if batch.is_empty() {
            break;
        }
        points.extend(
            batch
                .x()
                .zip(batch.y())
                .zip(batch.z())
                .map(|((x, y), z)| Point3::new(x, y, z)),
        );
    }
    Ok(points)
}

/// Per axis, the offset (the middle of the cloud) and the smallest power-of-ten scale whose
/// 32-bit integers span the cloud (an axis of no extent takes the largest axis's scale, 1 when
/// every point is the same).
fn transforms(cloud: &PointCloud) -> las::Vector<las::Transform> {
    let middle_and_half = |a: usize| {
        let (lo, hi) = cloud
            .points
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(p[a]), hi.max(p[a]))
            });
        if lo <= hi {
            ((lo + hi) / 2.0, (hi - lo) / 2.0)
        } else {
            (0.0, 0.0)
        }
    };
    let axes = [0, 1, 2].map(middle_and_half);
    let widest = axes.iter().map(|&(_, half)| half).fold(0.0, f64::max);
    let transform = |(offset, half): (f64, f64)| las::Transform {
        scale: spanning_scale(if half > 0.0 { half } else { widest }),
        offset,
    };
    las::Vector {
        x: transform(axes[0]),
        y: transform(axes[1]),
        z: transform(axes[2]),
    }
}

/// The smallest power of ten `s` with `half / s ≤ 2e9` (32-bit integers then span ±`half`),
/// exactly as its decimal spelling reads; 1 for no extent.
fn spanning_scale(half: f64) -> f64 {
    if !(half > 0.0 && half.is_finite()) {
        return 1.0;
    }
    let power = |k: i32| {
        format!("1e{k}")
            .parse::<f64>()
            .expect("a decimal power of ten")
    };
    let mut k = (half / 2e9).log10().floor() as i32;
    while half / power(k) > 2e9 {
        k += 1;
    }
    while half / power(k - 1) <= 2e9 {
        k -= 1;
    }
    power(k)
}

/// Writes LAS 1.2 point format 0 (compressed by LASzip when `laz`).
fn write(out: &mut dyn Write, cloud: &PointCloud, laz: bool) -> std::io::Result<()> {
    let las_error = |e: las::Error| std::io::Error::other(e.to_string());
    let mut builder = las::Builder::from((1, 2));
    builder.point_format = las::point::Format::new(0).map_err(las_error)?;
    builder.point_format.is_compressed = laz;
    builder.generating_software = "rgm".into();
    builder.transforms = transforms(cloud);
    let header = builder.into_header().map_err(las_error)?;
    let mut writer = las::Writer::new(Cursor::new(Vec::new()), header).map_err(las_error)?;
    for p in &cloud.points {
        let point = las::Point {
            x: p.x,
            y: p.y,
            z: p.z,
            ..Default::default()
        };
        writer.write_point(point).map_err(las_error)?;
    }
    let bytes = writer.into_inner().map_err(las_error)?.into_inner();
    out.write_all(&bytes)
}
