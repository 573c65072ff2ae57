//! Trainable parameters (value and gradient side by side) and the by-name view of a layer's
//! tensors that optimisers and weight files use.

use crate::Scalar;
use ndarray::{Array, ArrayViewD, ArrayViewMutD, Dimension};

/// A trainable tensor with its gradient of the same shape. Backward passes add into `grad`;
/// [`Parameters::zero_grad`] clears it once per step.
#[derive(Clone, Debug, PartialEq)]
pub struct Param<T, D: Dimension> {
    /// The current value.
    pub value: Array<T, D>,
    /// The accumulated gradient of the loss with respect to `value`.
    pub grad: Array<T, D>,
}

impl<T: Scalar, D: Dimension> Param<T, D> {
    /// A parameter holding `value`, with a zero gradient.
    pub fn new(value: Array<T, D>) -> Self {
        let grad = Array::zeros(value.raw_dim());
        Self { value, grad }
    }

    /// A read-only dynamic-dimensional view of value and gradient, as
    /// [`Parameters::visit_params_ref`] hands it out.
    pub fn view(&self) -> ParamView<'_, T> {
        ParamView {
            value: self.value.view().into_dyn(),
            grad: self.grad.view().into_dyn(),
        }
    }

    /// A dynamic-dimensional view of value and gradient, as [`Parameters::visit_params`] hands
    /// it out.
    pub fn view_mut(&mut self) -> ParamViewMut<'_, T> {
        ParamViewMut {
            value: self.value.view_mut().into_dyn(),
            grad: self.grad.view_mut().into_dyn(),
        }
    }
}

/// Views of one parameter's value and gradient, any dimensionality.
pub struct ParamView<'a, T> {
    pub value: ArrayViewD<'a, T>,
    pub grad: ArrayViewD<'a, T>,
}

/// Mutable views of one parameter's value and gradient, any dimensionality.
pub struct ParamViewMut<'a, T> {
    pub value: ArrayViewMutD<'a, T>,
    pub grad: ArrayViewMutD<'a, T>,
}

/// A layer or model that exposes its tensors by name (PyTorch state-dict style: `prefix.name`).
/// The visiting order must be fixed: optimisers keep their state in that order.
///
/// Two visitors, as burn's `ModuleVisitor` and `ModuleMapper`: the read-only `*_ref` ones for
/// counting, saving and reading gradients (`&self`), the mutating ones for updates and loading.
/// Both must give the same names in the same order.
pub trait Parameters<T: Scalar> {
    /// Calls `f(name, param)` for every trainable parameter, read-only.
    fn visit_params_ref<'a>(&'a self, prefix: &str, f: &mut dyn FnMut(&str, ParamView<'a, T>));

    /// Calls `f(name, param)` for every trainable parameter, to change it.
    fn visit_params(&mut self, prefix: &str, f: &mut dyn FnMut(&str, ParamViewMut<'_, T>));

    /// Calls `f(name, tensor)` for every saved, non-trained tensor (batch-norm running
    /// statistics), read-only. None by default.
    fn visit_buffers_ref<'a>(&'a self, _prefix: &str, _f: &mut dyn FnMut(&str, ArrayViewD<'a, T>)) {
    }

    /// [`Parameters::visit_buffers_ref`], to change them.
    fn visit_buffers(&mut self, _prefix: &str, _f: &mut dyn FnMut(&str, ArrayViewMutD<'_, T>)) {}

    /// Sets every parameter gradient to zero (once per step, before the backward pass).
    fn zero_grad(&mut self) {
        self.visit_params("", &mut |_, mut p| p.grad.fill(T::zero()));
    }

    /// The total number of trainable values.
    fn num_params(&self) -> usize {
        let mut n = 0;
        self.visit_params_ref("", &mut |_, p| n += p.value.len());
        n
    }
}

/// [`Parameters::visit_params`] with a visitor that can fail (loading a tensor that does not
/// fit): after the first error no parameter is handed to `f` again, and that error is returned.
pub fn try_visit_params<T: Scalar, E>(
    model: &mut (impl Parameters<T> + ?Sized),
    prefix: &str,
    mut f: impl FnMut(&str, ParamViewMut<'_, T>) -> Result<(), E>,
) -> Result<(), E> {
    let mut result = Ok(());
    model.visit_params(prefix, &mut |name, p| {
        if result.is_ok() {
            result = f(name, p);
        }
    });
    result
}

/// [`Parameters::visit_buffers`] with a visitor that can fail, as [`try_visit_params`].
pub fn try_visit_buffers<T: Scalar, E>(
    model: &mut (impl Parameters<T> + ?Sized),
    prefix: &str,
    mut f: impl FnMut(&str, ArrayViewMutD<'_, T>) -> Result<(), E>,
) -> Result<(), E> {
    let mut result = Ok(());
    model.visit_buffers(prefix, &mut |name, b| {
        if result.is_ok() {
            result = f(name, b);
        }
    });
    result
}

/// `prefix.name`, or `name` when the prefix is empty.
pub fn join_name(prefix: &str, name: &str) -> String {
    if prefix.is_empty() {
        name.to_string()
    } else {
        format!("{prefix}.{name}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::BatchNorm;

    #[test]
    fn a_failing_visitor_stops_at_its_first_error() {
        // Batch norm's parameters are weight, bias; its buffers running_mean, running_var.
        let mut bn = BatchNorm::<f32>::new(2);
        let mut seen = Vec::new();
        let result = try_visit_params(&mut bn, "bn", |name, mut p| {
            seen.push(name.to_string());
            if name == "bn.weight" {
                return Err(format!("{name} refused"));
            }
            p.value.fill(7.0);
            Ok(())
        });
        assert_eq!(result, Err("bn.weight refused".to_string()));
        assert_eq!(seen, ["bn.weight"]);
        assert_eq!(bn.bias.value, ndarray::array![0.0f32, 0.0]);

        let mut seen = Vec::new();
        let result = try_visit_buffers(&mut bn, "", |name, mut b| {
            seen.push(name.to_string());
            b.fill(3.0);
            Ok::<(), String>(())
        });
        assert_eq!(result, Ok(()));
        assert_eq!(seen, ["running_mean", "running_var"]);
        assert_eq!(bn.running_var, ndarray::array![3.0f32, 3.0]);
    }
}
