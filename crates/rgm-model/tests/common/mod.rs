//! What the tests that compare against a PyTorch fixture share: reading its tensors as
//! matrices, by prefix, and as ground-truth correspondences.

use ndarray::{Array2, ArrayD, Ix2};
use rgm_match::Correspondences;
use rgm_model::network::Element;
use std::collections::HashMap;

/// The fixture's tensor `name` as a matrix.
pub fn matrix(t: &HashMap<String, ArrayD<f64>>, name: &str) -> Array2<f64> {
    t[name].clone().into_dimensionality::<Ix2>().unwrap()
}

/// Tensors under `prefix.` with the prefix stripped.
pub fn with_prefix<T: Element>(
    t: &HashMap<String, ArrayD<T>>,
    prefix: &str,
) -> HashMap<String, ArrayD<T>> {
    t.iter()
        .filter_map(|(k, v)| k.strip_prefix(prefix).map(|k| (k.to_string(), v.clone())))
        .collect()
}

/// The correspondences of a dense 0/1 ground-truth matrix (N, M).
pub fn ground_truth(gt: &Array2<f64>) -> Correspondences {
    let pairs = gt
        .indexed_iter()
        .filter(|(_, &v)| v == 1.0)
        .map(|(ij, _)| ij)
        .collect();
    Correspondences::new(gt.nrows(), gt.ncols(), pairs).unwrap()
}
