//! The one error of reading a scenario, wherever in the file it is found.

use std::path::PathBuf;

/// A scenario that could not be read. Displays as `file:line:column: field: message`.
#[derive(Debug, Clone, thiserror::Error)]
#[error("{}:{line}:{column}: {field}: {message}", file.display())]
pub struct ScenarioError {
    pub file: PathBuf,
    /// 1-based; 0 when unknown.
    pub line: usize,
    /// 1-based; 0 when unknown.
    pub column: usize,
    /// Dotted path of the offending field, e.g. `blocks[1].size_mm`; `(file)` for the file.
    pub field: String,
    pub message: String,
}
