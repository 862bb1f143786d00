//! Reading PNG files as 8-bit grey, for every command that takes images (`feed --dir`,
//! `plan`, `hint`, `track`, `bench tracker`). Any bit depth and colour type is converted to
//! grey; what cannot be an image of ours is refused with a reason before anything large is
//! allocated: a side over [`MAX_SIDE_PX`] (the wire's own limit), or a declared size that the
//! file's bytes could not hold even at deflate's best ratio.
//!
//! This module depends only on `image` and `std`, so that the fuzz test
//! (`tests/fuzz_png.rs`) compiles this very file into itself and feeds it bytes.

use std::fmt;
use std::io::{BufReader, Cursor};
use std::path::{Path, PathBuf};

use image::{GrayImage, ImageFormat, ImageReader, Limits};

/// Largest width or height accepted, pixels: the largest the stereo wire carries
/// (`handeye_wire::stereo::MAX_SIDE_PX`).
pub const MAX_SIDE_PX: u32 = 16_384;
/// Most bytes the decoder may allocate for one image (a 16384 x 16384 grey image; RGBA at
/// that size is refused).
pub const MAX_DECODE_BYTES: u64 = 256 * 1024 * 1024;
/// Deflate's largest compression ratio (a 258-byte match in about 2 bits): no valid PNG
/// holds more raw image bytes than this many times its own length.
const DEFLATE_MAX_RATIO: u64 = 1032;

/// Why bytes are not an image we can use. [`PngReject::key`] names the counter.
#[derive(Debug)]
pub enum PngReject {
    /// The file could not be read.
    Read(std::io::Error),
    /// The bytes do not start with the PNG signature.
    NotPng,
    /// The header (IHDR) is missing, truncated or invalid (bit depth, colour type, zero size).
    Header(String),
    /// A declared side over [`MAX_SIDE_PX`], or more image than the file can hold.
    TooLarge { width: u32, height: u32, why: &'static str },
    /// The image data is truncated or corrupt.
    Decode(String),
}

// The binary reports rejections in words; the fuzz test counts them by key.
#[allow(dead_code)]
impl PngReject {
    /// Every counter key, in the order of [`PngReject::index`].
    pub const KEYS: [&'static str; 5] = ["read", "not_png", "header", "too_large", "decode"];

    pub fn key(&self) -> &'static str {
        Self::KEYS[self.index()]
    }

    pub fn index(&self) -> usize {
        match self {
            Self::Read(_) => 0,
            Self::NotPng => 1,
            Self::Header(_) => 2,
            Self::TooLarge { .. } => 3,
            Self::Decode(_) => 4,
        }
    }
}

impl fmt::Display for PngReject {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Read(e) => write!(f, "cannot read: {e}"),
            Self::NotPng => write!(f, "not a PNG file (no PNG signature)"),
            Self::Header(m) => write!(f, "not a readable PNG header: {m}"),
            Self::TooLarge { width, height, why } => write!(f, "declares {width}x{height} pixels: {why}"),
            Self::Decode(m) => write!(f, "truncated or corrupt PNG data: {m}"),
        }
    }
}

impl std::error::Error for PngReject {}

/// A PNG file that could not be used: the file and why.
#[derive(Debug)]
pub struct PngError {
    pub file: PathBuf,
    pub reject: PngReject,
}

impl fmt::Display for PngError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.file.display(), self.reject)
    }
}

impl std::error::Error for PngError {}

/// Decodes PNG bytes to 8-bit grey (colour by luma, 16 bits to 8, alpha dropped).
pub fn decode_gray(bytes: &[u8]) -> Result<GrayImage, PngReject> {
    const SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a];
    if !bytes.starts_with(&SIGNATURE) {
        return Err(PngReject::NotPng);
    }
    let reader = || ImageReader::with_format(Cursor::new(bytes), ImageFormat::Png);
    let (width, height) = reader().into_dimensions().map_err(|e| match e {
        // The PNG decoder's own memory limit, hit by a huge declared size.
        image::ImageError::Limits(l) => {
            let (width, height) = declared_size(bytes).unwrap_or_default();
            PngReject::TooLarge { width, height, why: limit_text(&l) }
        }
        other => PngReject::Header(other.to_string()),
    })?;
    check_size(width, height, raw_bits_per_pixel(bytes), bytes.len() as u64)?;
    let mut decoder = reader();
    let mut limits = Limits::default();
    limits.max_image_width = Some(MAX_SIDE_PX);
    limits.max_image_height = Some(MAX_SIDE_PX);
    limits.max_alloc = Some(MAX_DECODE_BYTES);
    decoder.limits(limits);
    let img = decoder.decode().map_err(|e| match e {
        image::ImageError::Limits(l) => PngReject::TooLarge { width, height, why: limit_text(&l) },
        other => PngReject::Decode(other.to_string()),
    })?;
    Ok(match img {
        image::DynamicImage::ImageLuma8(g) => g,
        other => other.to_luma8(),
    })
}

fn limit_text(l: &image::error::LimitError) -> &'static str {
    match l.kind() {
        image::error::LimitErrorKind::DimensionError => "a side exceeds 16384 pixels",
        _ => "decoding it would need more than 256 MiB",
    }
}

/// Refuses sizes no image of ours has, or that `file_len` bytes cannot hold.
fn check_size(width: u32, height: u32, bits_per_pixel: Option<u64>, file_len: u64) -> Result<(), PngReject> {
    if width > MAX_SIDE_PX || height > MAX_SIDE_PX {
        return Err(PngReject::TooLarge { width, height, why: "a side exceeds 16384 pixels" });
    }
    // Raw (filtered) data: one filter byte per row, then the row's bits rounded up to bytes.
    let bits = bits_per_pixel.unwrap_or(1);
    let raw = (width as u64 * bits).div_ceil(8).saturating_add(1).saturating_mul(height as u64);
    if raw > file_len.saturating_mul(DEFLATE_MAX_RATIO) {
        return Err(PngReject::TooLarge { width, height, why: "more image data than the file can hold (truncated or forged header)" });
    }
    Ok(())
}

/// Width and height as the IHDR chunk declares them, if it is there.
fn declared_size(bytes: &[u8]) -> Option<(u32, u32)> {
    let ihdr = bytes.get(8..8 + 8 + 13)?;
    let word = |at: usize| u32::from_be_bytes([ihdr[at], ihdr[at + 1], ihdr[at + 2], ihdr[at + 3]]);
    (&ihdr[4..8] == b"IHDR").then(|| (word(8), word(12)))
}

/// Bits per pixel of the raw data from the IHDR chunk (right after the signature), if it is
/// there and valid.
fn raw_bits_per_pixel(bytes: &[u8]) -> Option<u64> {
    let ihdr = bytes.get(8..8 + 8 + 13)?;
    if &ihdr[4..8] != b"IHDR" {
        return None;
    }
    let (depth, colour) = (ihdr[16] as u64, ihdr[17]);
    let channels = match colour {
        0 | 3 => 1,
        2 => 3,
        4 => 2,
        6 => 4,
        _ => return None,
    };
    Some(channels * depth)
}

/// Reads and decodes a PNG file as 8-bit grey.
pub fn read_gray(path: &Path) -> Result<GrayImage, PngError> {
    let err = |reject| PngError { file: path.to_path_buf(), reject };
    let bytes = std::fs::read(path).map_err(|e| err(PngReject::Read(e)))?;
    decode_gray(&bytes).map_err(err)
}

/// A PNG file's width and height from its header alone (nothing decoded), checked against
/// [`MAX_SIDE_PX`].
pub fn read_size(path: &Path) -> Result<(u32, u32), PngError> {
    let err = |reject| PngError { file: path.to_path_buf(), reject };
    let file = std::fs::File::open(path).map_err(|e| err(PngReject::Read(e)))?;
    let len = file.metadata().map(|m| m.len()).unwrap_or(u64::MAX);
    let mut head = Vec::with_capacity(29);
    use std::io::Read;
    BufReader::new(&file).take(29).read_to_end(&mut head).map_err(|e| err(PngReject::Read(e)))?;
    if !head.starts_with(&[0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a]) {
        return Err(err(PngReject::NotPng));
    }
    let file = std::fs::File::open(path).map_err(|e| err(PngReject::Read(e)))?;
    let (w, h) = ImageReader::with_format(BufReader::new(file), ImageFormat::Png).into_dimensions().map_err(|e| err(PngReject::Header(e.to_string())))?;
    check_size(w, h, raw_bits_per_pixel(&head), len).map_err(err)?;
    Ok((w, h))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A valid grey PNG of `w` x `h`, then its IHDR width and height replaced (CRC fixed).
    fn forged(w: u32, h: u32, declared: (u32, u32)) -> Vec<u8> {
        let mut bytes = Vec::new();
        image::codecs::png::PngEncoder::new(&mut bytes)
            .write_image(&vec![7u8; (w * h) as usize], w, h, image::ExtendedColorType::L8)
            .unwrap();
        bytes[16..20].copy_from_slice(&declared.0.to_be_bytes());
        bytes[20..24].copy_from_slice(&declared.1.to_be_bytes());
        let crc = crc32fast::hash(&bytes[12..29]);
        bytes[29..33].copy_from_slice(&crc.to_be_bytes());
        bytes
    }

    use image::ImageEncoder;

    #[test]
    fn grey_and_colour_decode_to_grey() {
        let g = decode_gray(&forged(3, 2, (3, 2))).unwrap();
        assert_eq!((g.width(), g.height(), g.as_raw().clone()), (3, 2, vec![7; 6]));
        // Pure white in 8-bit RGB and in 16-bit grey: both 255 after conversion.
        for (pixels, colour) in [(vec![255u8; 3], image::ExtendedColorType::Rgb8), (vec![255u8; 2], image::ExtendedColorType::L16)] {
            let mut bytes = Vec::new();
            image::codecs::png::PngEncoder::new(&mut bytes).write_image(&pixels, 1, 1, colour).unwrap();
            assert_eq!(decode_gray(&bytes).unwrap().as_raw(), &vec![255], "{colour:?}");
        }
    }

    #[test]
    fn a_huge_declared_size_is_refused_before_decoding() {
        // Sides over the limit, and within it but far more than 80 bytes can hold.
        for (declared, why) in [((100_000, 10), "16384"), ((16_384, 16_384), "file can hold")] {
            let err = decode_gray(&forged(2, 2, declared)).unwrap_err();
            assert_eq!(err.key(), "too_large", "{err}");
            assert!(err.to_string().contains(why), "{err}");
        }
    }

    #[test]
    fn truncated_and_foreign_bytes_have_reasons() {
        let good = forged(8, 8, (8, 8));
        assert_eq!(decode_gray(&good[..good.len() - 20]).unwrap_err().key(), "decode");
        assert_eq!(decode_gray(&good[..20]).unwrap_err().key(), "header");
        assert_eq!(decode_gray(b"GIF89a").unwrap_err().key(), "not_png");
        assert_eq!(decode_gray(&[]).unwrap_err().key(), "not_png");
    }
}
