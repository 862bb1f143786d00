//! `handeye/stereo`: stereo frames in shared memory.
//!
//! One sample carries every camera of one exposure: a [`StereoHeader`] user header and a
//! `[u8]` payload holding `camera_count` images one after the other, each `height` rows of
//! `stride` bytes. [`validate_stereo`] is the one place that decides whether a received sample
//! may be read; [`StereoPublisher`] and [`StereoSubscriber`] are the typed ports.

mod publisher;
mod subscriber;

pub use publisher::{Delivery, PublishError, StereoPublisher, StereoPublisherError, StereoPublisherOptions};
pub use subscriber::{StereoEvent, StereoFrame, StereoStats, StereoSubscriber, StereoSubscriberError, StereoWaitError};

use thiserror::Error;

use crate::types::{PixelFormat, StereoHeader, WIRE_VERSION};

/// Largest accepted image width or height, pixels.
pub const MAX_SIDE_PX: u32 = 16_384;
/// Largest accepted number of cameras in one sample.
pub const MAX_CAMERAS: u32 = 8;
/// Largest accepted payload, bytes (256 MiB).
pub const MAX_PAYLOAD_BYTES: u64 = 256 * 1024 * 1024;

/// The shape of the images a stereo publisher sends. Fixed for the publisher's lifetime: the
/// shared-memory slots are sized for it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StereoFormat {
    pub width: u32,
    pub height: u32,
    /// Bytes from one row to the next, `>= width * bytes_per_pixel`.
    pub stride: u32,
    pub camera_count: u32,
    pub pixel_format: PixelFormat,
}

impl StereoFormat {
    /// Two tightly packed GRAY8 images of `width` x `height` (stride = width).
    pub fn gray8_pair(width: u32, height: u32) -> Self {
        Self { width, height, stride: width, camera_count: 2, pixel_format: PixelFormat::Gray8 }
    }

    /// The header fields this geometry fixes; the publisher fills in ids and times.
    pub fn header(&self) -> StereoHeader {
        StereoHeader {
            version: WIRE_VERSION,
            pixel_format: self.pixel_format as u32,
            width: self.width,
            height: self.height,
            stride: self.stride,
            camera_count: self.camera_count,
            ..StereoHeader::default()
        }
    }

    /// Checks the geometry against the same rules a receiver applies.
    pub fn layout(&self) -> Result<StereoLayout, StereoReject> {
        let h = self.header();
        let len = payload_len_of(&h).ok_or(StereoReject::TooLarge { what: "payload", value: u64::MAX, max: MAX_PAYLOAD_BYTES })?;
        validate_stereo(&h, len as usize)
    }
}

/// What a valid header says about its payload. Every number here has been checked:
/// `plane_len * camera_count == payload_len`, `stride >= row_len`, all within the caps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StereoLayout {
    pub width: usize,
    pub height: usize,
    pub stride: usize,
    pub camera_count: usize,
    pub pixel_format: PixelFormat,
    /// Bytes of pixels in one row (`width * bytes_per_pixel`).
    pub row_len: usize,
    /// Bytes of one camera's image (`stride * height`).
    pub plane_len: usize,
    pub payload_len: usize,
}

/// Why a received stereo sample was rejected. [`StereoReject::key`] names the counter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum StereoReject {
    #[error("version {found}, expected {WIRE_VERSION}")]
    Version { found: u32 },
    #[error("unknown pixel_format {found}")]
    PixelFormat { found: u32 },
    #[error("zero size: width {width}, height {height}, camera_count {camera_count}")]
    ZeroSize { width: u32, height: u32, camera_count: u32 },
    #[error("{what} {value} exceeds the limit {max}")]
    TooLarge { what: &'static str, value: u64, max: u64 },
    #[error("stride {stride} < width {width} x {bytes_per_pixel} bytes per pixel")]
    StrideTooSmall { stride: u32, width: u32, bytes_per_pixel: u32 },
    #[error("payload is {actual} bytes but stride x height x camera_count = {expected}")]
    PayloadLength { expected: u64, actual: u64 },
    #[error("frame_id {found} does not follow {previous} from the same publisher")]
    FrameIdNotIncreasing { previous: u64, found: u64 },
}

impl StereoReject {
    /// All counter keys, in the order of [`StereoReject::index`].
    pub const KEYS: [&'static str; 7] =
        ["version", "pixel_format", "zero_size", "too_large", "stride", "payload_length", "frame_id"];

    /// Stable short name of the reason, used as counter key and in JSON.
    pub fn key(&self) -> &'static str {
        Self::KEYS[self.index()]
    }

    pub fn index(&self) -> usize {
        match self {
            Self::Version { .. } => 0,
            Self::PixelFormat { .. } => 1,
            Self::ZeroSize { .. } => 2,
            Self::TooLarge { .. } => 3,
            Self::StrideTooSmall { .. } => 4,
            Self::PayloadLength { .. } => 5,
            Self::FrameIdNotIncreasing { .. } => 6,
        }
    }
}

/// `stride * height * camera_count` in u64, or `None` on overflow.
fn payload_len_of(h: &StereoHeader) -> Option<u64> {
    (h.stride as u64).checked_mul(h.height as u64)?.checked_mul(h.camera_count as u64)
}

/// Checks a received header against its payload length. The rules, in order:
/// 1. `version == WIRE_VERSION`;
/// 2. `pixel_format` is a known [`PixelFormat`];
/// 3. `width`, `height`, `camera_count` are all non-zero;
/// 4. `width`, `height` <= [`MAX_SIDE_PX`], `camera_count` <= [`MAX_CAMERAS`],
///    `stride * height * camera_count` <= [`MAX_PAYLOAD_BYTES`] (computed without overflow);
/// 5. `stride >= width * bytes_per_pixel`;
/// 6. `stride * height * camera_count == payload_len` exactly.
///
/// Frame-id order is checked by the subscriber, which knows the previous id.
///
/// ```
/// use handeye_wire::stereo::{validate_stereo, StereoFormat, StereoReject};
/// let mut h = StereoFormat::gray8_pair(4, 3).header();
/// assert_eq!(validate_stereo(&h, 24).unwrap().plane_len, 12);
/// assert!(matches!(validate_stereo(&h, 23), Err(StereoReject::PayloadLength { .. })));
/// h.width = 0;
/// assert_eq!(validate_stereo(&h, 24).unwrap_err().key(), "zero_size");
/// ```
pub fn validate_stereo(h: &StereoHeader, payload_len: usize) -> Result<StereoLayout, StereoReject> {
    if h.version != WIRE_VERSION {
        return Err(StereoReject::Version { found: h.version });
    }
    let format = PixelFormat::from_u32(h.pixel_format).ok_or(StereoReject::PixelFormat { found: h.pixel_format })?;
    if h.width == 0 || h.height == 0 || h.camera_count == 0 {
        return Err(StereoReject::ZeroSize { width: h.width, height: h.height, camera_count: h.camera_count });
    }
    let side_max = MAX_SIDE_PX as u64;
    for (what, value, max) in [
        ("width", h.width as u64, side_max),
        ("height", h.height as u64, side_max),
        ("camera_count", h.camera_count as u64, MAX_CAMERAS as u64),
    ] {
        if value > max {
            return Err(StereoReject::TooLarge { what, value, max });
        }
    }
    let expected = match payload_len_of(h) {
        Some(n) if n <= MAX_PAYLOAD_BYTES => n,
        other => {
            return Err(StereoReject::TooLarge { what: "payload", value: other.unwrap_or(u64::MAX), max: MAX_PAYLOAD_BYTES });
        }
    };
    let bpp = format.bytes_per_pixel();
    // width <= 16384 and bpp is tiny, so this cannot overflow u64.
    let row_len = h.width as u64 * bpp as u64;
    if (h.stride as u64) < row_len {
        return Err(StereoReject::StrideTooSmall { stride: h.stride, width: h.width, bytes_per_pixel: bpp });
    }
    if expected != payload_len as u64 {
        return Err(StereoReject::PayloadLength { expected, actual: payload_len as u64 });
    }
    // All values are below 256 MiB here, so the casts are lossless.
    Ok(StereoLayout {
        width: h.width as usize,
        height: h.height as usize,
        stride: h.stride as usize,
        camera_count: h.camera_count as usize,
        pixel_format: format,
        row_len: row_len as usize,
        plane_len: h.stride as usize * h.height as usize,
        payload_len,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn good() -> StereoHeader {
        StereoFormat::gray8_pair(640, 480).header()
    }
    const GOOD_LEN: usize = 640 * 480 * 2;

    #[test]
    fn a_well_formed_pair_is_accepted_with_its_layout() {
        let l = validate_stereo(&good(), GOOD_LEN).unwrap();
        assert_eq!((l.width, l.height, l.stride, l.camera_count), (640, 480, 640, 2));
        assert_eq!((l.row_len, l.plane_len, l.payload_len), (640, 640 * 480, GOOD_LEN));
    }

    #[test]
    fn padded_stride_counts_in_the_payload() {
        let mut h = good();
        h.stride = 704;
        assert!(matches!(validate_stereo(&h, GOOD_LEN), Err(StereoReject::PayloadLength { expected, .. }) if expected == 704 * 480 * 2));
        assert_eq!(validate_stereo(&h, 704 * 480 * 2).unwrap().row_len, 640);
    }

    #[test]
    fn each_rule_rejects_with_its_own_key() {
        let cases: Vec<(StereoHeader, usize, &str)> = vec![
            (StereoHeader { version: WIRE_VERSION + 1, ..good() }, GOOD_LEN, "version"),
            (StereoHeader { version: 0, ..good() }, GOOD_LEN, "version"),
            (StereoHeader { pixel_format: 0, ..good() }, GOOD_LEN, "pixel_format"),
            (StereoHeader { pixel_format: 7, ..good() }, GOOD_LEN, "pixel_format"),
            (StereoHeader { width: 0, ..good() }, GOOD_LEN, "zero_size"),
            (StereoHeader { height: 0, ..good() }, GOOD_LEN, "zero_size"),
            (StereoHeader { camera_count: 0, ..good() }, GOOD_LEN, "zero_size"),
            (StereoHeader { width: MAX_SIDE_PX + 1, stride: MAX_SIDE_PX + 1, ..good() }, GOOD_LEN, "too_large"),
            (StereoHeader { height: MAX_SIDE_PX + 1, ..good() }, GOOD_LEN, "too_large"),
            (StereoHeader { camera_count: MAX_CAMERAS + 1, ..good() }, GOOD_LEN, "too_large"),
            // 16384 x 16384 x 8 cameras = 2 GiB: every side is legal, the total is not.
            (StereoHeader { width: MAX_SIDE_PX, height: MAX_SIDE_PX, stride: MAX_SIDE_PX, camera_count: 8, ..good() }, GOOD_LEN, "too_large"),
            (StereoHeader { stride: 639, ..good() }, 639 * 480 * 2, "stride"),
            (good(), GOOD_LEN - 1, "payload_length"),
            (good(), GOOD_LEN + 1, "payload_length"),
            (good(), 0, "payload_length"),
        ];
        for (h, len, key) in cases {
            let r = validate_stereo(&h, len);
            assert_eq!(r.map_err(|e| e.key()), Err(key), "header {h:?} len {len}");
        }
    }

    #[test]
    fn huge_values_never_overflow() {
        // u32::MAX everywhere must be a clean rejection, not an arithmetic panic.
        let h = StereoHeader { width: u32::MAX, height: u32::MAX, stride: u32::MAX, camera_count: u32::MAX, ..good() };
        assert_eq!(validate_stereo(&h, usize::MAX).unwrap_err().key(), "too_large");
        let h = StereoHeader { width: 1, height: MAX_SIDE_PX, stride: u32::MAX, camera_count: MAX_CAMERAS, ..good() };
        assert_eq!(validate_stereo(&h, usize::MAX).unwrap_err().key(), "too_large");
    }

    #[test]
    fn payload_cap_is_inclusive() {
        // Exactly 256 MiB is allowed: 16384 x 16384 x 1 camera = 256 MiB.
        let h = StereoHeader { width: MAX_SIDE_PX, height: MAX_SIDE_PX, stride: MAX_SIDE_PX, camera_count: 1, ..good() };
        assert!(validate_stereo(&h, MAX_PAYLOAD_BYTES as usize).is_ok());
    }

    #[test]
    fn keys_are_distinct_and_indexed() {
        let mut keys = StereoReject::KEYS.to_vec();
        keys.sort();
        keys.dedup();
        assert_eq!(keys.len(), StereoReject::KEYS.len());
        assert_eq!(StereoReject::FrameIdNotIncreasing { previous: 1, found: 1 }.key(), "frame_id");
    }
}
