//! Why rendering failed (the graphics device, or a frame that does not fit the renderer).

/// Why rendering failed.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error("no graphics adapter (install mesa-vulkan-drivers for software Vulkan): {0}")]
    NoAdapter(String),
    #[error("graphics device error: {0}")]
    Device(String),
    #[error("scene has {have} vertices, more than the {capacity} the renderer was built for")]
    TooManyVertices { have: usize, capacity: usize },
    #[error("output buffer holds {have} elements, a stereo frame needs {want}")]
    OutputSize { have: usize, want: usize },
    #[error("both cameras must have the same resolution")]
    ResolutionMismatch,
}
