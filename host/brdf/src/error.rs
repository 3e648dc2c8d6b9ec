/// Errors of BRDF model construction and validation.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BrdfError {
    /// A parameter is out of range or not finite.
    #[error("BRDF parameter `{field}` {reason}")]
    InvalidParameter {
        /// The parameter (e.g. `lobes[1].exponent`).
        field: String,
        /// What is wrong.
        reason: String,
    },
    /// A parameter vector of the wrong length.
    #[error("model {model} takes {expected} parameters per channel, got {found}")]
    ParamCount {
        /// The model.
        model: String,
        /// Expected length.
        expected: usize,
        /// Given length.
        found: usize,
    },
    /// An unknown model name.
    #[error("unknown model `{0}` (expected lambertian, lafortune1, lafortune2, lafortune3 or cook-torrance)")]
    UnknownModel(String),
}
