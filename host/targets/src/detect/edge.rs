//! The edge estimator's gradient, shared by the outer edges (`refine`) and the inner ones
//! (`border_width`): the centroid of the squared dark-to-light central difference along the
//! edge's normal.

/// Half the span of the central difference that measures the edge gradient, pixels (the
/// reference library uses 1; wider is less sensitive to noise and JPEG ringing, narrower
/// resolves closely spaced edges of tiny tags).
pub const GRADIENT_HALF_SPAN_PX: f64 = 1.0;

/// Cells narrower than this (pixels) use half the gradient span.
pub const SMALL_CELL_PX: f64 = 3.0;

/// The gradient's half span on cells of `cell_px`: on cells under [`SMALL_CELL_PX`] the
/// border's inner edge and the white ring's outer edge are within a cell of the edge measured,
/// and half of [`GRADIENT_HALF_SPAN_PX`] keeps their gradient lobes from biasing it.
pub(crate) fn gradient_half_span_px(cell_px: f64) -> f64 {
    if cell_px < SMALL_CELL_PX {
        0.5 * GRADIENT_HALF_SPAN_PX
    } else {
        GRADIENT_HALF_SPAN_PX
    }
}
