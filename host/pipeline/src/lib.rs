//! The planned processing pipeline: poses, derendering, smoothing and fitting, with per-stage accuracy and run time.
