//! Evaluation: a renderer of dives with known ground truth, the scores, the demo and the speed bench.

pub mod bench;
pub mod demo;
pub mod evaluate;
pub mod matrix;
pub mod register;
pub mod simulate;
