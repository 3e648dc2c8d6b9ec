//! Derendering: images, poses and the head scan to calibrated BRDF samples (equations 2 and 3 of the method).
