//! Weight files in safetensors (readable by PyTorch, numpy, candle): every parameter and buffer
//! under its state-dict name, in the element type of the model (F32 or F64).

use crate::bf16::{bf16_bits, bf16_to_f32};
use crate::{NnError, Parameters, Result, Scalar};
use ndarray::{ArrayD, ArrayViewD, IxDyn};
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
/// snapshots where that precision is enough (an optimiser's moments); the readers upcast.
pub fn write_tensors_with_bf16<T: Scalar>(
    path: &Path,
    tensors: &[(String, ArrayViewD<'_, T>)],
    metadata: HashMap<String, String>,
    bf16: &dyn Fn(&str) -> bool,
) -> Result<()> {
    let dtypes: Vec<Dtype> = tensors
        .iter()
        .map(|(name, _)| {
            if bf16(name) {
                Dtype::BF16
            } else {
                dtype_of::<T>()
            }
        })
        .collect();
    let bytes: Vec<Vec<u8>> = tensors
        .iter()
        .zip(&dtypes)
        .map(|((_, t), &dtype)| le_bytes(t, dtype))
        .collect();
    let views = tensors
        .iter()
        .zip(&dtypes)
        .zip(&bytes)
        .map(|(((name, t), &dtype), b)| {
            let view = TensorView::new(dtype, t.shape().to_vec(), b).map_err(|source| {
                NnError::Safetensors {
                    path: path.to_path_buf(),
                    source,
                }
            })?;
            Ok((name.clone(), view))
        })
        .collect::<Result<Vec<_>>>()?;
    safetensors::serialize_to_file(views, &Some(metadata), path).map_err(|source| {
        NnError::Safetensors {
            path: path.to_path_buf(),
            source,
        }
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
fn read_bytes(path: &Path) -> Result<Vec<u8>> {
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

/// The values of one F32, F64 or BF16 tensor, converted to `T`, in the file's shape.
fn to_array<T: Scalar>(path: &Path, name: &str, view: &TensorView<'_>) -> Result<ArrayD<T>> {
    let values: Vec<T> = match view.dtype() {
        Dtype::F32 => view
            .data()
            .chunks_exact(4)
            .map(|b| T::from_f64(f32::from_le_bytes(b.try_into().unwrap()) as f64))
            .collect(),
        Dtype::F64 => view
            .data()
            .chunks_exact(8)
            .map(|b| T::from_f64(f64::from_le_bytes(b.try_into().unwrap())))
            .collect(),
        Dtype::BF16 => view
            .data()
            .chunks_exact(2)
            .map(|b| T::from_f64(bf16_to_f32(u16::from_le_bytes([b[0], b[1]])) as f64))
            .collect(),
        other => {
            return Err(NnError::TensorDtype {
                path: path.to_path_buf(),
                name: name.to_string(),
                dtype: format!("{other:?}"),
            })
        }
    };
    Ok(ArrayD::from_shape_vec(IxDyn(view.shape()), values)
        .expect("safetensors checked the byte length"))
}

/// Reads every tensor of a safetensors file (all must be F32, F64 or BF16; converted to `T`)
/// and its metadata.
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
    let mut tensors = HashMap::new();
    for (name, view) in parse(origin, buffer)?.tensors() {
        let array = to_array(origin, &name, &view)?;
        tensors.insert(name, array);
    }
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
    let buffer = read_bytes(path)?;
    let file = parse(path, &buffer)?;
    let mut err = None;
    let mut fill = |name: &str, mut dst: ndarray::ArrayViewMutD<'_, T>| {
        if err.is_some() {
            return;
        }
        let Ok(view) = file.tensor(name) else {
            err = Some(NnError::MissingTensor {
                path: path.to_path_buf(),
                name: name.to_string(),
            });
            return;
        };
        let (got, want) = (view.shape(), dst.shape());
        let trailing_ones = got.len() >= want.len() && got[want.len()..].iter().all(|&d| d == 1);
        if !trailing_ones || &got[..want.len()] != want {
            err = Some(NnError::TensorShape {
                path: path.to_path_buf(),
                name: name.to_string(),
                expected: want.to_vec(),
                got: got.to_vec(),
            });
            return;
        }
        match to_array::<T>(path, name, &view) {
            Ok(t) => dst.assign(
                &t.into_shape_with_order(want.to_vec())
                    .expect("same number of values"),
            ),
            Err(e) => err = Some(e),
        }
    };
    model.visit_params("", &mut |name, p| fill(name, p.value));
    model.visit_buffers("", &mut |name, b| fill(name, b));
    err.map_or(Ok(()), Err)
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
}
