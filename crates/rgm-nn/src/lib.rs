#![doc = include_str!("../README.md")]
//!
//! # Layering
//!
//! Layering rule: rgm-nn depends on no other rgm crate and knows nothing of geometry, point
//! clouds or matching. It owns the numeric engine: BLAS-backed matrix products, the ops, their
//! parameters, initialisation, optimisers and weight files.
//!
//! # Conventions (every op follows them; crates above should too)
//! - **Dimension letters**: B batch, N source points, M target points, K neighbours, C channels,
//!   Q graph width, H heads, F feed-forward width.
//! - **Shapes**: an activation is a row-major [`ndarray::Array2`] `(rows, C)`: one row per point
//!   (`(N, C)`) or per point-neighbour pair (`(N*K, C)`, row `n*K + k`, the neighbour index
//!   fastest); columns are channels. A batch is stacked along the rows for row-wise ops (linear,
//!   batch norm, ReLU, max over K) and looped over where rows interact (attention, softmax of a
//!   score matrix, L1 normalisation).
//! - **Weights** keep PyTorch's layout: a linear / 1×1 convolution weight is `(C_out, C_in)` and
//!   `out = inp · weightᵀ + bias`, so state dicts convert without transposes.
//! - **Arguments**: ops take views, outputs first then inputs (llm.c order), and an op that
//!   runs a matrix product takes the compute settings ([`Compute`]) last:
//!   `forward(out, inp, .., cache, compute)`, `backward(dinp, .., dout, inp, .., cache,
//!   compute)`. The caller owns every buffer (reused across steps: no allocation in the hot
//!   path once shapes are stable); an op checks the shapes it is given and returns
//!   [`NnError::Shape`] on a mismatch.
//! - **Gradients accumulate**: every backward *adds* into `dinp` and into the parameters' `grad`
//!   buffers; the caller zeroes them once per step ([`Parameters::zero_grad`]). Gradient buffers
//!   are named `d` + the name of the value (`dinp`, `dout`, `dweight`).
//! - **Caches**: a forward pass fills an explicit cache struct holding exactly what its backward
//!   needs beyond the forward's own inputs and outputs (which the caller keeps).
//! - **Layers** with parameters are structs (`Linear`, `BatchNorm`, ...) holding [`Param`]s (value
//!   and gradient side by side); parameterless ops are free functions (`relu_forward`, ...).
//!   Layers expose their tensors by name through [`Parameters`], which the optimisers and the
//!   safetensors reader/writer use.
//! - **Elements**: every op is generic over [`Scalar`] (f32 for compute, f64 for the gradient
//!   checks in [`gradcheck`]).
//! - **Matrix products** all go through [`gemm::mat_mul`]: f32 on AVX-512 where the processor
//!   has it ([`gemm::f32_mat_mul`]) and BLAS elsewhere, f64 on BLAS, or bf16 inputs with f32
//!   accumulation on AMX tile units (or AVX-512 BF16) when the [`Compute`] it is given says
//!   [`Precision::Bf16`] (f32 where the processor has neither).
//! - **Threads**: BLAS products use OpenBLAS's own threads, the AVX-512 and bf16 ones the
//!   calling thread; the attention's row softmax (and its
//!   backward) runs on rayon's pool between BLAS calls; everything else runs on the calling
//!   thread. A caller that parallelises over independent work with rayon first sets BLAS to one
//!   thread ([`threads::set_blas_threads`]) so the two pools never nest.
//!
//! `tests/dgcnn_chain.rs` and `tests/encoder_chain.rs` compose the ops the way the model does
//! (buffers, caches, reverse-order backward, residual gradients) and check the chains end to end
//! by finite differences; `docs/nn.md` lists every op, its proof and its measured speed.

// Links the statically built OpenBLAS that ndarray's `blas` feature calls into.
extern crate openblas_src;

pub mod bf16;
pub mod compute;
pub mod error;
pub mod exp;
pub mod gemm;
pub mod gradcheck;
pub mod init;
pub mod io;
pub mod lanes;
pub mod ops;
pub mod optim;
pub mod param;
#[cfg(test)]
mod pytorch_pinned;
pub mod scalar;
pub mod threads;

pub use compute::{Compute, Precision};
pub use error::{NnError, Result};
pub use ops::attention::{AttentionCache, MultiHeadAttention};
pub use ops::batchnorm::{BatchNorm, BatchNormCache};
pub use ops::concat::{concat_backward, concat_forward};
pub use ops::edge::{edge_features_backward, edge_features_forward};
pub use ops::feedforward::{FeedForward, FeedForwardCache};
pub use ops::gram::{gram_backward, gram_forward};
pub use ops::layernorm::{LayerNorm, LayerNormCache};
pub use ops::linear::Linear;
pub use ops::matmul::{bmm_backward, bmm_forward, matmul_backward, matmul_forward};
pub use ops::max_k::{max_k_backward, max_k_forward, MaxKCache};
pub use ops::normalize::{
    l1_normalize_columns_backward, l1_normalize_columns_forward, L1NormalizeCache,
};
pub use ops::relu::{relu_backward, relu_forward, relu_in_place};
pub use ops::softmax::{softmax_rows_backward, softmax_rows_forward};
pub use optim::Optimizer;
pub use param::{Param, Parameters};
pub use scalar::Scalar;
