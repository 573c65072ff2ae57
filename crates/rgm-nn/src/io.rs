//! Weight files in safetensors (readable by PyTorch, numpy, candle): every parameter and buffer
//! under its state-dict name, in the element type of the model (F32 or F64).

use crate::{NnError, Parameters, Result, Scalar};
use ndarray::{ArrayD, ArrayViewD, IxDyn};
use safetensors::tensor::{Dtype, TensorView};
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

fn le_bytes<T: Scalar>(t: &ArrayViewD<'_, T>) -> Vec<u8> {
    let mut out = Vec::with_capacity(t.len() * std::mem::size_of::<T>());
    for &v in t.iter() {
        match dtype_of::<T>() {
            Dtype::F32 => out.extend_from_slice(&(Scalar::to_f64(v) as f32).to_le_bytes()),
            _ => out.extend_from_slice(&Scalar::to_f64(v).to_le_bytes()),
        }
    }
    out
}

/// Writes `tensors` (name, value) and string `metadata` to a safetensors file at `path`.
pub fn write_tensors<T: Scalar>(
    path: &Path,
    tensors: &[(String, ArrayViewD<'_, T>)],
    metadata: HashMap<String, String>,
) -> Result<()> {
    let bytes: Vec<Vec<u8>> = tensors.iter().map(|(_, t)| le_bytes(t)).collect();
    let views = tensors
        .iter()
        .zip(&bytes)
        .map(|((name, t), b)| {
            let view =
                TensorView::new(dtype_of::<T>(), t.shape().to_vec(), b).map_err(|source| {
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

/// Reads every tensor of a safetensors file (F32 or F64, converted to `T`) and its metadata.
pub fn read_tensors<T: Scalar>(path: &Path) -> Result<(Tensors<T>, HashMap<String, String>)> {
    let buffer = std::fs::read(path).map_err(|source| NnError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let st_err = |source| NnError::Safetensors {
        path: path.to_path_buf(),
        source,
    };
    let (_, header) = SafeTensors::read_metadata(&buffer).map_err(st_err)?;
    let metadata = header.metadata().clone().unwrap_or_default();
    let file = SafeTensors::deserialize(&buffer).map_err(st_err)?;
    let mut tensors = HashMap::new();
    for (name, view) in file.tensors() {
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
            other => {
                return Err(NnError::TensorDtype {
                    path: path.to_path_buf(),
                    name,
                    dtype: format!("{other:?}"),
                })
            }
        };
        let array = ArrayD::from_shape_vec(IxDyn(view.shape()), values)
            .expect("safetensors checked the byte length");
        tensors.insert(name, array);
    }
    Ok((tensors, metadata))
}

/// Saves every parameter and buffer of `model` under its name.
pub fn save_params<T: Scalar>(path: &Path, model: &mut dyn Parameters<T>) -> Result<()> {
    let mut owned: Vec<(String, ArrayD<T>)> = Vec::new();
    model.visit_params("", &mut |name, p| {
        owned.push((name.to_string(), p.value.to_owned()))
    });
    model.visit_buffers("", &mut |name, b| {
        owned.push((name.to_string(), b.to_owned()))
    });
    let views: Vec<_> = owned.iter().map(|(n, t)| (n.clone(), t.view())).collect();
    write_tensors(path, &views, HashMap::new())
}

/// Loads every parameter and buffer of `model` from `path`, checking each shape. A tensor the
/// model lacks is an error ([`NnError::MissingTensor`]), as is a mis-shaped one
/// ([`NnError::TensorShape`]); tensors in the file that the model does not use are ignored.
pub fn load_params<T: Scalar>(path: &Path, model: &mut dyn Parameters<T>) -> Result<()> {
    let (tensors, _) = read_tensors::<T>(path)?;
    let mut err = None;
    let mut fill = |name: &str, mut dst: ndarray::ArrayViewMutD<'_, T>| {
        if err.is_some() {
            return;
        }
        match tensors.get(name) {
            None => {
                err = Some(NnError::MissingTensor {
                    path: path.to_path_buf(),
                    name: name.to_string(),
                })
            }
            Some(t) if t.shape() != dst.shape() => {
                err = Some(NnError::TensorShape {
                    path: path.to_path_buf(),
                    name: name.to_string(),
                    expected: dst.shape().to_vec(),
                    got: t.shape().to_vec(),
                })
            }
            Some(t) => dst.assign(t),
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
        save_params(&path, &mut bn).unwrap();
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
            &mut Linear::<f32>::new(3, 2, false, &mut StdRng::seed_from_u64(0)),
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
    fn a_file_that_is_not_safetensors_is_an_error() {
        let path = temp("garbage");
        std::fs::write(&path, b"not a weight file").unwrap();
        assert!(matches!(
            load_params(&path, &mut BatchNorm::<f32>::new(2)),
            Err(NnError::Safetensors { .. })
        ));
        std::fs::remove_file(&path).unwrap();
    }
}
