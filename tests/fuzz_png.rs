//! Fuzzing the PNG reader every image-taking command uses (`src/cli/png.rs`: `feed --dir`,
//! `plan`, `hint`, `track`), compiled into this test from its source file (the CLI is a
//! binary crate). Inputs: random bytes (with and without the PNG signature), PNGs built
//! from fuzzed parts with valid checksums (any width and height up to `u32::MAX`, every
//! bit depth and colour type and invalid ones, interlaced or not, palettes, transparency,
//! image data exact, cut short or random, any row filter), and those with byte edits.
//! No input may panic; a huge declared size must be refused before it is allocated (the
//! largest allocation is bounded by the input's length); every refusal has its reason.
//!
//! `make test` runs the short test; `make fuzz` the `#[ignore]`d long one.

// Decoders take `&S::Value` of their proptest strategy (`&String`, `&Vec<u8>`).
#![allow(clippy::ptr_arg)]

mod fuzz_support;

#[path = "../src/cli/png.rs"]
#[allow(dead_code)]
mod png;

use fuzz_support::mutate::{apply_bytes, byte_edits, ByteEdit};
use fuzz_support::{assert_coverage, Fuzz, Outcome};
use proptest::prelude::*;

/// A PNG file described by its parts.
#[derive(Debug, Clone)]
struct PngSpec {
    width: u32,
    height: u32,
    depth: u8,
    colour: u8,
    interlace: u8,
    /// Palette entries (PLTE), if any.
    palette: Option<usize>,
    /// A transparency chunk (tRNS) of this many bytes, if any.
    trns: Option<usize>,
    data: Data,
    /// Filter byte of every row (0..=4 are valid).
    filter: u8,
    /// Split the image data over this many IDAT chunks.
    idat_chunks: usize,
    edits: Vec<ByteEdit>,
}

#[derive(Debug, Clone)]
enum Data {
    /// The exact raw data the header declares (when small enough), stored in zlib.
    Exact,
    /// That, cut to this fraction (per mille) of its length.
    Cut(u16),
    /// Random bytes (not a zlib stream).
    Random(Vec<u8>),
}

fn side() -> impl Strategy<Value = u32> {
    prop_oneof![
        8 => 1u32..48,
        1 => prop::sample::select(vec![0u32, 1, 16_384, 16_385, 65_535, 1 << 31, u32::MAX]),
        1 => any::<u32>(),
    ]
}

fn spec() -> impl Strategy<Value = PngSpec> {
    (
        (side(), side()),
        prop_oneof![9 => (0usize..5).prop_map(Depth::Valid), 1 => any::<u8>().prop_map(Depth::Any)],
        prop_oneof![9 => prop::sample::select(vec![0u8, 2, 3, 4, 6]), 1 => any::<u8>()],
        prop_oneof![6 => Just(0u8), 3 => Just(1u8), 1 => any::<u8>()],
        prop_oneof![3 => Just(None), 1 => (prop::option::of(0usize..300), prop::option::of(0usize..300)).prop_map(Some)],
        prop_oneof![5 => Just(Data::Exact), 2 => (0u16..1000).prop_map(Data::Cut), 1 => prop::collection::vec(any::<u8>(), 0..200).prop_map(Data::Random)],
        prop_oneof![6 => 0u8..5, 1 => any::<u8>()],
        1usize..4,
        prop_oneof![3 => Just(vec![]), 1 => byte_edits(3)],
    )
        .prop_map(|((width, height), depth, colour, interlace, extras, data, filter, idat_chunks, edits)| {
            // The depths valid for the colour type, or any byte.
            let valid: &[u8] = match colour {
                0 => &[1, 2, 4, 8, 16],
                3 => &[1, 2, 4, 8],
                _ => &[8, 16],
            };
            let depth = match depth {
                Depth::Valid(i) => valid[i % valid.len()],
                Depth::Any(d) => d,
            };
            // The chunks the colour type needs (a palette for type 3), or fuzzed ones.
            let (palette, trns) = extras.unwrap_or((if colour == 3 { Some(16) } else { None }, None));
            PngSpec {
            width,
            height,
            depth,
            colour,
            interlace,
            palette,
            trns,
            data,
            filter,
            idat_chunks,
            edits,
        }
        })
}

#[derive(Debug, Clone)]
enum Depth {
    Valid(usize),
    Any(u8),
}

fn chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
    out.extend_from_slice(&(data.len() as u32).to_be_bytes());
    let start = out.len();
    out.extend_from_slice(kind);
    out.extend_from_slice(data);
    let crc = crc32fast::hash(&out[start..]);
    out.extend_from_slice(&crc.to_be_bytes());
}

/// zlib stream of stored (uncompressed) deflate blocks.
fn zlib_stored(data: &[u8]) -> Vec<u8> {
    let mut out = vec![0x78, 0x01];
    let blocks: Vec<&[u8]> = if data.is_empty() { vec![&[][..]] } else { data.chunks(65_535).collect() };
    for (i, b) in blocks.iter().enumerate() {
        out.push(u8::from(i + 1 == blocks.len()));
        out.extend_from_slice(&(b.len() as u16).to_le_bytes());
        out.extend_from_slice(&(!(b.len() as u16)).to_le_bytes());
        out.extend_from_slice(b);
    }
    let (mut a, mut b) = (1u32, 0u32);
    for &x in data {
        a = (a + x as u32) % 65_521;
        b = (b + a) % 65_521;
    }
    out.extend_from_slice(&((b << 16) | a).to_be_bytes());
    out
}

/// Raw (filtered) row lengths the header declares, filter byte included: one per row, per
/// Adam7 pass when interlaced; `None` when that is more than `max` bytes.
fn raw_rows(s: &PngSpec, max: u64) -> Option<Vec<u64>> {
    let channels = match s.colour {
        2 => 3,
        4 => 2,
        6 => 4,
        _ => 1,
    };
    let bits = channels * s.depth as u64;
    let row = |w: u64| 1 + w.saturating_mul(bits).div_ceil(8);
    let (w, h) = (s.width as u64, s.height as u64);
    let passes: &[(u64, u64, u64, u64)] =
        if s.interlace == 1 { &[(0, 0, 8, 8), (4, 0, 8, 8), (0, 4, 4, 8), (2, 0, 4, 4), (0, 2, 2, 4), (1, 0, 2, 2), (0, 1, 1, 2)] } else { &[(0, 0, 1, 1)] };
    let mut rows = Vec::new();
    let mut total = 0u64;
    for &(x0, y0, dx, dy) in passes {
        let pw = if w > x0 { (w - x0).div_ceil(dx) } else { 0 };
        let ph = if h > y0 { (h - y0).div_ceil(dy) } else { 0 };
        if pw == 0 {
            continue;
        }
        total = total.saturating_add(row(pw).saturating_mul(ph));
        if total > max {
            return None;
        }
        rows.extend(std::iter::repeat_n(row(pw), ph as usize));
    }
    Some(rows)
}

/// Raw image data is built only up to this size; larger declared images get random data.
const EXACT_MAX: u64 = 256 * 1024;


fn build(s: &PngSpec) -> Vec<u8> {
    let mut out = vec![0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a];
    let mut ihdr = Vec::with_capacity(13);
    ihdr.extend_from_slice(&s.width.to_be_bytes());
    ihdr.extend_from_slice(&s.height.to_be_bytes());
    ihdr.extend_from_slice(&[s.depth, s.colour, 0, 0, s.interlace]);
    chunk(&mut out, b"IHDR", &ihdr);
    if let Some(n) = s.palette {
        let plte: Vec<u8> = (0..n * 3).map(|i| (i * 37) as u8).collect();
        chunk(&mut out, b"PLTE", &plte);
    }
    if let Some(n) = s.trns {
        chunk(&mut out, b"tRNS", &vec![0x80; n]);
    }
    let rows = raw_rows(s, EXACT_MAX);
    let idat = match (&s.data, rows) {
        (Data::Random(b), _) => b.clone(),
        (_, None) => vec![0x78, 0x01, 0x01, 0x00, 0x00, 0xff, 0xff],
        (data, Some(rows)) => {
            // Each row: the filter byte, then pixel bytes.
            let mut raw = Vec::new();
            for len in rows {
                raw.push(s.filter);
                raw.extend((1..len).map(|i| (i as u8).wrapping_mul(13)));
            }
            let mut z = zlib_stored(&raw);
            if let Data::Cut(per_mille) = data {
                z.truncate(z.len() * *per_mille as usize / 1000);
            }
            z
        }
    };
    let per = idat.len().div_ceil(s.idat_chunks).max(1);
    for part in idat.chunks(per) {
        chunk(&mut out, b"IDAT", part);
    }
    if idat.is_empty() {
        chunk(&mut out, b"IDAT", &[]);
    }
    chunk(&mut out, b"IEND", &[]);
    apply_bytes(&mut out, &s.edits);
    out
}

fn inputs() -> impl Strategy<Value = Vec<u8>> {
    let random = prop::collection::vec(any::<u8>(), 0..600);
    let signed = prop::collection::vec(any::<u8>(), 0..600).prop_map(|mut b| {
        b.splice(0..0, [0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a]);
        b
    });
    prop_oneof![1 => random, 1 => signed, 8 => spec().prop_map(|s| build(&s))]
}

fn decode(bytes: &Vec<u8>) -> Outcome {
    let img = png::decode_gray(bytes).map_err(|e| e.key().to_string())?;
    assert!(img.width() <= png::MAX_SIDE_PX && img.height() <= png::MAX_SIDE_PX && img.width() > 0 && img.height() > 0, "{}x{}", img.width(), img.height());
    assert_eq!(img.as_raw().len(), img.width() as usize * img.height() as usize);
    Ok(())
}

/// Deflate holds at most 1032 raw bytes per input byte, a decoded pixel is at most 32 times
/// its raw bits (1-bit palette to RGBA8), and the grey copy is smaller still.
fn alloc_bound(bytes: &Vec<u8>) -> usize {
    (2 << 20) + 33 * 1032 * bytes.len()
}

#[test]
fn png_input() {
    let counts = Fuzz::short("png", 5000).run(inputs(), alloc_bound, decode);
    assert_coverage("png", &counts, &["not_png", "header", "too_large", "decode"]);
}

#[test]
#[ignore = "long fuzz run: make fuzz"]
fn png_input_long() {
    Fuzz::long("png").run(inputs(), alloc_bound, decode);
}
