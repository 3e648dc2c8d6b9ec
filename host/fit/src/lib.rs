//! Local quadratic regression smoothing, nonlinear least-squares BRDF fitting, polar plots and renderings.
