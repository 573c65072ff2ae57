//! `cargo xtask pack-modelnet`: ModelNet40's training shapes as one safetensors file of at most
//! 32 MiB, which travels to a GPU machine with the working tree (ModelNet40 itself, 194 MB,
//! does not). The encoding is `rgm_data::pack`; `docs/training/gpu.md` describes the file.
//!
//! The shapes are `ModelNet40::open(DIR)` then `.split(Split::Train, false)`, in that order.
//! The unseen-categories training set is the same list filtered to labels 0–19
//! (`split(Split::Train, true)` keeps exactly the shapes of `split(Split::Train, false)` whose
//! label is below half the 40 categories, in the same order), so a trainer takes it from the
//! pack's `label`.
//!
//! `--check PATH` reads a pack back, decodes every point in Rust with the stated formula and
//! reports the largest error against the data (the round trip).

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, ensure, Context, Result};
use rgm_data::pack::{self, Pack};
use rgm_data::{ModelNet40, Split};
use safetensors::tensor::{Dtype, TensorView};
use safetensors::SafeTensors;

use crate::project_root;

/// Points per shape of the pack (the `.npy` tree's 1,024).
pub const POINTS_PER_SHAPE: usize = 1024;
/// The largest pack written (32 MiB: half of what travels to a GPU machine).
pub const MAX_BYTES: usize = 32 << 20;

/// Options of `cargo xtask pack-modelnet`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The ModelNet40 tree (e.g. ../shared/data/modelnet40_npy1024); written to the pack's
    /// `source` as given.
    #[arg(long, value_name = "DIR")]
    data: PathBuf,
    /// Where to write the pack [default: target/modelnet40-train.pack.safetensors].
    #[arg(long, value_name = "PATH", conflicts_with = "check")]
    out: Option<PathBuf>,
    /// Read this pack back instead, decode every point and report the largest error against
    /// the training shapes of --data.
    #[arg(long, value_name = "PATH")]
    check: Option<PathBuf>,
}

pub fn run(args: Args) -> Result<()> {
    match &args.check {
        Some(path) => check(path, &args.data),
        None => {
            let out = args
                .out
                .clone()
                .unwrap_or_else(|| project_root().join("target/modelnet40-train.pack.safetensors"));
            write(&args.data, &out)
        }
    }
}

/// ModelNet40 from `data`.
fn load(data: &Path) -> Result<ModelNet40> {
    ModelNet40::open(data).with_context(|| format!("loading ModelNet40 from {}", data.display()))
}

fn write(data: &Path, out: &Path) -> Result<()> {
    let start = Instant::now();
    let dataset = load(data)?;
    let shapes = dataset.split(Split::Train, false);
    let packed = Pack::encode(&shapes, POINTS_PER_SHAPE)?;
    let max = packed.max_error(&shapes)?;
    let max_error = max.iter().copied().fold(0.0, f64::max);
    let bound = pack::unit_sphere_error_bound();
    ensure!(
        max_error <= bound,
        "max error {max_error} beyond {bound}, the bound for shapes within the unit sphere"
    );
    let bytes = to_bytes(
        &packed,
        &dataset.categories,
        &data.display().to_string(),
        max_error,
    )?;
    ensure!(
        bytes.len() <= MAX_BYTES,
        "the pack would be {} bytes, more than {MAX_BYTES} (32 MiB)",
        bytes.len()
    );
    if let Some(parent) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent)
            .with_context(|| format!("creating {}", parent.display()))?;
    }
    rgm_data::durable::replace(out, |file| file.write_all(&bytes))
        .with_context(|| format!("writing {}", out.display()))?;
    println!(
        "{}: {} shapes of {POINTS_PER_SHAPE} points (split train), {} bytes ({:.2} MiB); \
         max error {max_error} (x {}, y {}, z {}; bound {bound:.6}); {:.1} s",
        out.display(),
        packed.len(),
        bytes.len(),
        bytes.len() as f64 / f64::from(1 << 20),
        max[0],
        max[1],
        max[2],
        start.elapsed().as_secs_f64()
    );
    Ok(())
}

fn check(path: &Path, data: &Path) -> Result<()> {
    let start = Instant::now();
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let (packed, metadata) =
        from_bytes(&bytes).with_context(|| format!("reading the pack {}", path.display()))?;
    let dataset = load(data)?;
    let categories = metadata["categories"].split('\n').collect::<Vec<_>>();
    ensure!(
        categories == dataset.categories,
        "{}: the pack's categories are not those of {}",
        path.display(),
        data.display()
    );
    let shapes = dataset.split(Split::Train, false);
    let max = packed
        .max_error(&shapes)
        .with_context(|| format!("{} against {}", path.display(), data.display()))?;
    let max_error = max.iter().copied().fold(0.0, f64::max);
    let stated: f64 = metadata["max_error"]
        .parse()
        .with_context(|| format!("max_error `{}`", metadata["max_error"]))?;
    println!(
        "{}: {} shapes decoded in Rust ({}), max error {max_error} against {} \
         (x {}, y {}, z {}; the pack states {stated}); {:.1} s",
        path.display(),
        packed.len(),
        pack::DECODE,
        data.display(),
        max[0],
        max[1],
        max[2],
        start.elapsed().as_secs_f64()
    );
    ensure!(
        max_error == stated,
        "the measured max error {max_error} is not the one the pack states ({stated})"
    );
    Ok(())
}

/// The pack as a safetensors file: tensors `points` (U32, (S, P)), `lo` and `extent`
/// (F32, (S, 3)), `label` (U8, (S,)) and the metadata of `docs/training/gpu.md`.
pub fn to_bytes(
    packed: &Pack,
    categories: &[String],
    source: &str,
    max_error: f64,
) -> Result<Vec<u8>> {
    let (s, p) = (packed.len(), packed.points_per_shape);
    let words: Vec<u8> = packed.words.iter().flat_map(|w| w.to_le_bytes()).collect();
    let floats = |rows: &[[f32; 3]]| -> Vec<u8> {
        rows.iter()
            .flatten()
            .flat_map(|v| v.to_le_bytes())
            .collect()
    };
    let (lo, extent) = (floats(&packed.lo), floats(&packed.extent));
    let views = vec![
        ("points", TensorView::new(Dtype::U32, vec![s, p], &words)?),
        ("lo", TensorView::new(Dtype::F32, vec![s, 3], &lo)?),
        ("extent", TensorView::new(Dtype::F32, vec![s, 3], &extent)?),
        (
            "label",
            TensorView::new(Dtype::U8, vec![s], &packed.labels)?,
        ),
    ];
    let metadata: HashMap<String, String> = [
        ("format", pack::FORMAT.to_string()),
        ("version", pack::VERSION.to_string()),
        ("split", "train".to_string()),
        ("bits", pack::BITS_TEXT.to_string()),
        ("decode", pack::DECODE.to_string()),
        // Rust's shortest round-trip decimal, never an exponent.
        ("max_error", max_error.to_string()),
        ("shapes", s.to_string()),
        ("points_per_shape", p.to_string()),
        ("categories", categories.join("\n")),
        ("source", source.to_string()),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect();
    sorted_header(safetensors::serialize(views, &Some(metadata))?)
}

/// The safetensors file `bytes` with its header's keys in sorted order, so that the same pack
/// is the same bytes (the crate writes the metadata in a hash map's random order). The header
/// keeps its length: the same JSON, compact, its keys reordered.
fn sorted_header(mut bytes: Vec<u8>) -> Result<Vec<u8>> {
    let n = u64::from_le_bytes(bytes[..8].try_into().expect("8 bytes")) as usize;
    let header = &bytes[8..8 + n];
    // serde_json's maps are sorted (the workspace does not enable `preserve_order`).
    let value: serde_json::Value = serde_json::from_slice(header.trim_ascii_end())?;
    let sorted = serde_json::to_string(&value)?;
    ensure!(
        sorted.len() <= n,
        "the sorted header is longer than the header"
    );
    bytes[8..8 + sorted.len()].copy_from_slice(sorted.as_bytes());
    bytes[8 + sorted.len()..8 + n].fill(b' ');
    Ok(bytes)
}

/// Metadata keys every pack has.
const KEYS: [&str; 10] = [
    "format",
    "version",
    "split",
    "bits",
    "decode",
    "max_error",
    "shapes",
    "points_per_shape",
    "categories",
    "source",
];

/// A pack read back from its bytes, checked against the layout of [`to_bytes`], with its
/// metadata (every key of [`KEYS`] present).
pub fn from_bytes(bytes: &[u8]) -> Result<(Pack, HashMap<String, String>)> {
    let (_, header) = SafeTensors::read_metadata(bytes)?;
    let metadata = header.metadata().clone().unwrap_or_default();
    for key in KEYS {
        ensure!(metadata.contains_key(key), "no `{key}` in the metadata");
    }
    for (key, expected) in [
        ("format", pack::FORMAT),
        ("version", pack::VERSION),
        ("split", "train"),
        ("bits", pack::BITS_TEXT),
        ("decode", pack::DECODE),
    ] {
        ensure!(
            metadata[key] == expected,
            "metadata `{key}` is `{}`, not `{expected}`",
            metadata[key]
        );
    }
    let s: usize = metadata["shapes"].parse().context("metadata `shapes`")?;
    let p: usize = metadata["points_per_shape"]
        .parse()
        .context("metadata `points_per_shape`")?;
    let tensors = SafeTensors::deserialize(bytes)?;
    let tensor = |name: &str, dtype: Dtype, shape: &[usize]| -> Result<&[u8]> {
        let view = tensors
            .tensor(name)
            .with_context(|| format!("tensor `{name}`"))?;
        if view.dtype() != dtype || view.shape() != shape {
            bail!(
                "tensor `{name}` is {:?} {:?}, not {dtype:?} {shape:?}",
                view.dtype(),
                view.shape()
            );
        }
        Ok(view.data())
    };
    let words = tensor("points", Dtype::U32, &[s, p])?
        .chunks_exact(4)
        .map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes")))
        .collect();
    let rows = |name: &str| -> Result<Vec<[f32; 3]>> {
        Ok(tensor(name, Dtype::F32, &[s, 3])?
            .chunks_exact(12)
            .map(|row| {
                std::array::from_fn(|a| {
                    f32::from_le_bytes(row[4 * a..4 * a + 4].try_into().expect("4 bytes"))
                })
            })
            .collect())
    };
    let packed = Pack {
        points_per_shape: p,
        words,
        lo: rows("lo")?,
        extent: rows("extent")?,
        labels: tensor("label", Dtype::U8, &[s])?.to_vec(),
    };
    Ok((packed, metadata))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rgm_data::Shape;

    fn categories() -> Vec<String> {
        (0..40).map(|i| format!("category{i}")).collect()
    }

    /// `n` shapes of `p` points on a spiral, each scaled and shifted its own way.
    fn shapes(n: usize, p: usize) -> Vec<Shape> {
        (0..n)
            .map(|s| Shape {
                name: format!("shape_{s:04}"),
                label: (s * 7) % 40,
                points: (0..p)
                    .map(|i| {
                        let t = i as f32 / p as f32 * 20.0;
                        let r = 0.2 + 0.1 * s as f32;
                        [
                            r * t.cos(),
                            r * t.sin(),
                            (t / 20.0 - 0.5) * (1.0 + s as f32 * 0.1),
                        ]
                    })
                    .collect(),
            })
            .collect()
    }

    #[test]
    fn file_round_trip_keeps_every_tensor_and_key() {
        let owned = shapes(5, 64);
        let refs: Vec<&Shape> = owned.iter().collect();
        let packed = Pack::encode(&refs, 64).unwrap();
        let max = packed.max_error(&refs).unwrap();
        let max_error = max.iter().copied().fold(0.0, f64::max);
        let bytes = to_bytes(&packed, &categories(), "some/dir", max_error).unwrap();
        let (back, metadata) = from_bytes(&bytes).unwrap();
        assert_eq!(back, packed);
        // The same pack is the same bytes (the metadata's keys sorted).
        for _ in 0..4 {
            let again = to_bytes(&packed, &categories(), "some/dir", max_error).unwrap();
            assert_eq!(again, bytes);
        }
        let header = std::str::from_utf8(&bytes[8..200]).unwrap();
        assert!(header.starts_with(r#"{"__metadata__":{"bits":"11,11,10","categories":"#));
        assert_eq!(back.max_error(&refs).unwrap(), max);
        assert_eq!(metadata.len(), KEYS.len());
        assert_eq!(metadata["max_error"].parse::<f64>().unwrap(), max_error);
        assert!(!metadata["max_error"].contains('e'));
        assert_eq!(metadata["shapes"], "5");
        assert_eq!(metadata["points_per_shape"], "64");
        assert_eq!(metadata["source"], "some/dir");
        assert_eq!(metadata["bits"], "11,11,10");
        assert_eq!(metadata["categories"].lines().nth(39), Some("category39"));
        // The layout as a reader without rgm sees it.
        let tensors = SafeTensors::deserialize(&bytes).unwrap();
        let points = tensors.tensor("points").unwrap();
        assert_eq!((points.dtype(), points.shape()), (Dtype::U32, &[5, 64][..]));
        let label = tensors.tensor("label").unwrap();
        assert_eq!(
            (label.dtype(), label.data()),
            (Dtype::U8, &[0, 7, 14, 21, 28][..])
        );
        assert_eq!(tensors.tensor("lo").unwrap().shape(), [5, 3]);
        assert_eq!(tensors.tensor("extent").unwrap().dtype(), Dtype::F32);
        // A pack that states another decoding is refused.
        let mut other = HashMap::new();
        for (k, v) in &metadata {
            other.insert(k.clone(), v.clone());
        }
        other.insert("decode".into(), "v = q".into());
        let views: Vec<_> = tensors.tensors();
        let changed = safetensors::serialize(views, &Some(other)).unwrap();
        let err = format!("{:#}", from_bytes(&changed).unwrap_err());
        assert!(err.contains("metadata `decode` is `v = q`"), "{err}");
    }

    /// The shared ModelNet40 tree: `$RGM_DATA`, else `../shared/data/modelnet40_npy1024`
    /// beside the repository.
    fn data_dir() -> PathBuf {
        std::env::var_os("RGM_DATA")
            .map(PathBuf::from)
            .unwrap_or_else(|| project_root().join("../shared/data/modelnet40_npy1024"))
    }

    #[test]
    fn real_training_shapes_pack_within_the_bound() {
        let data = data_dir();
        if !data.is_dir() {
            println!(
                "SKIPPED pack on real data: no ModelNet40 data at {} (set RGM_DATA)",
                data.display()
            );
            return;
        }
        let dataset = ModelNet40::open(&data).unwrap();
        let train = dataset.split(Split::Train, false);
        // The unseen-categories training set is the same list filtered to labels 0–19.
        let unseen = dataset.split(Split::Train, true);
        let filtered: Vec<_> = train.iter().filter(|s| s.label < 20).copied().collect();
        assert_eq!(unseen, filtered);
        let first = &train[..50];
        let packed = Pack::encode(first, POINTS_PER_SHAPE).unwrap();
        let max = packed.max_error(first).unwrap();
        let max_error = max.iter().copied().fold(0.0, f64::max);
        assert!(max_error <= pack::unit_sphere_error_bound(), "{max:?}");
        let bytes = to_bytes(&packed, &dataset.categories, "data", max_error).unwrap();
        let (back, _) = from_bytes(&bytes).unwrap();
        assert_eq!(back.max_error(first).unwrap(), max);
        // 4 bytes a point and 25 a shape, plus the header.
        assert!(bytes.len() < 50 * (4 * POINTS_PER_SHAPE + 25) + 4096);
    }
}
