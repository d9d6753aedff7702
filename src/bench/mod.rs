//! `sepmem bench` building blocks: the paper's evaluation (§IV) inputs.
//!
//! [`clouds`] generates the deterministic input clouds of Table 1 (four
//! conditions), the sphere robustness sweep and the attribute ablation.
pub mod clouds;
