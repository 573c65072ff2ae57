//! One module per subcommand, each with its `Args` and `run`.

pub mod eval;
pub mod eval_multiway;
pub mod merge;
pub mod page;
pub mod pair_list;
pub mod pairs;
pub mod register;
pub mod render;
pub mod score;
pub mod train;
