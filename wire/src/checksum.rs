//! An order-sensitive checksum of pixel bytes, so a receiver can prove it got exactly the
//! frames a sender had: `handeye monitor --checksum` and the tests compute the same value, the
//! monitor from shared memory, the tests from the image files.

/// 64-bit FNV-1a over pixel bytes: `width * bytes_per_pixel` bytes per row (stride padding is
/// skipped), rows top to bottom, cameras in order (left then right), frames in order.
///
/// ```
/// use handeye_wire::checksum::PixelChecksum;
/// let mut a = PixelChecksum::new();
/// a.add_image(&[1, 2, 99, 3, 4, 99], 2, 2, 3); // 2x2 image, one padding byte per row
/// let mut b = PixelChecksum::new();
/// b.add_image(&[1, 2, 3, 4], 2, 2, 2);          // the same pixels, tightly packed
/// assert_eq!(a.value(), b.value());
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PixelChecksum {
    state: u64,
}

const FNV_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
const FNV_PRIME: u64 = 0x0000_0100_0000_01b3;

impl Default for PixelChecksum {
    fn default() -> Self {
        Self::new()
    }
}

impl PixelChecksum {
    pub fn new() -> Self {
        Self { state: FNV_OFFSET }
    }

    /// Adds raw bytes in order.
    #[inline]
    pub fn add_bytes(&mut self, bytes: &[u8]) {
        let mut h = self.state;
        for &b in bytes {
            h ^= b as u64;
            h = h.wrapping_mul(FNV_PRIME);
        }
        self.state = h;
    }

    /// Adds one image of `height` rows, `stride` bytes apart, of which the first `row_len`
    /// bytes are pixels. Panics if `data` is too short (callers pass validated layouts).
    pub fn add_image(&mut self, data: &[u8], row_len: usize, height: usize, stride: usize) {
        for y in 0..height {
            self.add_bytes(&data[y * stride..y * stride + row_len]);
        }
    }

    /// Adds every camera of a received frame, in order.
    pub fn add_frame(&mut self, frame: &crate::stereo::StereoFrame) {
        let l = frame.layout();
        for cam in 0..l.camera_count {
            if let Some(plane) = frame.camera(cam) {
                self.add_image(plane, l.row_len, l.height, l.stride);
            }
        }
    }

    pub fn value(&self) -> u64 {
        self.state
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_published_fnv1a_vectors() {
        // Reference values of 64-bit FNV-1a (Fowler/Noll/Vo test suite).
        let h = |s: &[u8]| {
            let mut c = PixelChecksum::new();
            c.add_bytes(s);
            c.value()
        };
        assert_eq!(h(b""), 0xcbf29ce484222325);
        assert_eq!(h(b"a"), 0xaf63dc4c8601ec8c);
        assert_eq!(h(b"foobar"), 0x85944171f73967e8);
    }

    #[test]
    fn order_matters() {
        let mut a = PixelChecksum::new();
        a.add_bytes(&[1, 2]);
        let mut b = PixelChecksum::new();
        b.add_bytes(&[2, 1]);
        assert_ne!(a.value(), b.value());
    }

    #[test]
    fn stride_padding_is_ignored() {
        let mut a = PixelChecksum::new();
        a.add_image(&[1, 2, 7, 7, 3, 4, 8, 8], 2, 2, 4);
        let mut b = PixelChecksum::new();
        b.add_bytes(&[1, 2, 3, 4]);
        assert_eq!(a.value(), b.value());
    }
}
