//! ModelNet40: the `.npy` tree (`<category>/{train,test}/<category>_NNNN.npy`) and the HDF5
//! release `modelnet40_ply_hdf5_2048`, with the splits of spec §1.
//!
//! Order: the official train and test lists are ordered by category label, then by file name
//! (byte order; the numbers are zero-padded, so this is numeric order). The HDF5 release keeps
//! its own order: files as listed in `train_files.txt`/`test_files.txt`, rows in file order.
//!
//! Splits ([`ModelNet40::split`]): the 80/20 cut of the official train split is taken **per
//! category**, in the order above: of a category's `n` train shapes the first `⌊0.8·n⌋` train
//! and the rest validate, so that validation covers every category that training does. (The
//! reference code cuts its whole HDF5 list, whose rows are shuffled across categories, at
//! `int(0.8·N)`, which is a per-category cut in expectation.) The unseen-category setting keeps
//! the first half of the labels (0–19) for training and validation and the second half (20–39)
//! for testing, on top of the same 80/20 cut.

use std::path::{Path, PathBuf};

use rayon::prelude::*;

use crate::io::{checked_cloud, npy, read_regular_file};
use crate::{DataError, Result};

/// One shape of the dataset.
#[derive(Clone, Debug, PartialEq)]
pub struct Shape {
    /// Where it comes from: the file stem (`airplane_0001`) or `FILE.h5:ROW` for the HDF5 release.
    pub name: String,
    /// Category label: line number (from 0) of its category in the shape-names file.
    pub label: usize,
    /// The points, as stored (float32). // (N, 3)
    pub points: Vec<[f32; 3]>,
}

/// Which part of the protocol a shape list is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum Split {
    /// First 80 % (per category) of the official train split.
    #[cfg_attr(feature = "clap", value(skip))]
    Train,
    /// The last 20 % of the official training split, per category (what `rgm train` validates
    /// on).
    Validation,
    /// The official test split (every table of the paper).
    Test,
}

/// The dataset: category names and the official train and test splits, all points in memory.
#[derive(Clone, Debug)]
pub struct ModelNet40 {
    /// Category names in label order. // (40,)
    pub categories: Vec<String>,
    /// The official train split in dataset order.
    pub official_train: Vec<Shape>,
    /// The official test split in dataset order.
    pub official_test: Vec<Shape>,
}

/// Share of each category's official train shapes used for training.
const TRAIN_SHARE: f64 = 0.8;

fn dataset_error(path: &Path, why: impl Into<String>) -> DataError {
    DataError::Dataset {
        path: path.to_path_buf(),
        why: why.into(),
    }
}

/// Non-empty trimmed lines of a text file.
fn read_lines(path: &Path) -> Result<Vec<String>> {
    let text = std::fs::read_to_string(path).map_err(|source| DataError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    Ok(text
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .map(String::from)
        .collect())
}

impl ModelNet40 {
    /// Loads whichever layout `dir` holds: the `.npy` tree (it has
    /// `modelnet40_shape_names.txt`, [`Self::open_npy`]) or the HDF5 release (it has
    /// `shape_names.txt`, [`Self::open_hdf5`]).
    pub fn open(dir: impl AsRef<Path>) -> Result<Self> {
        let dir = dir.as_ref();
        if dir.join("modelnet40_shape_names.txt").is_file() {
            Self::open_npy(dir)
        } else if dir.join("shape_names.txt").is_file() {
            Self::open_hdf5(dir)
        } else {
            let why =
                "neither a ModelNet40 .npy tree (no modelnet40_shape_names.txt) nor the HDF5 \
                       release modelnet40_ply_hdf5_2048 (no shape_names.txt)";
            Err(dataset_error(dir, why))
        }
    }

    /// Loads the `.npy` tree under `dir` (with `modelnet40_shape_names.txt`), in parallel.
    pub fn open_npy(dir: impl AsRef<Path>) -> Result<Self> {
        let dir = dir.as_ref();
        let categories = read_lines(&dir.join("modelnet40_shape_names.txt"))?;
        let load_split = |split: &str| -> Result<Vec<Shape>> {
            // (label, path) in dataset order.
            let mut files: Vec<(usize, PathBuf)> = Vec::new();
            for (label, category) in categories.iter().enumerate() {
                let folder = dir.join(category).join(split);
                let entries = std::fs::read_dir(&folder).map_err(|source| DataError::Io {
                    path: folder.clone(),
                    source,
                })?;
                let mut paths = Vec::new();
                for entry in entries {
                    let path = entry
                        .map_err(|source| DataError::Io {
                            path: folder.clone(),
                            source,
                        })?
                        .path();
                    if path.extension().is_some_and(|e| e == "npy") {
                        paths.push(path);
                    }
                }
                paths.sort();
                files.extend(paths.into_iter().map(|p| (label, p)));
            }
            files
                .par_iter()
                .map(|(label, path)| load_npy_shape(path, *label))
                .collect()
        };
        let official_train = load_split("train")?;
        let official_test = load_split("test")?;
        Ok(Self {
            categories,
            official_train,
            official_test,
        })
    }

    /// Loads the HDF5 release `modelnet40_ply_hdf5_2048` under `dir`: categories from
    /// `shape_names.txt`, files from `train_files.txt` / `test_files.txt` (their base names, looked
    /// up in `dir`), each with `data` (B, N, 3) float and `label` (B, 1) integer datasets. Other
    /// datasets (`normal`, `faceId`) are ignored.
    pub fn open_hdf5(dir: impl AsRef<Path>) -> Result<Self> {
        let dir = dir.as_ref();
        let categories = read_lines(&dir.join("shape_names.txt"))?;
        let load_split = |list: &str| -> Result<Vec<Shape>> {
            let list = dir.join(list);
            let files: Vec<PathBuf> = read_lines(&list)?
                .iter()
                .map(|line| Path::new(line).file_name().map(|name| dir.join(name)))
                .collect::<Option<_>>()
                .ok_or_else(|| dataset_error(&list, "a line names no file"))?;
            let per_file = files
                .par_iter()
                .map(|f| load_hdf5_file(f, categories.len()))
                .collect::<Result<Vec<_>>>()?;
            Ok(per_file.into_iter().flatten().collect())
        };
        let official_train = load_split("train_files.txt")?;
        let official_test = load_split("test_files.txt")?;
        Ok(Self {
            categories,
            official_train,
            official_test,
        })
    }

    /// The shapes of `split`; with `unseen`, only the first half of the categories for
    /// [`Split::Train`] and [`Split::Validation`] and only the second half for [`Split::Test`].
    pub fn split(&self, split: Split, unseen: bool) -> Vec<&Shape> {
        let half = self.categories.len() / 2;
        let category_ok = |label: usize| match (unseen, split) {
            (false, _) => true,
            (true, Split::Test) => label >= half,
            (true, _) => label < half,
        };
        let shapes: Vec<&Shape> = match split {
            Split::Test => self.official_test.iter().collect(),
            Split::Train | Split::Validation => {
                // Sized by the labels present, so a hand-made dataset cannot index out of range.
                let n_labels = self
                    .official_train
                    .iter()
                    .map(|s| s.label + 1)
                    .max()
                    .unwrap_or(0);
                let mut per_category = vec![0usize; n_labels];
                for s in &self.official_train {
                    per_category[s.label] += 1;
                }
                let mut seen = vec![0usize; n_labels];
                self.official_train
                    .iter()
                    .filter(|s| {
                        let rank = seen[s.label];
                        seen[s.label] += 1;
                        let in_train =
                            (rank as f64) < (per_category[s.label] as f64 * TRAIN_SHARE).floor();
                        in_train == (split == Split::Train)
                    })
                    .collect()
            }
        };
        shapes
            .into_iter()
            .filter(|s| category_ok(s.label))
            .collect()
    }
}

/// One `.npy` shape file, checked (finite, non-empty).
fn load_npy_shape(path: &Path, label: usize) -> Result<Shape> {
    let bytes = read_regular_file(path)?;
    let cloud = checked_cloud(npy::parse(&bytes, path)?, path)?;
    let name = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    Ok(Shape {
        name,
        label,
        points: cloud.to_f32_rows(),
    })
}

/// Every dataset value of `name` in `file` as f64, whatever its numeric type. // (elements,)
fn read_hdf5_numbers(
    file: &hdf5_reader::Hdf5File,
    name: &str,
    path: &Path,
) -> Result<(Vec<u64>, Vec<f64>)> {
    use hdf5_reader::Datatype;
    let fail =
        |e: hdf5_reader::error::Error| dataset_error(path, format!("HDF5 dataset `{name}`: {e}"));
    let dataset = file.dataset(name).map_err(fail)?;
    if let Some(values) = read_chunked_f32_3d(&dataset).map_err(fail)? {
        return Ok((
            dataset.shape().to_vec(),
            values.into_iter().map(f64::from).collect(),
        ));
    }
    macro_rules! read_as {
        ($t:ty) => {
            dataset
                .read_array::<$t>()
                .map_err(fail)?
                .iter()
                .map(|&v| v as f64)
                .collect()
        };
    }
    let unsupported = || {
        let why = format!(
            "HDF5 dataset `{name}` has type {:?}, not a number",
            dataset.dtype()
        );
        dataset_error(path, why)
    };
    let values: Vec<f64> = match *dataset.dtype() {
        Datatype::FloatingPoint { size: 4, .. } => read_as!(f32),
        Datatype::FloatingPoint { size: 8, .. } => read_as!(f64),
        Datatype::FixedPoint { size, signed, .. } => match (size, signed) {
            (1, false) => read_as!(u8),
            (1, true) => read_as!(i8),
            (2, false) => read_as!(u16),
            (2, true) => read_as!(i16),
            (4, false) => read_as!(u32),
            (4, true) => read_as!(i32),
            (8, false) => read_as!(u64),
            (8, true) => read_as!(i64),
            _ => return Err(unsupported()),
        },
        _ => return Err(unsupported()),
    };
    Ok((dataset.shape().to_vec(), values))
}

/// Largest dataset [`read_chunked_f32_3d`] assembles itself (4 GiB of float32).
const MAX_FAST_ELEMENTS: usize = 1 << 30;

/// Fast path for chunked float32 3-D datasets (the release's `data`, stored in chunks such as
/// (128, 128, 1)): decodes each chunk and copies its rows into place instead of the library's
/// element-wise assembly. `Ok(None)` when the dataset is not of that kind. Chunks never
/// written keep 0, HDF5's default fill value. // (d0·d1·d2,)
fn read_chunked_f32_3d(
    dataset: &hdf5_reader::Dataset,
) -> std::result::Result<Option<Vec<f32>>, hdf5_reader::error::Error> {
    let hdf5_reader::Datatype::FloatingPoint {
        size: 4,
        byte_order,
    } = *dataset.dtype()
    else {
        return Ok(None);
    };
    let dims: Vec<usize> = dataset.shape().iter().map(|&d| d as usize).collect();
    let (Some(_), &[d0, d1, d2]) = (dataset.chunks(), dims.as_slice()) else {
        return Ok(None);
    };
    let decode = match byte_order {
        hdf5_reader::ByteOrder::LittleEndian => f32::from_le_bytes,
        hdf5_reader::ByteOrder::BigEndian => f32::from_be_bytes,
    };
    // Header dimensions are not bounded by the (compressed) file size: leave huge ones to the
    // library's read budget.
    let total = d0.checked_mul(d1).and_then(|n| n.checked_mul(d2));
    let Some(total) = total.filter(|&n| n <= MAX_FAST_ELEMENTS) else {
        return Ok(None);
    };
    let mut out = vec![0.0f32; total]; // (d0, d1, d2)
    let mut local = Vec::new(); // (c0, c1, c2)
    for chunk in dataset.iter_chunks()? {
        let chunk = chunk?;
        let to_usize = |v: &[u64]| v.iter().map(|&x| x as usize).collect::<Vec<_>>();
        let (offsets, shape) = (to_usize(chunk.offsets()), to_usize(chunk.shape()));
        let (&[o0, o1, o2], &[c0, c1, c2]) = (offsets.as_slice(), shape.as_slice()) else {
            return Ok(None);
        };
        if chunk.bytes().len() != c0 * c1 * c2 * 4 {
            return Ok(None);
        }
        local.clear();
        local.extend(
            chunk
                .bytes()
                .chunks_exact(4)
                .map(|b| decode(b.try_into().expect("4 bytes"))),
        );
        // Edge chunks are stored whole; only their part inside the dataset is copied.
        let (n0, n1, run) = (
            c0.min(d0.saturating_sub(o0)),
            c1.min(d1.saturating_sub(o1)),
            c2.min(d2.saturating_sub(o2)),
        );
        for i0 in 0..n0 {
            let src_row = &local[i0 * c1 * c2..][..c1 * c2];
            let dst_row = &mut out[((o0 + i0) * d1 + o1) * d2 + o2..];
            for (src, dst) in src_row
                .chunks_exact(c2)
                .zip(dst_row.chunks_mut(d2))
                .take(n1)
            {
                dst[..run].copy_from_slice(&src[..run]);
            }
        }
    }
    Ok(Some(out))
}

/// The shapes of one HDF5 file of the release, named `FILE:ROW`.
fn load_hdf5_file(path: &Path, n_categories: usize) -> Result<Vec<Shape>> {
    let file = hdf5_reader::Hdf5File::open(path)
        .map_err(|e| dataset_error(path, format!("not a readable HDF5 file: {e}")))?;
    let (data_shape, data) = read_hdf5_numbers(&file, "data", path)?; // (B, N, 3)
    let (label_shape, labels) = read_hdf5_numbers(&file, "label", path)?; // (B, 1)
    let &[b, n, 3] = data_shape.as_slice() else {
        return Err(dataset_error(
            path,
            format!("HDF5 dataset `data` has shape {data_shape:?}, expected (B, N, 3)"),
        ));
    };
    if labels.len() as u64 != b || label_shape.first() != Some(&b) {
        return Err(dataset_error(
            path,
            format!("HDF5 dataset `label` has shape {label_shape:?}, expected ({b}, 1)"),
        ));
    }
    let file_name = path
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    if n == 0 {
        return Err(dataset_error(
            path,
            "HDF5 dataset `data` has shapes of 0 points",
        ));
    }
    let n = n as usize;
    let mut shapes = Vec::with_capacity(b as usize);
    for (row, (&label, rows)) in labels.iter().zip(data.chunks_exact(n * 3)).enumerate() {
        if label < 0.0 || label >= n_categories as f64 || label.fract() != 0.0 {
            return Err(dataset_error(
                path,
                format!("row {row} has label {label}, outside 0..{n_categories}"),
            ));
        }
        let points: Vec<_> = rows
            .chunks_exact(3)
            .map(|c| rgm_geom::Point3::new(c[0], c[1], c[2]))
            .collect();
        let row_path = PathBuf::from(format!("{}:{row}", path.display()));
        let cloud = checked_cloud(points, &row_path)?;
        shapes.push(Shape {
            name: format!("{file_name}:{row}"),
            label: label as usize,
            points: cloud.to_f32_rows(),
        });
    }
    Ok(shapes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::scratch_path;
    use rgm_geom::{Point3, PointCloud};

    /// A tree with categories `a`, `b`, `c`, `d`; category k has 5 + k train shapes and 2 test
    /// shapes; shape j of category k is the single point (k, j, 0) repeated twice.
    fn fake_tree(name: &str) -> PathBuf {
        let dir = scratch_path(name);
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("modelnet40_shape_names.txt"), "a\nb\nc\nd\n").unwrap();
        for (k, cat) in ["a", "b", "c", "d"].iter().enumerate() {
            for (split, n) in [("train", 5 + k), ("test", 2)] {
                let folder = dir.join(cat).join(split);
                std::fs::create_dir_all(&folder).unwrap();
                // Written in reverse so that the loader's sorting is what orders them.
                for j in (0..n).rev() {
                    let cloud = PointCloud::new(vec![Point3::new(k as f64, j as f64, 0.0); 2]);
                    let mut file =
                        std::fs::File::create(folder.join(format!("{cat}_{:04}.npy", j + 1)))
                            .unwrap();
                    npy::write(&mut file, &cloud, npy::Dtype::F32).unwrap();
                }
            }
        }
        std::fs::write(dir.join("a/train/notes.txt"), "not a shape").unwrap();
        dir
    }

    fn names(shapes: &[&Shape]) -> Vec<String> {
        shapes.iter().map(|s| s.name.clone()).collect()
    }

    #[test]
    fn loads_labels_and_orders_by_label_then_name() {
        let data = ModelNet40::open(fake_tree("mn_order")).unwrap();
        assert_eq!(data.categories, ["a", "b", "c", "d"]);
        assert_eq!(data.official_train.len(), 5 + 6 + 7 + 8);
        assert_eq!(data.official_test.len(), 8);
        let first: Vec<_> = data
            .official_train
            .iter()
            .take(6)
            .map(|s| (s.name.as_str(), s.label))
            .collect();
        let expected = [
            ("a_0001", 0),
            ("a_0002", 0),
            ("a_0003", 0),
            ("a_0004", 0),
            ("a_0005", 0),
            ("b_0001", 1),
        ];
        assert_eq!(first, expected);
        assert_eq!(data.official_train[6].points, vec![[1.0, 1.0, 0.0]; 2]);
    }

    #[test]
    fn splits_cut_each_category_at_eighty_percent() {
        let data = ModelNet40::open(fake_tree("mn_split")).unwrap();
        // ⌊0.8·n⌋ for n = 5, 6, 7, 8 is 4, 4, 5, 6.
        let train = data.split(Split::Train, false);
        let validation = data.split(Split::Validation, false);
        assert_eq!(train.len(), 4 + 4 + 5 + 6);
        assert_eq!(
            names(&validation),
            ["a_0005", "b_0005", "b_0006", "c_0006", "c_0007", "d_0007", "d_0008"]
        );
        assert_eq!(data.split(Split::Test, false).len(), 8);
        // Unseen: labels 0–1 train and validate, labels 2–3 test.
        assert_eq!(data.split(Split::Train, true).len(), 4 + 4);
        assert_eq!(
            names(&data.split(Split::Validation, true)),
            ["a_0005", "b_0005", "b_0006"]
        );
        let test = data.split(Split::Test, true);
        assert_eq!(
            test.iter().map(|s| s.label).collect::<Vec<_>>(),
            [2, 2, 3, 3]
        );
    }

    /// The fixture made by `tests/fixtures/make_hdf5_fixture.py`.
    fn hdf5_fixture() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/modelnet40_ply_hdf5_2048")
    }

    #[test]
    fn reads_the_hdf5_release_in_file_order() {
        // `open` recognises the layout.
        let data = ModelNet40::open(hdf5_fixture()).unwrap();
        assert_eq!(data.categories, ["a", "b", "c", "d"]);
        let labels = |shapes: &[Shape]| shapes.iter().map(|s| s.label).collect::<Vec<_>>();
        assert_eq!(labels(&data.official_train), [0, 1, 2, 3, 0, 1, 2, 3]);
        assert_eq!(labels(&data.official_test), [2, 3]);
        // Point j of row b in file k is (100 k + b, j, label / 2); train1 is file 1.
        let s = &data.official_train[6];
        assert_eq!(s.name, "ply_data_train1.h5:1");
        assert_eq!(
            s.points,
            [
                [101.0, 0.0, 1.0],
                [101.0, 1.0, 1.0],
                [101.0, 2.0, 1.0],
                [101.0, 3.0, 1.0]
            ]
        );
        assert_eq!(data.official_test[1].points[3], [201.0, 3.0, 1.5]);
        // Each category has 2 train shapes: ⌊1.6⌋ = 1 trains, 1 validates.
        assert_eq!(names(&data.split(Split::Validation, false)).len(), 4);
    }

    #[test]
    fn chunk_fast_path_equals_the_library_assembly() {
        // Chunks of (2, 3, 1) over (5, 4, 3): edge chunks in the first two dimensions.
        for name in ["ply_data_train0.h5", "ply_data_train1.h5"] {
            let file = hdf5_reader::Hdf5File::open(hdf5_fixture().join(name)).unwrap();
            let dataset = file.dataset("data").unwrap();
            let fast = read_chunked_f32_3d(&dataset)
                .unwrap()
                .expect("a chunked f32 3-D dataset");
            let library = dataset.read_array::<f32>().unwrap();
            assert_eq!(fast, library.iter().copied().collect::<Vec<_>>(), "{name}");
        }
        // The contiguous test file is not for the fast path.
        let file = hdf5_reader::Hdf5File::open(hdf5_fixture().join("ply_data_test0.h5")).unwrap();
        assert!(read_chunked_f32_3d(&file.dataset("data").unwrap())
            .unwrap()
            .is_none());
    }

    #[test]
    fn hdf5_problems_are_named() {
        let dir = scratch_path("h5_broken");
        std::fs::create_dir_all(&dir).unwrap();
        for f in [
            "shape_names.txt",
            "train_files.txt",
            "test_files.txt",
            "ply_data_train0.h5",
            "ply_data_test0.h5",
        ] {
            std::fs::copy(hdf5_fixture().join(f), dir.join(f)).unwrap();
        }
        let err = ModelNet40::open_hdf5(&dir).unwrap_err().to_string();
        assert!(err.contains("ply_data_train1.h5"), "{err}");
        std::fs::write(dir.join("ply_data_train1.h5"), b"not hdf5 at all").unwrap();
        let err = ModelNet40::open_hdf5(&dir).unwrap_err().to_string();
        assert!(
            err.contains("ply_data_train1.h5: not a readable HDF5 file"),
            "{err}"
        );
        // Too few categories for the labels.
        std::fs::copy(
            hdf5_fixture().join("ply_data_train1.h5"),
            dir.join("ply_data_train1.h5"),
        )
        .unwrap();
        std::fs::write(dir.join("shape_names.txt"), "a\nb\n").unwrap();
        let err = ModelNet40::open_hdf5(&dir).unwrap_err().to_string();
        assert!(err.contains("has label 2, outside 0..2"), "{err}");
    }

    #[test]
    fn missing_pieces_are_named() {
        let err = ModelNet40::open(scratch_path("mn_nowhere"))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("mn_nowhere: neither a ModelNet40 .npy tree"),
            "{err}"
        );
        let err = ModelNet40::open_npy(scratch_path("mn_nowhere"))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("mn_nowhere/modelnet40_shape_names.txt"),
            "{err}"
        );
        let dir = fake_tree("mn_broken");
        std::fs::write(dir.join("c/test/c_0001.npy"), b"\x93NUMPY garbage").unwrap();
        let err = ModelNet40::open(&dir).unwrap_err().to_string();
        assert!(err.contains("c/test/c_0001.npy: npy:"), "{err}");
        std::fs::remove_dir_all(dir.join("d/train")).unwrap();
        let err = ModelNet40::open(&dir).unwrap_err().to_string();
        assert!(err.contains("d/train"), "{err}");
    }
}
