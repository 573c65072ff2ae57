//! Optimisers with PyTorch's update rules (SGD with momentum, Adam, L2 weight decay), the
//! multi-step learning-rate schedule, and their state in safetensors files for resuming.

use crate::io::{read_tensors, write_tensors, NamedViews};
use crate::param::{try_visit_params, ParamViewMut};
use crate::{NnError, Parameters, Result, Scalar};
use ndarray::{ArrayD, Zip};
use std::collections::HashMap;
use std::path::Path;

/// Per-parameter state tensors (one per kind: `velocity`, or `m` and `v`) in the model's
/// visiting order, named after their parameter.
#[derive(Clone, Debug)]
struct Slots<T> {
    kinds: &'static [&'static str],
    names: Vec<String>,
    tensors: Vec<Vec<ArrayD<T>>>, // [parameter][kind]
}

impl<T: Scalar> Slots<T> {
    fn new(kinds: &'static [&'static str]) -> Self {
        Self {
            kinds,
            names: Vec::new(),
            tensors: Vec::new(),
        }
    }

    /// Visits the model's parameters with their state tensors (created as zeros on first use).
    /// Errors if the model's parameters are not the ones the state was created for.
    fn for_each(
        &mut self,
        op: &'static str,
        model: &mut dyn Parameters<T>,
        mut f: impl FnMut(&mut [ArrayD<T>], ParamViewMut<'_, T>),
    ) -> Result<()> {
        let mut i = 0;
        try_visit_params(model, "", |name, p| {
            if i == self.names.len() {
                self.names.push(name.to_string());
                self.tensors.push(
                    self.kinds
                        .iter()
                        .map(|_| ArrayD::zeros(p.value.raw_dim()))
                        .collect(),
                );
            }
            if self.names[i] != name || self.tensors[i][0].shape() != p.value.shape() {
                return Err(NnError::InvalidArgument {
                    op,
                    why: format!(
                        "parameter {i} is {name:?} {:?}, the optimiser state has {:?} {:?}",
                        p.value.shape(),
                        self.names[i],
                        self.tensors[i][0].shape()
                    ),
                });
            }
            f(&mut self.tensors[i], p);
            i += 1;
            Ok(())
        })
    }

    /// The state as `kind.parameter_name` tensors, and the metadata entry listing the order.
    fn named(&self) -> (NamedViews<'_, T>, (String, String)) {
        let mut out = Vec::new();
        for (name, ts) in self.names.iter().zip(&self.tensors) {
            for (kind, t) in self.kinds.iter().zip(ts) {
                out.push((format!("{kind}.{name}"), t.view()));
            }
        }
        (out, ("order".to_string(), self.names.join("\n")))
    }

    /// Rebuilds the slots from the tensors and `order` metadata written by [`Slots::named`].
    /// The kinds in `zero_if_missing` may be absent from the file (a snapshot that left them
    /// out): they start as zeros of the parameter's shape, taken from the last kind.
    fn read(
        kinds: &'static [&'static str],
        zero_if_missing: &[&str],
        path: &Path,
    ) -> Result<(Self, HashMap<String, String>)> {
        let (mut tensors, meta) = read_tensors(path)?;
        let mut slots = Self::new(kinds);
        for name in meta
            .get("order")
            .map(|o| o.lines().collect::<Vec<_>>())
            .unwrap_or_default()
        {
            let mut per_kind: Vec<Option<ArrayD<T>>> = kinds
                .iter()
                .map(|kind| tensors.remove(&format!("{kind}.{name}")))
                .collect();
            let shape = per_kind.last().cloned().flatten().map(|t| t.raw_dim());
            for (kind, slot) in kinds.iter().zip(&mut per_kind) {
                if slot.is_none() {
                    match (&shape, zero_if_missing.contains(kind)) {
                        (Some(shape), true) => *slot = Some(ArrayD::zeros(shape.clone())),
                        _ => {
                            return Err(NnError::MissingTensor {
                                path: path.to_path_buf(),
                                name: format!("{kind}.{name}"),
                            })
                        }
                    }
                }
            }
            slots.names.push(name.to_string());
            slots.tensors.push(per_kind.into_iter().flatten().collect());
        }
        Ok((slots, meta))
    }
}

/// An optimiser: one update of a model's parameters from their accumulated gradients per
/// [`Optimizer::step`], as burn's `Optimizer`, so a trainer holds any of them. Its state (the
/// per-parameter buffers, kept in the model's visiting order) saves to a safetensors file;
/// each optimiser's own `load` reads it back.
pub trait Optimizer<T: Scalar>: Send {
    /// One update of every parameter from its accumulated gradient. Errors if the model's
    /// parameters are not the ones the state was made for.
    fn step(&mut self, model: &mut dyn Parameters<T>) -> Result<()>;

    /// The learning rate of the next steps.
    fn lr(&self) -> f64;

    /// Sets the learning rate of the next steps (a schedule's).
    fn set_lr(&mut self, lr: f64);

    /// Writes the state and hyper-parameters to a safetensors file.
    fn save(&self, path: &Path) -> Result<()>;
}

fn metadata_number(meta: &HashMap<String, String>, key: &str, path: &Path) -> Result<f64> {
    meta.get(key)
        .and_then(|v| v.parse().ok())
        .ok_or_else(|| NnError::InvalidArgument {
            op: "optimiser load",
            why: format!(
                "{}: metadata {key:?} missing or not a number",
                path.display()
            ),
        })
}

/// SGD with momentum, `torch.optim.SGD` (dampening 0):
/// `g = grad + weight_decay · p`, `v = momentum · v + g`, then `p −= lr · v`, or with
/// `nesterov` (the reference's setting, spec §3) `p −= lr · (g + momentum · v)`.
#[derive(Clone, Debug)]
pub struct Sgd<T> {
    pub lr: f64,
    pub momentum: f64,
    pub weight_decay: f64,
    pub nesterov: bool,
    velocity: Slots<T>,
}

impl<T: Scalar> Sgd<T> {
    /// Plain momentum; set [`Sgd::nesterov`] for Nesterov's.
    pub fn new(lr: f64, momentum: f64, weight_decay: f64) -> Self {
        Self {
            lr,
            momentum,
            weight_decay,
            nesterov: false,
            velocity: Slots::new(&["velocity"]),
        }
    }

    /// Reads a state written by [`Optimizer::save`] (plain momentum when it names none).
    pub fn load(path: &Path) -> Result<Self> {
        let (velocity, meta) = Slots::read(&["velocity"], &[], path)?;
        let num = |k| metadata_number(&meta, k, path);
        Ok(Self {
            lr: num("lr")?,
            momentum: num("momentum")?,
            weight_decay: num("weight_decay")?,
            nesterov: meta.get("nesterov").is_some_and(|v| v == "true"),
            velocity,
        })
    }
}

impl<T: Scalar> Optimizer<T> for Sgd<T> {
    fn step(&mut self, model: &mut dyn Parameters<T>) -> Result<()> {
        let (lr, mu, wd) = (
            T::from_f64(self.lr),
            T::from_f64(self.momentum),
            T::from_f64(self.weight_decay),
        );
        let nesterov = self.nesterov;
        self.velocity.for_each("sgd step", model, |state, mut p| {
            Zip::from(&mut state[0])
                .and(&mut p.value)
                .and(&p.grad)
                .for_each(|v, w, &g| {
                    let g = g + wd * *w;
                    *v = mu * *v + g;
                    *w -= lr * if nesterov { g + mu * *v } else { *v };
                });
        })
    }

    fn lr(&self) -> f64 {
        self.lr
    }

    fn set_lr(&mut self, lr: f64) {
        self.lr = lr;
    }

    /// Writes the momentum buffers and hyper-parameters.
    fn save(&self, path: &Path) -> Result<()> {
        let (tensors, order) = self.velocity.named();
        let meta = HashMap::from([
            ("optimizer".to_string(), "sgd".to_string()),
            ("lr".to_string(), self.lr.to_string()),
            ("momentum".to_string(), self.momentum.to_string()),
            ("weight_decay".to_string(), self.weight_decay.to_string()),
            ("nesterov".to_string(), self.nesterov.to_string()),
            order,
        ]);
        write_tensors(path, &tensors, meta)
    }
}

/// Adam, `torch.optim.Adam` (L2 weight decay added to the gradient, not AdamW):
/// `g = grad + weight_decay · p`, `m = β1 m + (1 − β1) g`, `v = β2 v + (1 − β2) g²`,
/// `p −= lr · (m / (1 − β1ᵗ)) / (√(v / (1 − β2ᵗ)) + eps)`.
#[derive(Clone, Debug)]
pub struct Adam<T> {
    pub lr: f64,
    pub beta1: f64,
    pub beta2: f64,
    pub eps: f64,
    pub weight_decay: f64,
    step: u64,
    moments: Slots<T>, // first moment `m`, second moment `v`
}

impl<T: Scalar> Adam<T> {
    /// PyTorch's defaults besides `lr`: β = (0.9, 0.999), eps 1e-8.
    pub fn new(lr: f64, weight_decay: f64) -> Self {
        Self {
            lr,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
            weight_decay,
            step: 0,
            moments: Slots::new(&["m", "v"]),
        }
    }

    /// Reads a state written by [`Optimizer::save`]. The first moments may be missing (a
    /// snapshot kept small for git): they restart from zero, and after n steps hold all but
    /// 0.9ⁿ of the gradient history they would have had.
    pub fn load(path: &Path) -> Result<Self> {
        let (moments, meta) = Slots::read(&["m", "v"], &["m"], path)?;
        let num = |k| metadata_number(&meta, k, path);
        Ok(Self {
            lr: num("lr")?,
            beta1: num("beta1")?,
            beta2: num("beta2")?,
            eps: num("eps")?,
            weight_decay: num("weight_decay")?,
            step: num("step")? as u64,
            moments,
        })
    }
}

impl<T: Scalar> Optimizer<T> for Adam<T> {
    fn step(&mut self, model: &mut dyn Parameters<T>) -> Result<()> {
        self.step += 1;
        let t = self.step as i32;
        let (b1, b2) = (T::from_f64(self.beta1), T::from_f64(self.beta2));
        let step_size = T::from_f64(self.lr / (1.0 - self.beta1.powi(t)));
        let sqrt_bc2 = T::from_f64((1.0 - self.beta2.powi(t)).sqrt());
        let (eps, wd) = (T::from_f64(self.eps), T::from_f64(self.weight_decay));
        self.moments.for_each("adam step", model, |state, mut p| {
            let [m, v] = state else {
                unreachable!("two moments per parameter")
            };
            Zip::from(m)
                .and(v)
                .and(&mut p.value)
                .and(&p.grad)
                .for_each(|m, v, w, &g| {
                    let g = g + wd * *w;
                    *m = b1 * *m + (T::one() - b1) * g;
                    *v = b2 * *v + (T::one() - b2) * g * g;
                    *w -= step_size * *m / (v.sqrt() / sqrt_bc2 + eps);
                });
        })
    }

    fn lr(&self) -> f64 {
        self.lr
    }

    fn set_lr(&mut self, lr: f64) {
        self.lr = lr;
    }

    /// Writes both moments, the step count and the hyper-parameters.
    fn save(&self, path: &Path) -> Result<()> {
        let (tensors, order) = self.moments.named();
        let meta = HashMap::from([
            ("optimizer".to_string(), "adam".to_string()),
            ("lr".to_string(), self.lr.to_string()),
            ("beta1".to_string(), self.beta1.to_string()),
            ("beta2".to_string(), self.beta2.to_string()),
            ("eps".to_string(), self.eps.to_string()),
            ("weight_decay".to_string(), self.weight_decay.to_string()),
            ("step".to_string(), self.step.to_string()),
            order,
        ]);
        write_tensors(path, &tensors, meta)
    }
}

/// `torch.optim.lr_scheduler.MultiStepLR`: the rate is `base · gamma^(milestones passed)`
/// (the paper: base 1e-3, milestones 120 and 140, gamma 0.2).
#[derive(Clone, Debug, PartialEq)]
pub struct MultiStepLr {
    pub base: f64,
    pub milestones: Vec<usize>,
    pub gamma: f64,
}

impl MultiStepLr {
    /// The learning rate of epoch `epoch` (counted from 0).
    pub fn lr(&self, epoch: usize) -> f64 {
        let passed = self.milestones.iter().filter(|&&m| epoch >= m).count();
        self.base * self.gamma.powi(passed as i32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Linear;
    use rand::{rngs::StdRng, SeedableRng};

    // Expected trajectories against PyTorch are pinned in `pytorch_pinned`; these check the rest.

    #[test]
    fn sgd_momentum_by_hand() {
        // p = 1, g = 0.5 each step, lr 0.1, μ 0.9: v = 0.5 then 0.95; p = 0.95 then 0.855.
        let mut lin = Linear::<f64>::from_values(ndarray::array![[1.0]], None).unwrap();
        let mut sgd = Sgd::new(0.1, 0.9, 0.0);
        for want in [0.95, 0.855] {
            lin.weight.grad.fill(0.5);
            sgd.step(&mut lin).unwrap();
            assert!((lin.weight.value[[0, 0]] - want).abs() < 1e-15);
        }
    }

    #[test]
    fn sgd_nesterov_by_hand() {
        // As above with Nesterov: the step is g + μv = 0.95, then 0.5 + 0.9·0.95 = 1.355,
        // so p = 0.905, then 0.7695 (torch.optim.SGD(nesterov=True)).
        let mut lin = Linear::<f64>::from_values(ndarray::array![[1.0]], None).unwrap();
        let mut sgd = Sgd::new(0.1, 0.9, 0.0);
        sgd.nesterov = true;
        for want in [0.905, 0.7695] {
            lin.weight.grad.fill(0.5);
            sgd.step(&mut lin).unwrap();
            assert!((lin.weight.value[[0, 0]] - want).abs() < 1e-15);
        }
    }

    #[test]
    fn learning_rate_drops_at_each_milestone() {
        let s = MultiStepLr {
            base: 1e-3,
            milestones: vec![120, 140],
            gamma: 0.2,
        };
        assert_eq!((s.lr(0), s.lr(119)), (1e-3, 1e-3));
        assert!((s.lr(120) - 2e-4).abs() < 1e-18 && (s.lr(139) - 2e-4).abs() < 1e-18);
        assert!((s.lr(140) - 4e-5).abs() < 1e-18 && (s.lr(199) - 4e-5).abs() < 1e-18);
    }

    /// Three steps straight equal two steps, a save and load of model and optimiser, and one
    /// more step: `fresh` makes an optimiser, `reload` saves it to a file and reads it back.
    fn assert_resume_is_exact<O>(
        fresh: impl Fn() -> O,
        step: impl Fn(&mut O, &mut Linear<f32>) -> Result<()>,
        reload: impl Fn(&O, &Path) -> Result<O>,
    ) {
        let dir = std::env::temp_dir().join(format!(
            "rgm-nn-resume-{}-{}",
            std::process::id(),
            std::any::type_name::<O>().len()
        ));
        std::fs::create_dir_all(&dir).unwrap();
        let model = || Linear::<f32>::new(3, 2, true, &mut StdRng::seed_from_u64(5));
        let set_grads = |lin: &mut Linear<f32>, t: usize| {
            lin.weight.grad = lin.weight.value.mapv(|w| w * 0.5 + t as f32);
            lin.bias.as_mut().unwrap().grad.fill(-(t as f32));
        };
        let (mut straight, mut opt) = (model(), fresh());
        for t in 0..3 {
            set_grads(&mut straight, t);
            step(&mut opt, &mut straight).unwrap();
        }
        let (mut first, mut opt) = (model(), fresh());
        for t in 0..2 {
            set_grads(&mut first, t);
            step(&mut opt, &mut first).unwrap();
        }
        crate::io::save_params(&dir.join("model.safetensors"), &first).unwrap();
        let mut opt = reload(&opt, &dir.join("optimiser.safetensors")).unwrap();
        let mut resumed = Linear::<f32>::new(3, 2, true, &mut StdRng::seed_from_u64(99));
        crate::io::load_params(&dir.join("model.safetensors"), &mut resumed).unwrap();
        set_grads(&mut resumed, 2);
        step(&mut opt, &mut resumed).unwrap();
        assert_eq!(resumed.weight.value, straight.weight.value);
        assert_eq!(resumed.bias.unwrap().value, straight.bias.unwrap().value);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn sgd_resumes_exactly_from_a_saved_state() {
        for nesterov in [false, true] {
            assert_resume_is_exact(
                || Sgd {
                    nesterov,
                    ..Sgd::new(0.1, 0.9, 0.01)
                },
                |o, m| o.step(m),
                |o, path| {
                    o.save(path)?;
                    Sgd::load(path)
                },
            );
        }
    }

    #[test]
    fn adam_resumes_exactly_from_a_saved_state() {
        assert_resume_is_exact(
            || Adam::new(0.01, 0.01),
            |o, m| o.step(m),
            |o, path| {
                o.save(path)?;
                Adam::load(path)
            },
        );
    }

    /// A snapshot whose moments were stored as bf16 loads with every moment upcast from its
    /// rounded value, hyper-parameters and step count kept, and goes on stepping.
    #[test]
    fn adam_loads_moments_stored_as_bf16() {
        let dir = std::env::temp_dir().join(format!("rgm-nn-adam-bf16-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut lin = Linear::<f32>::new(3, 2, true, &mut StdRng::seed_from_u64(5));
        let mut adam = Adam::new(0.01, 0.0);
        for t in 0..2 {
            lin.weight.grad = lin.weight.value.mapv(|w| 0.37 * w + t as f32);
            lin.bias.as_mut().unwrap().grad.fill(0.3);
            adam.step(&mut lin).unwrap();
        }
        let (f32_path, bf16_path) = (
            dir.join("adam.safetensors"),
            dir.join("adam-bf16.safetensors"),
        );
        adam.save(&f32_path).unwrap();
        crate::io::rewrite_with_bf16(&f32_path, &bf16_path, &|n| {
            n.starts_with("m.") || n.starts_with("v.")
        })
        .unwrap();
        let loaded = Adam::<f32>::load(&bf16_path).unwrap();
        assert_eq!((loaded.step, loaded.lr, loaded.beta2), (2, 0.01, 0.999));
        let (exact, _) = read_tensors::<f32>(&f32_path).unwrap();
        let round = |t: &ArrayD<f32>| t.mapv(crate::bf16::round_to_bf16);
        let m = &loaded.moments.tensors[0][0];
        assert_eq!(m, &round(&exact["m.weight"]));
        assert_ne!(m, &exact["m.weight"], "0.37 w is not a bf16 value");
        let mut loaded = loaded;
        loaded.step(&mut lin).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A snapshot without the first moments loads them as zeros and keeps the second; one
    /// without the second moments is refused, naming the tensor.
    #[test]
    fn adam_restarts_missing_first_moments_from_zero() {
        let dir = std::env::temp_dir().join(format!("rgm-nn-adam-no-m-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut lin = Linear::<f32>::new(3, 2, true, &mut StdRng::seed_from_u64(6));
        let mut adam = Adam::new(0.01, 0.0);
        lin.weight.grad.fill(0.5);
        lin.bias.as_mut().unwrap().grad.fill(-0.25);
        adam.step(&mut lin).unwrap();
        let full = dir.join("adam.safetensors");
        adam.save(&full).unwrap();
        let (tensors, meta) = read_tensors::<f32>(&full).unwrap();
        for (drop, path) in [("m.", "no-m"), ("v.", "no-v")] {
            let kept: Vec<_> = tensors
                .iter()
                .filter(|(n, _)| !n.starts_with(drop))
                .map(|(n, t)| (n.clone(), t.view()))
                .collect();
            crate::io::write_tensors(&dir.join(path), &kept, meta.clone()).unwrap();
        }
        let loaded = Adam::<f32>::load(&dir.join("no-m")).unwrap();
        let (m, v) = (&loaded.moments.tensors[0][0], &loaded.moments.tensors[0][1]);
        assert!(m.iter().all(|&x| x == 0.0));
        assert_eq!(v, &tensors["v.weight"]);
        assert!(v.iter().all(|&x| x > 0.0));
        let err = Adam::<f32>::load(&dir.join("no-v"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("v.weight") || err.contains("v.bias"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn state_of_another_model_is_refused() {
        let mut sgd = Sgd::new(0.1, 0.9, 0.0);
        sgd.step(&mut Linear::<f32>::new(
            3,
            2,
            true,
            &mut StdRng::seed_from_u64(0),
        ))
        .unwrap();
        let err = sgd
            .step(&mut Linear::<f32>::new(
                4,
                2,
                true,
                &mut StdRng::seed_from_u64(0),
            ))
            .unwrap_err();
        assert!(
            err.to_string()
                .contains("\"weight\" [2, 4], the optimiser state has \"weight\" [2, 3]"),
            "{err}"
        );
    }
}
