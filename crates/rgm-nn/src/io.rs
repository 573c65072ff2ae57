//! Weight files in safetensors (readable by PyTorch, numpy, candle): every parameter and buffer
//! under its state-dict name, in the element type of the model (F32 or F64).
//!
//! The file is long because its unit tests sit beside the code they check (as everywhere in
//! rgm); the code itself is one job, kept in one place.

use crate::bf16::{bf16_bits, bf16_to_f32};
use crate::param::{try_visit_buffers, try_visit_params};
use crate::{NnError, Parameters, Result, Scalar};
use ndarray::{ArrayD, ArrayViewD, IxDyn};
use rayon::prelude::*;
use safetensors::tensor::{Dtype, TensorView};
use safetensors::SafeTensorError;
use safetensors::SafeTensors;
use std::any::TypeId;
use std::collections::HashMap;
use std::path::Path;

/// Tensors by name, as read from a file.
pub type Tensors<T> = HashMap<String, ArrayD<T>>;

/// Named views of tensors, as written to a file.
pub type NamedViews<'a, T> = Vec<(String, ArrayViewD<'a, T>)>;

fn dtype_of<T: Scalar>() -> Dtype {
    if TypeId::of::<T>() == TypeId::of::<f32>() {
        Dtype::F32
    } else {
        Dtype::F64
    }
}

/// How a tensor is stored in a file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Storage {
    /// The model's element type (F32 or F64), exact.
    Native,
    /// bfloat16: half of f32's bytes, 8 significant bits.
    Bf16,
    /// One byte per value on a logarithmic scale between the tensor's smallest and largest
    /// positive values ([`log8_encode`]); zero stays zero. For non-negative tensors whose
    /// values span many octaves and need only a rough relative precision, such as Adam's second
    /// moments in a snapshot: a quarter of f32's bytes.
    Log8,
}

/// The metadata key that holds the log₂ range of the [`Storage::Log8`] tensor `name`.
fn log8_key(name: &str) -> String {
    format!("log8:{name}")
}

/// Codes of [`Storage::Log8`]: 0 for zero, and 1..=255 spread evenly over log₂ of the
/// positive values from their minimum `lo` to their maximum `hi`, which are returned. Every
/// positive value comes back within a factor 2^((hi − lo)/508) of itself. Refuses negative
/// and non-finite values (`None`).
pub fn log8_encode(values: impl Iterator<Item = f64> + Clone) -> Option<(Vec<u8>, f64, f64)> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.clone() {
        if !(v.is_finite() && v >= 0.0) {
            return None;
        }
        if v > 0.0 {
            lo = lo.min(v.log2());
            hi = hi.max(v.log2());
        }
    }
    if lo > hi {
        (lo, hi) = (0.0, 0.0); // all zero
    }
    let span = (hi - lo).max(f64::MIN_POSITIVE);
    let codes = values
        .map(|v| {
            if v == 0.0 {
                0
            } else {
                1 + ((v.log2() - lo) / span * 254.0).round().clamp(0.0, 254.0) as u8
            }
        })
        .collect();
    Some((codes, lo, hi))
}

/// The value of [`log8_encode`]'s `code` for the range `lo`..=`hi`.
pub fn log8_decode(code: u8, lo: f64, hi: f64) -> f64 {
    if code == 0 {
        0.0
    } else {
        (lo + f64::from(code - 1) / 254.0 * (hi - lo)).exp2()
    }
}

/// The little-endian bytes of `t` stored as `dtype` (F32, F64 or BF16).
fn le_bytes<T: Scalar>(t: &ArrayViewD<'_, T>, dtype: Dtype) -> Vec<u8> {
    let mut out = Vec::with_capacity(t.len() * dtype.size());
    for &v in t.iter() {
        let v = Scalar::to_f64(v);
        match dtype {
            Dtype::F64 => out.extend_from_slice(&v.to_le_bytes()),
            Dtype::BF16 => out.extend_from_slice(&bf16_bits(v as f32).to_le_bytes()),
            _ => out.extend_from_slice(&(v as f32).to_le_bytes()),
        }
    }
    out
}

/// Writes `tensors` (name, value) and string `metadata` to a safetensors file at `path`, in the
/// element type of `T`.
pub fn write_tensors<T: Scalar>(
    path: &Path,
    tensors: &[(String, ArrayViewD<'_, T>)],
    metadata: HashMap<String, String>,
) -> Result<()> {
    write_tensors_with_bf16(path, tensors, metadata, &|_| false)
}

/// [`write_tensors`], storing the tensors whose name `bf16` accepts as bfloat16 (rounded to
/// nearest, ties to even; F64 values through f32): half the bytes, 8 significant bits. For
/// snapshots where that precision is enough; the readers upcast.
pub fn write_tensors_with_bf16<T: Scalar>(
    path: &Path,
    tensors: &[(String, ArrayViewD<'_, T>)],
    metadata: HashMap<String, String>,
    bf16: &dyn Fn(&str) -> bool,
) -> Result<()> {
    write_tensors_stored(path, tensors, metadata, &|name| {
        if bf16(name) {
            Storage::Bf16
        } else {
            Storage::Native
        }
    })
}

/// [`write_tensors`] with each tensor stored as `storage` says for its name; the readers
/// ([`read_tensors`], [`load_params`]) convert every storage back to `T`. A
/// [`Storage::Log8`] tensor with a negative or non-finite value is refused.
pub fn write_tensors_stored<T: Scalar>(
    path: &Path,
    tensors: &[(String, ArrayViewD<'_, T>)],
    mut metadata: HashMap<String, String>,
    storage: &dyn Fn(&str) -> Storage,
) -> Result<()> {
    let mut encoded: Vec<(Dtype, Vec<u8>)> = Vec::with_capacity(tensors.len());
    for (name, t) in tensors {
        encoded.push(match storage(name) {
            Storage::Native => (dtype_of::<T>(), le_bytes(t, dtype_of::<T>())),
            Storage::Bf16 => (Dtype::BF16, le_bytes(t, Dtype::BF16)),
            Storage::Log8 => {
                let values = t.iter().map(|&v| Scalar::to_f64(v));
                let (codes, lo, hi) =
                    log8_encode(values).ok_or_else(|| NnError::InvalidArgument {
                        op: "write_tensors_stored",
                        why: format!(
                            "{}: tensor {name} has a negative or non-finite value, which \
                             8-bit logarithmic storage cannot hold",
                            path.display()
                        ),
                    })?;
                metadata.insert(log8_key(name), format!("{lo:?} {hi:?}"));
                (Dtype::U8, codes)
            }
        });
    }
    let views = tensors
        .iter()
        .zip(&encoded)
        .map(|((name, t), (dtype, b))| {
            let view = TensorView::new(*dtype, t.shape().to_vec(), b).map_err(|source| {
                NnError::Safetensors {
                    path: path.to_path_buf(),
                    source,
                }
            })?;
            Ok((name.clone(), view))
        })
        .collect::<Result<Vec<_>>>()?;
    // The crate's errors print as their Debug form; a failed write (a full disk) is told as
    // the I/O error it is.
    safetensors::serialize_to_file(views, &Some(metadata), path).map_err(|error| match error {
        SafeTensorError::IoError(source) => NnError::Io {
            path: path.to_path_buf(),
            source,
        },
        source => NnError::Safetensors {
            path: path.to_path_buf(),
            source,
        },
    })
}

/// Rewrites the safetensors file `from` as `to` with the tensors whose name `bf16` accepts
/// stored as bfloat16 (the others as f32), metadata kept: e.g. a run's Adam moments for a
/// snapshot in git (`|name| name.starts_with("m.") || name.starts_with("v.")`).
pub fn rewrite_with_bf16(from: &Path, to: &Path, bf16: &dyn Fn(&str) -> bool) -> Result<()> {
    let (tensors, metadata) = read_tensors::<f32>(from)?;
    let mut named: Vec<_> = tensors.iter().map(|(n, t)| (n.clone(), t.view())).collect();
    named.sort_by(|a, b| a.0.cmp(&b.0));
    write_tensors_with_bf16(to, &named, metadata, bf16)
}

/// The bytes of the regular file at `path`; folders, devices, FIFOs and sockets are refused
/// before they are opened (`/dev/zero` would never end).
pub fn read_bytes(path: &Path) -> Result<Vec<u8>> {
    let io_error = |source| NnError::Io {
        path: path.to_path_buf(),
        source,
    };
    let kind = std::fs::metadata(path).map_err(io_error)?.file_type();
    if !kind.is_file() {
        let kind = if kind.is_dir() {
            "a folder"
        } else {
            "a device, FIFO or socket"
        };
        return Err(NnError::NotAFile {
            path: path.to_path_buf(),
            kind,
        });
    }
    std::fs::read(path).map_err(io_error)
}

/// What is wrong with a file safetensors refused, in words.
fn not_safetensors(path: &Path, source: SafeTensorError) -> NnError {
    let why = match source {
        SafeTensorError::HeaderTooSmall => {
            "it is shorter than the 8 bytes that give the header's length".to_string()
        }
        SafeTensorError::HeaderTooLarge | SafeTensorError::InvalidHeaderLength => {
            "its first 8 bytes do not give a header length that fits in the file".to_string()
        }
        SafeTensorError::InvalidHeader
        | SafeTensorError::InvalidHeaderStart
        | SafeTensorError::InvalidHeaderDeserialization
        | SafeTensorError::JsonError(_) => {
            "its header is not the JSON table of tensors a safetensors file starts with".to_string()
        }
        SafeTensorError::MetadataIncompleteBuffer
        | SafeTensorError::InvalidOffset(_)
        | SafeTensorError::TensorInvalidInfo
        | SafeTensorError::ValidationOverflow => {
            "the tensors its header lists do not fit its size (a truncated or damaged file)"
                .to_string()
        }
        other => other.to_string(),
    };
    NnError::NotSafetensors {
        path: path.to_path_buf(),
        why,
    }
}

fn parse<'b>(path: &Path, buffer: &'b [u8]) -> Result<SafeTensors<'b>> {
    SafeTensors::deserialize(buffer).map_err(|source| not_safetensors(path, source))
}

/// The log₂ range `metadata` gives the [`Storage::Log8`] tensor `name`, if it has one.
fn log8_range(metadata: &HashMap<String, String>, name: &str) -> Option<(f64, f64)> {
    let range = metadata.get(&log8_key(name))?;
    let (lo, hi) = range.split_once(' ')?;
    let (lo, hi) = (lo.parse::<f64>().ok()?, hi.parse::<f64>().ok()?);
    (lo.is_finite() && hi.is_finite() && lo <= hi).then_some((lo, hi))
}

/// The values of one F32, F64, BF16 or [`Storage::Log8`] tensor, converted to `T`, in the
/// file's shape; `metadata` is the file's (it holds the Log8 ranges).
fn to_array<T: Scalar>(
    path: &Path,
    name: &str,
    view: &TensorView<'_>,
    metadata: &HashMap<String, String>,
) -> Result<ArrayD<T>> {
    let mut array = ArrayD::zeros(IxDyn(view.shape()));
    let values = array.as_slice_mut().expect("a new array is contiguous");
    decode_into(path, name, view, metadata, values)?;
    Ok(array)
}

/// [`to_array`] into `dst`, which holds as many values as the tensor, in row order: a model's
/// parameters are filled without a second copy of them.
fn decode_into<T: Scalar>(
    path: &Path,
    name: &str,
    view: &TensorView<'_>,
    metadata: &HashMap<String, String>,
    dst: &mut [T],
) -> Result<()> {
    let data = view.data();
    match view.dtype() {
        Dtype::U8 if log8_range(metadata, name).is_some() => {
            let (lo, hi) = log8_range(metadata, name).expect("checked");
            for (d, &c) in dst.iter_mut().zip(data) {
                *d = T::from_f64(log8_decode(c, lo, hi));
            }
        }
        Dtype::F32 => {
            for (d, b) in dst.iter_mut().zip(data.chunks_exact(4)) {
                *d = T::from_f64(f32::from_le_bytes(b.try_into().unwrap()) as f64);
            }
        }
        Dtype::F64 => {
            for (d, b) in dst.iter_mut().zip(data.chunks_exact(8)) {
                *d = T::from_f64(f64::from_le_bytes(b.try_into().unwrap()));
            }
        }
        Dtype::BF16 => {
            for (d, b) in dst.iter_mut().zip(data.chunks_exact(2)) {
                *d = T::from_f64(bf16_to_f32(u16::from_le_bytes([b[0], b[1]])) as f64);
            }
        }
        other => {
            return Err(NnError::TensorDtype {
                path: path.to_path_buf(),
                name: name.to_string(),
                dtype: format!("{other:?}"),
            })
        }
    }
    Ok(())
}

/// Reads every tensor of a safetensors file (all must be F32, F64, BF16 or
/// [`Storage::Log8`]; converted to `T`) and its metadata.
pub fn read_tensors<T: Scalar>(path: &Path) -> Result<(Tensors<T>, HashMap<String, String>)> {
    read_tensors_from_bytes(&read_bytes(path)?, path)
}

/// [`read_tensors`] on the bytes of a safetensors file already in memory (weights embedded in
/// a binary); `origin` names them in errors.
pub fn read_tensors_from_bytes<T: Scalar>(
    buffer: &[u8],
    origin: &Path,
) -> Result<(Tensors<T>, HashMap<String, String>)> {
    let (_, header) =
        SafeTensors::read_metadata(buffer).map_err(|source| not_safetensors(origin, source))?;
    let metadata = header.metadata().clone().unwrap_or_default();
    // Converted side by side: decoding a model's few million values is most of loading it.
    let tensors = parse(origin, buffer)?
        .tensors()
        .into_par_iter()
        .map(|(name, view)| {
            let array = to_array(origin, &name, &view, &metadata)?;
            Ok((name, array))
        })
        .collect::<Result<Tensors<T>>>()?;
    Ok((tensors, metadata))
}

/// Saves every parameter and buffer of `model` under its name.
pub fn save_params<T: Scalar>(path: &Path, model: &dyn Parameters<T>) -> Result<()> {
    let mut views: NamedViews<'_, T> = Vec::new();
    model.visit_params_ref("", &mut |name, p| views.push((name.to_string(), p.value)));
    model.visit_buffers_ref("", &mut |name, b| views.push((name.to_string(), b)));
    write_tensors(path, &views, HashMap::new())
}

/// Loads every parameter and buffer of `model` from `path`, checking each shape. A tensor the
/// model lacks is an error ([`NnError::MissingTensor`]), as is a mis-shaped one
/// ([`NnError::TensorShape`]) or one that is not F32/F64. Trailing size-1 dimensions in the file
/// are accepted, so a PyTorch 1×1 convolution weight `(C_out, C_in, 1, 1)` loads into a
/// [`crate::Linear`]. Tensors the model does not use (e.g. batch norm's integer
/// `num_batches_tracked`) are ignored.
pub fn load_params<T: Scalar>(path: &Path, model: &mut dyn Parameters<T>) -> Result<()> {
    load_params_from_bytes(&read_bytes(path)?, path, "", model)
}

/// [`load_params`] from the bytes of a safetensors file already in memory (weights embedded in
/// a binary, or a file read once for several parts of a model); `origin` names them in errors.
/// `model` is the part whose names start with `prefix` ("" for a whole model). Each tensor is
/// decoded straight into its parameter.
pub fn load_params_from_bytes<T: Scalar>(
    buffer: &[u8],
    origin: &Path,
    prefix: &str,
    model: &mut dyn Parameters<T>,
) -> Result<()> {
    let file = parse(origin, buffer)?;
    let (_, header) =
        SafeTensors::read_metadata(buffer).map_err(|source| not_safetensors(origin, source))?;
    let metadata = header.metadata().clone().unwrap_or_default();
    let fill = |name: &str, mut dst: ndarray::ArrayViewMutD<'_, T>| -> Result<()> {
        let view = file.tensor(name).map_err(|_| NnError::MissingTensor {
            path: origin.to_path_buf(),
            name: name.to_string(),
        })?;
        let (got, want) = (view.shape(), dst.shape());
        let trailing_ones = got.len() >= want.len() && got[want.len()..].iter().all(|&d| d == 1);
        if !trailing_ones || &got[..want.len()] != want {
            return Err(NnError::TensorShape {
                path: origin.to_path_buf(),
                name: name.to_string(),
                expected: want.to_vec(),
                got: got.to_vec(),
            });
        }
        // Both in row order (trailing size-1 axes add none).
        match dst.as_slice_mut() {
            Some(values) => decode_into(origin, name, &view, &metadata, values)?,
            None => {
                let t = to_array::<T>(origin, name, &view, &metadata)?;
                dst.iter_mut().zip(t.iter()).for_each(|(d, &v)| *d = v);
            }
        }
        match dst.iter().position(|v| !v.is_finite()) {
            Some(index) => Err(NnError::NonFiniteWeight {
                path: origin.to_path_buf(),
                name: name.to_string(),
                index,
                value: dst
                    .iter()
                    .nth(index)
                    .map_or(f64::NAN, |&v| Scalar::to_f64(v)),
            }),
            None => Ok(()),
        }
    };
    try_visit_params(model, prefix, |name, p| fill(name, p.value))?;
    try_visit_buffers(model, prefix, fill)
}
#[cfg(test)]
mod tests {
    use super::*;
    use crate::{BatchNorm, Linear};
    use rand::{rngs::StdRng, SeedableRng};

    fn temp(name: &str) -> std::path::PathBuf {
        std::env::temp_dir().join(format!(
            "rgm-nn-io-{}-{name}.safetensors",
            std::process::id()
        ))
    }

    #[test]
    fn round_trip_keeps_parameters_and_buffers_and_converts_f64_to_f32() {
        let path = temp("round");
        let mut bn = BatchNorm::<f64>::new(3);
        bn.weight.value = ndarray::array![1.5, 2.5, 3.5];
        bn.running_var = ndarray::array![0.25, 0.5, 4.0];
        save_params(&path, &bn).unwrap();
        let (tensors, _) = read_tensors::<f64>(&path).unwrap();
        let mut names: Vec<_> = tensors.keys().cloned().collect();
        names.sort();
        assert_eq!(names, ["bias", "running_mean", "running_var", "weight"]);
        let mut back = BatchNorm::<f32>::new(3);
        load_params(&path, &mut back).unwrap();
        assert_eq!(back.weight.value, ndarray::array![1.5f32, 2.5, 3.5]);
        assert_eq!(back.running_var, ndarray::array![0.25f32, 0.5, 4.0]);
        std::fs::remove_file(&path).unwrap();
    }

    /// Issue 59, E10: NaN weights were blamed on the clouds (the network's output was found
    /// non-finite); the file is refused when read, naming the tensor.
    #[test]
    fn a_weight_file_holding_nan_is_refused_naming_the_tensor() {
        let path = temp("nan");
        let mut bn = BatchNorm::<f32>::new(3);
        bn.running_var = ndarray::array![0.25, f32::NAN, 4.0];
        save_params(&path, &bn).unwrap();
        let err = load_params(&path, &mut BatchNorm::<f32>::new(3)).unwrap_err();
        let text = err.to_string();
        assert!(
            text.contains(r#"tensor "running_var" holds a non-finite value (NaN at element 1)"#),
            "{text}"
        );
        std::fs::remove_file(&path).unwrap();
    }

    /// Log8 keeps zero, the extremes and every value within its stated factor; a negative
    /// value is refused with the tensor named.
    #[test]
    fn log8_storage_round_trips_within_its_bound() {
        let path = temp("log8");
        let v = ndarray::array![0.0f32, 1e-12, 3.7e-9, 2.5e-6, 0.01, 4.0].into_dyn();
        let w = ndarray::array![-1.5f32, 2.0].into_dyn();
        let tensors = [("v.a".to_string(), v.view()), ("w".to_string(), w.view())];
        write_tensors_stored(&path, &tensors, HashMap::new(), &|n| {
            if n == "v.a" {
                Storage::Log8
            } else {
                Storage::Native
            }
        })
        .unwrap();
        assert!(
            std::fs::metadata(&path).unwrap().len() < 200,
            "6 bytes, not 24, for v.a"
        );
        let (back, _) = read_tensors::<f64>(&path).unwrap();
        assert_eq!(back["w"], w.mapv(f64::from));
        let got = back["v.a"].as_slice().unwrap().to_vec();
        assert_eq!(got[0], 0.0);
        // log2 spans 4e0 / 1e-12 ≈ 41.9 octaves: every value within 2^(41.9/508) ≈ 1.059×.
        let bound = (4.0f64.log2() - 1e-12f64.log2()) / 508.0;
        for (g, want) in got.iter().zip(v.iter()).skip(1) {
            let octaves = (g / f64::from(*want)).log2().abs();
            assert!(octaves <= bound + 1e-9, "{g} for {want}: {octaves} octaves");
        }
        assert!((got[1] / 1e-12 - 1.0).abs() < 1e-6, "the minimum is exact");
        assert!((got[5] / 4.0 - 1.0).abs() < 1e-6, "the maximum is exact");
        let err = write_tensors_stored(&path, &tensors, HashMap::new(), &|_| Storage::Log8)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("tensor w") && err.contains("negative"),
            "{err}"
        );
        std::fs::remove_file(&path).unwrap();
    }

    #[test]
    fn missing_and_misshaped_tensors_are_named() {
        let path = temp("errors");
        save_params(
            &path,
            &Linear::<f32>::new(3, 2, false, &mut StdRng::seed_from_u64(0)),
        )
        .unwrap();
        let err = load_params(
            &path,
            &mut Linear::<f32>::new(3, 2, true, &mut StdRng::seed_from_u64(0)),
        )
        .unwrap_err();
        assert!(
            matches!(&err, NnError::MissingTensor { name, .. } if name == "bias"),
            "{err}"
        );
        let err = load_params(
            &path,
            &mut Linear::<f32>::new(4, 2, false, &mut StdRng::seed_from_u64(0)),
        )
        .unwrap_err();
        assert!(
            err.to_string()
                .ends_with("tensor \"weight\" has shape [2, 3], expected [2, 4]"),
            "{err}"
        );
        std::fs::remove_file(&path).unwrap();
    }

    #[test]
    fn pytorch_layouts_load_conv_weight_and_skip_integer_counters() {
        // What a converted PyTorch state dict holds: a (2, 3, 1, 1) conv weight and batch
        // norm's int64 num_batches_tracked next to the float tensors.
        let path = temp("pytorch");
        let w: Vec<u8> = (0..6).flat_map(|v| (v as f32).to_le_bytes()).collect();
        let count = 7i64.to_le_bytes();
        let views = [
            (
                "conv.weight",
                TensorView::new(Dtype::F32, vec![2, 3, 1, 1], &w).unwrap(),
            ),
            (
                "bn.num_batches_tracked",
                TensorView::new(Dtype::I64, vec![], &count).unwrap(),
            ),
        ];
        safetensors::serialize_to_file(views, &None, &path).unwrap();
        let mut conv = Linear::<f64>::new(3, 2, false, &mut StdRng::seed_from_u64(0));
        struct Conv<'a>(&'a mut Linear<f64>);
        impl Parameters<f64> for Conv<'_> {
            fn visit_params_ref<'a>(
                &'a self,
                prefix: &str,
                f: &mut dyn FnMut(&str, crate::param::ParamView<'a, f64>),
            ) {
                self.0
                    .visit_params_ref(&crate::param::join_name(prefix, "conv"), f);
            }
            fn visit_params(
                &mut self,
                prefix: &str,
                f: &mut dyn FnMut(&str, crate::param::ParamViewMut<'_, f64>),
            ) {
                self.0
                    .visit_params(&crate::param::join_name(prefix, "conv"), f);
            }
        }
        load_params(&path, &mut Conv(&mut conv)).unwrap();
        assert_eq!(
            conv.weight.value,
            ndarray::array![[0.0, 1.0, 2.0], [3.0, 4.0, 5.0]]
        );
        std::fs::remove_file(&path).unwrap();
    }

    #[test]
    fn bytes_in_memory_read_as_the_file_does() {
        let path = temp("bytes");
        let mut bn = BatchNorm::<f32>::new(2);
        bn.running_mean = ndarray::array![0.5f32, -1.0];
        save_params(&path, &bn).unwrap();
        let (from_file, _) = read_tensors::<f32>(&path).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let (from_bytes, _) = read_tensors_from_bytes::<f32>(&bytes, Path::new("memory")).unwrap();
        assert_eq!(from_file, from_bytes);
        assert_eq!(
            from_bytes["running_mean"].as_slice().unwrap(),
            &[0.5f32, -1.0]
        );
        let err = read_tensors_from_bytes::<f32>(b"garbage", Path::new("builtin:x")).unwrap_err();
        assert!(err.to_string().starts_with("builtin:x: "), "{err}");
        std::fs::remove_file(&path).unwrap();
    }

    #[test]
    fn chosen_tensors_are_written_as_bf16_and_read_back_upcast() {
        let path = temp("bf16");
        let mut bn = BatchNorm::<f32>::new(3);
        bn.weight.value = ndarray::array![1.0f32 + 2f32.powi(-8), -3.0, 0.1];
        bn.running_var = ndarray::array![0.1f32, 2.0, 3.0];
        let rounded = bn.weight.value.mapv(|v| bf16_to_f32(bf16_bits(v)));
        // 0.1 rounds up to 0x3DCD, 0.10009765625.
        assert_eq!(
            rounded,
            ndarray::array![1.0f32, -3.0, f32::from_bits(0x3DCD_0000)]
        );
        save_params(&path, &bn).unwrap();
        let bf16_path = temp("bf16-rewritten");
        rewrite_with_bf16(&path, &bf16_path, &|name| name == "weight").unwrap();
        let bytes = std::fs::read(&bf16_path).unwrap();
        let file = SafeTensors::deserialize(&bytes).unwrap();
        assert_eq!(file.tensor("weight").unwrap().dtype(), Dtype::BF16);
        assert_eq!(file.tensor("running_var").unwrap().dtype(), Dtype::F32);
        let mut back = BatchNorm::<f32>::new(3);
        load_params(&bf16_path, &mut back).unwrap();
        assert_eq!(back.weight.value, rounded);
        assert_eq!(back.running_var, bn.running_var);
        let (as_f64, _) = read_tensors::<f64>(&bf16_path).unwrap();
        assert_eq!(as_f64["weight"][[2]], 0.10009765625);
        std::fs::remove_file(&path).unwrap();
        std::fs::remove_file(&bf16_path).unwrap();
    }

    #[test]
    fn a_file_that_is_not_safetensors_is_an_error() {
        let path = temp("garbage");
        std::fs::write(&path, b"not a weight file").unwrap();
        assert!(matches!(
            load_params(&path, &mut BatchNorm::<f32>::new(2)),
            Err(NnError::NotSafetensors { .. })
        ));
        let err = load_params(&path, &mut BatchNorm::<f32>::new(2)).unwrap_err();
        assert_eq!(
            err.to_string(),
            format!(
                "{}: not a safetensors weight file: its first 8 bytes do not give a header \
                 length that fits in the file",
                path.display()
            )
        );
        // Cut short: the header promises more data than the file holds.
        let mut bn = BatchNorm::<f32>::new(2);
        save_params(&path, &bn).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() - 3]).unwrap();
        let err = load_params(&path, &mut bn).unwrap_err().to_string();
        assert!(err.ends_with("(a truncated or damaged file)"), "{err}");
        let err = load_params(Path::new("/dev/zero"), &mut bn).unwrap_err();
        assert_eq!(
            err.to_string(),
            "/dev/zero: is a device, FIFO or socket, not a file"
        );
        std::fs::remove_file(&path).unwrap();
    }

    /// Issue 59, E10: a full disk while saving (here `/dev/full`) was told in the safetensors
    /// crate's Debug form (`IoError(Os { code: 28, … })`); it is the I/O error, by its path.
    #[test]
    fn a_full_disk_is_told_as_an_io_error() {
        let bn = BatchNorm::<f32>::new(2);
        let err = save_params(Path::new("/dev/full"), &bn).unwrap_err();
        assert!(matches!(err, NnError::Io { .. }), "{err:?}");
        assert_eq!(
            err.to_string(),
            "/dev/full: No space left on device (os error 28)"
        );
    }
}
