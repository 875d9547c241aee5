//! The progress callback that [`crate::bake()`] and its stages report to.

/// Progress callback: `(stage, done, total)`. Called from worker threads.
pub type Progress<'a> = dyn Fn(&str, u64, u64) + Sync + 'a;
