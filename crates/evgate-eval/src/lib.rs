//! Evaluation of motion-aware event suppression: metrics (IoU, mIoU, pIoU, SR@0.5, R@0.5,
//! per-event precision / recall / F1), the baselines (OMS, no forecast, linear extrapolation,
//! oracle), the harness that runs them and the model over labelled sequences, and the reports.

pub mod components;
pub mod event_scores;
pub mod hungarian;
pub mod instances;
pub mod linear;
pub mod oms;
pub mod plot;
pub mod segmentation;
