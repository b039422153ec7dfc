//! Tools over the renderer: comparing a render with a reference and the paper's figure series.

pub mod compare;
pub mod figures;
