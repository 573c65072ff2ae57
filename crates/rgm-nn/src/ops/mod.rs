//! The ops, one module per op (or small family); in each, the forward sits directly above its
//! backward and the doc comment states the derivative.

pub mod attention;
pub mod batchnorm;
pub mod concat;
pub mod edge;
pub mod feedforward;
pub mod gram;
pub mod layernorm;
pub mod linear;
pub mod matmul;
pub mod max_k;
pub mod normalize;
pub mod relu;
pub mod softmax;
