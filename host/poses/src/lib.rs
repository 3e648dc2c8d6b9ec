//! Photogrammetry: camera calibration, PnP with RANSAC, Levenberg-Marquardt pose refinement, flash triangulation.
