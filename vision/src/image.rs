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

/// The pixel-wise mean of a few frames of a still scene: sensor noise falls as the square
/// root of their number, so a planner that scales its edge thresholds by the measured noise
/// finds fainter edges, and its result no longer turns on one frame's noise.
///
/// ```
/// use handeye_vision::image::{ImageBuf, ImageMean};
/// let mut mean = ImageMean::default();
/// mean.add(&ImageBuf::filled(2, 1, 10).view()).unwrap();
/// mean.add(&ImageBuf::filled(2, 1, 13).view()).unwrap();
/// assert_eq!(mean.frames(), 2);
/// assert_eq!(mean.mean().unwrap().data, vec![12, 12]); // 11.5 rounds half up
/// ```
#[derive(Debug, Clone, Default)]
pub struct ImageMean {
    sum: Vec<u32>,
    width: usize,
    height: usize,
    frames: u32,
}

/// A frame whose size is not that of the frames already summed.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("a {got_width}x{got_height} frame cannot join the mean of {width}x{height} frames")]
pub struct ImageMeanSizeError {
    pub width: usize,
    pub height: usize,
    pub got_width: usize,
    pub got_height: usize,
}

impl ImageMean {
    /// Adds a frame; the first one sets the size.
    pub fn add(&mut self, img: &ImageView<'_>) -> Result<(), ImageMeanSizeError> {
        if self.frames == 0 {
            self.width = img.width();
            self.height = img.height();
            self.sum.clear();
            self.sum.resize(self.width * self.height, 0);
        } else if (img.width(), img.height()) != (self.width, self.height) {
            return Err(ImageMeanSizeError { width: self.width, height: self.height, got_width: img.width(), got_height: img.height() });
        }
        for y in 0..self.height {
            let row = &mut self.sum[y * self.width..(y + 1) * self.width];
            for (s, &p) in row.iter_mut().zip(img.row(y)) {
                *s += u32::from(p);
            }
        }
        self.frames += 1;
        Ok(())
    }

    /// Whether `img` can join the mean (the first frame always can).
    pub fn fits(&self, img: &ImageView<'_>) -> bool {
        self.frames == 0 || (img.width(), img.height()) == (self.width, self.height)
    }

    /// Frames summed so far.
    pub fn frames(&self) -> u32 {
        self.frames
    }

    /// Starts over.
    pub fn clear(&mut self) {
        self.frames = 0;
    }

    /// The mean frame, rounded to the nearest grey level; `None` before the first frame.
    pub fn mean(&self) -> Option<ImageBuf> {
        if self.frames == 0 {
            return None;
        }
        let n = self.frames;
        let data = self.sum.iter().map(|&s| ((s + n / 2) / n).min(255) as u8).collect();
        ImageBuf::from_vec(data, self.width, self.height)
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

    #[test]
    fn mean_of_frames_rounds_per_pixel_skips_padding_and_refuses_another_size() {
        // Two 2x2 frames with a padding byte per row that must not be summed.
        let a = [0u8, 255, 99, 10, 7, 99];
        let b = [1u8, 255, 0, 20, 8, 0];
        let mut mean = ImageMean::default();
        assert!(mean.mean().is_none());
        mean.add(&ImageView::new(&a, 2, 2, 3).unwrap()).unwrap();
        mean.add(&ImageView::new(&b, 2, 2, 3).unwrap()).unwrap();
        // 0.5 -> 1, 255 stays, 15, 7.5 -> 8.
        assert_eq!(mean.mean().unwrap().data, vec![1, 255, 15, 8]);
        let err = mean.add(&ImageBuf::new(3, 2).view()).unwrap_err();
        assert_eq!((err.width, err.got_width), (2, 3));
        assert_eq!(mean.frames(), 2, "a refused frame is not counted");
        assert!(!mean.fits(&ImageBuf::new(3, 2).view()) && mean.fits(&ImageBuf::new(2, 2).view()));
        mean.clear();
        mean.add(&ImageBuf::new(3, 2).view()).unwrap();
        assert_eq!(mean.mean().unwrap().data, vec![0; 6], "a cleared mean starts over at the new size");
    }
}
