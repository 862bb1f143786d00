//! GRAY8 images: a borrowed view that can sit directly on a shared-memory sample, and an
//! owned buffer for everything else.

use thiserror::Error;

/// Why an [`ImageView`] could not be built over a byte slice.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum ImageViewError {
    #[error("image has zero width or height ({width}x{height})")]
    Empty { width: usize, height: usize },
    #[error("stride {stride} is smaller than width {width}")]
    StrideTooSmall { width: usize, stride: usize },
    #[error("buffer of {len} bytes is too short for {height} rows of stride {stride} (width {width})")]
    TooShort { width: usize, height: usize, stride: usize, len: usize },
}

/// A borrowed 8-bit grayscale image: `height` rows of `stride` bytes, the first `width` of
/// which are pixels. Built over any byte slice without copying.
///
/// ```
/// use handeye_vision::image::ImageView;
/// let bytes = [0u8, 10, 99, 20, 30, 99]; // 2x2 pixels, stride 3 (one padding byte per row)
/// let img = ImageView::new(&bytes, 2, 2, 3).unwrap();
/// assert_eq!(img.get(1, 1), 30);
/// assert_eq!(img.row(1), &[20, 30]);
/// ```
#[derive(Debug, Clone, Copy)]
pub struct ImageView<'a> {
    data: &'a [u8],
    width: usize,
    height: usize,
    stride: usize,
}

impl<'a> ImageView<'a> {
    /// A view of `height` rows of `stride` bytes over `data`. The last row needs only `width`
    /// bytes, so a tightly cropped buffer is accepted.
    pub fn new(data: &'a [u8], width: usize, height: usize, stride: usize) -> Result<Self, ImageViewError> {
        if width == 0 || height == 0 {
            return Err(ImageViewError::Empty { width, height });
        }
        if stride < width {
            return Err(ImageViewError::StrideTooSmall { width, stride });
        }
        let needed = (height - 1)
            .checked_mul(stride)
            .and_then(|n| n.checked_add(width))
            .ok_or(ImageViewError::TooShort { width, height, stride, len: data.len() })?;
        if data.len() < needed {
            return Err(ImageViewError::TooShort { width, height, stride, len: data.len() });
        }
        Ok(Self { data, width, height, stride })
    }

    #[inline]
    pub fn width(&self) -> usize {
        self.width
    }

    #[inline]
    pub fn height(&self) -> usize {
        self.height
    }

    #[inline]
    pub fn stride(&self) -> usize {
        self.stride
    }

    /// The underlying bytes, rows `stride` apart.
    #[inline]
    pub fn data(&self) -> &'a [u8] {
        self.data
    }

    /// Pixel at column `x`, row `y`. Panics when out of bounds, like slice indexing.
    #[inline]
    pub fn get(&self, x: usize, y: usize) -> u8 {
        assert!(x < self.width && y < self.height, "pixel ({x}, {y}) outside {}x{}", self.width, self.height);
        self.data[y * self.stride + x]
    }

    /// The `width` pixels of row `y`.
    #[inline]
    pub fn row(&self, y: usize) -> &'a [u8] {
        let start = y * self.stride;
        &self.data[start..start + self.width]
    }

    /// Copies the pixels into an owned, tightly packed buffer.
    pub fn to_owned(&self) -> ImageBuf {
        let mut data = Vec::with_capacity(self.width * self.height);
        for y in 0..self.height {
            data.extend_from_slice(self.row(y));
        }
        ImageBuf { data, width: self.width, height: self.height }
    }
}

/// An owned, tightly packed (stride = width) 8-bit grayscale image.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ImageBuf {
    pub data: Vec<u8>,
    pub width: usize,
    pub height: usize,
}

impl ImageBuf {
    /// A black image.
    pub fn new(width: usize, height: usize) -> Self {
        Self { data: vec![0; width * height], width, height }
    }

    /// An image filled with `value`.
    pub fn filled(width: usize, height: usize, value: u8) -> Self {
        Self { data: vec![value; width * height], width, height }
    }

    /// Takes ownership of packed pixels; `None` when the length is not `width * height`.
    pub fn from_vec(data: Vec<u8>, width: usize, height: usize) -> Option<Self> {
        (data.len() == width * height && width > 0 && height > 0).then_some(Self { data, width, height })
    }

    /// A borrowed view of this image.
    pub fn view(&self) -> ImageView<'_> {
        ImageView { data: &self.data, width: self.width, height: self.height, stride: self.width }
    }

    #[inline]
    pub fn get(&self, x: usize, y: usize) -> u8 {
        self.data[y * self.width + x]
    }

    #[inline]
    pub fn set(&mut self, x: usize, y: usize, value: u8) {
        self.data[y * self.width + x] = value;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejects_bad_geometry_without_panicking() {
        let bytes = [0u8; 10];
        assert!(matches!(ImageView::new(&bytes, 0, 2, 2), Err(ImageViewError::Empty { .. })));
        assert!(matches!(ImageView::new(&bytes, 3, 2, 2), Err(ImageViewError::StrideTooSmall { .. })));
        assert!(matches!(ImageView::new(&bytes, 4, 3, 4), Err(ImageViewError::TooShort { .. })));
        // Overflowing sizes are a clean error too.
        assert!(matches!(ImageView::new(&bytes, 1, usize::MAX, usize::MAX), Err(ImageViewError::TooShort { .. })));
        // Last row needs only `width` bytes: 3 rows of stride 4 with width 2 fit in 10 bytes.
        assert!(ImageView::new(&bytes, 2, 3, 4).is_ok());
    }

    #[test]
    fn to_owned_drops_row_padding() {
        let bytes = [1u8, 2, 0, 3, 4, 0];
        let img = ImageView::new(&bytes, 2, 2, 3).unwrap().to_owned();
        assert_eq!(img.data, vec![1, 2, 3, 4]);
    }
}
