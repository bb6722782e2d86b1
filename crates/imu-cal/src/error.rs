//! The one error type of the fitting side.

/// Errors of the fitting side: what went wrong and where.
#[derive(Debug, Clone, PartialEq)]
pub enum CalError {
    /// Bad or insufficient input data.
    Input(String),
    /// The model cannot be fitted from this data.
    Fit(String),
}

impl std::fmt::Display for CalError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CalError::Input(s) => write!(f, "input: {s}"),
            CalError::Fit(s) => write!(f, "fit: {s}"),
        }
    }
}

impl std::error::Error for CalError {}
