//! Fuzzing the wire's decoders (issue 21): the stereo header and payload, every robot and
//! telemetry message, and `hint.json`. Random bytes and structured mutations of valid
//! inputs; no input may panic or allocate without bound, and every rejection is counted
//! under its reason (the receivers' own counter keys: `StereoReject::key`,
//! `MessageReject::key`; the hint's failing field). See `fuzz_support` for the harness.
//!
//! `make test` runs the short tests; `make fuzz` the `#[ignore]`d `*_long` ones at 10⁶
//! cases per decoder.

// Decoders take `&S::Value` of their proptest strategy (`&String`, `&Vec<u8>`).
#![allow(clippy::ptr_arg)]

mod fuzz_support;

use std::path::Path;

use fuzz_support::mutate::{byte_edits, edit_json, edit_text, node_edit};
use fuzz_support::{assert_coverage, Fuzz, Outcome};
use handeye_vision::image::ImageView;
use handeye_wire::checksum::PixelChecksum;
use handeye_wire::hint::{HintError, OperatorHint};
use handeye_wire::message::WireMessage;
use handeye_wire::stereo::{validate_stereo, StereoFormat, StereoReject};
use handeye_wire::{CommandKind, GripperCommand, Phase, RejectReason, RobotCommand, RobotState, StereoHeader, Telemetry, WIRE_VERSION};
use proptest::prelude::*;

/// A `#[repr(C)]` wire type made only of integers and floats, so that every bit pattern is
/// a value of it (what a receiver finds in shared memory written by anyone).
trait Pod: Copy + 'static {}
impl Pod for StereoHeader {}
impl Pod for RobotState {}
impl Pod for RobotCommand {}
impl Pod for Telemetry {}

fn from_bytes<T: Pod>(b: &[u8]) -> T {
    assert_eq!(b.len(), std::mem::size_of::<T>());
    // SAFETY: `b` holds size_of::<T>() bytes; T is a Pod (integers and floats only, no
    // padding, no invalid bit patterns); the read is unaligned-safe.
    unsafe { std::ptr::read_unaligned(b.as_ptr().cast::<T>()) }
}

fn to_bytes<T: Pod>(v: &T) -> Vec<u8> {
    // SAFETY: T is a Pod without padding: all of its bytes are initialised.
    unsafe { std::slice::from_raw_parts((v as *const T).cast::<u8>(), std::mem::size_of::<T>()) }.to_vec()
}

/// 32-bit words a field is most likely to break on: enum bounds, NaN, infinities, -0,
/// negative numbers, the largest float, a denormal, all ones.
fn interesting_word() -> impl Strategy<Value = u32> {
    prop_oneof![
        prop::sample::select(vec![
            0, 1, 2, 3, 4, 5, 7, 8, 9, 10, 11, 255, 256, 16_384, 16_385, 0x7fc0_0000, 0x7f80_0000, 0xff80_0000, 0x8000_0000, 0xbf80_0000,
            0x3f80_0000, 0x7f7f_ffff, 0x0000_0001, 0x7fff_ffff, u32::MAX,
        ]),
        any::<u32>(),
    ]
}

/// Random bytes of a type's size, or a valid value with up to 4 of its 32-bit words
/// replaced by interesting ones.
fn pod_bytes(valid: Vec<u8>) -> BoxedStrategy<Vec<u8>> {
    let n = valid.len();
    prop_oneof![
        1 => prop::collection::vec(any::<u8>(), n),
        3 => prop::collection::vec((any::<usize>(), interesting_word()), 0..5).prop_map(move |edits| {
            let mut b = valid.clone();
            for (at, w) in edits {
                let off = (at % (n / 4)) * 4;
                b[off..off + 4].copy_from_slice(&w.to_ne_bytes());
            }
            b
        }),
    ]
    .boxed()
}

/// A stereo sample as a receiver sees it: header bytes and the payload's length.
fn stereo_inputs() -> impl Strategy<Value = (Vec<u8>, usize, u8)> {
    let valid = (1u32..700, 1u32..500).prop_flat_map(|(w, h)| pod_bytes(to_bytes(&StereoFormat::gray8_pair(w, h).header())));
    let random = prop::collection::vec(any::<u8>(), std::mem::size_of::<StereoHeader>());
    let header = prop_oneof![1 => random, 4 => valid];
    // The payload length: what the header implies, one off, or anything.
    (header, prop_oneof![3 => Just(None), 1 => any::<usize>().prop_map(Some), 1 => (0usize..3).prop_map(|d| Some(usize::MAX - d))], -1i8..=1, any::<u8>())
        .prop_map(|(b, len, delta, fill)| {
            let h: StereoHeader = from_bytes(&b);
            let implied = (h.stride as usize).saturating_mul(h.height as usize).saturating_mul(h.camera_count as usize);
            (b, len.unwrap_or_else(|| implied.saturating_add_signed(delta as isize)), fill)
        })
}

/// Payloads up to this size are built and read as the daemon reads them.
const PAYLOAD_BUILT_MAX: usize = 1 << 20;

fn decode_stereo((bytes, payload_len, fill): &(Vec<u8>, usize, u8)) -> Outcome {
    let h: StereoHeader = from_bytes(bytes);
    let layout = validate_stereo(&h, *payload_len).map_err(|e: StereoReject| e.key().to_string())?;
    // What an accepted layout promises the subscriber's slicing and the daemon's views.
    assert_eq!(layout.plane_len * layout.camera_count, layout.payload_len, "{layout:?}");
    assert!(layout.row_len <= layout.stride && layout.width * h.pixel_format as usize <= layout.row_len.max(layout.width), "{layout:?}");
    if layout.payload_len <= PAYLOAD_BUILT_MAX {
        let payload: Vec<u8> = (0..layout.payload_len).map(|i| (i as u8).wrapping_mul(31) ^ fill).collect();
        let mut sum = PixelChecksum::new();
        for cam in 0..layout.camera_count {
            // As `StereoFrame::camera` and the daemon (`ImageView::new`) do.
            let start = cam * layout.plane_len;
            let plane = payload.get(start..start + layout.plane_len).expect("plane within the payload");
            let view = ImageView::new(plane, layout.width, layout.height, layout.stride).expect("an accepted GRAY8 plane is a view");
            let _ = (view.get(0, 0), view.get(layout.width - 1, layout.height - 1));
            sum.add_image(plane, layout.row_len, layout.height, layout.stride);
        }
        let _ = sum.value();
    }
    Ok(())
}

fn stereo_alloc_bound(_: &(Vec<u8>, usize, u8)) -> usize {
    PAYLOAD_BUILT_MAX
}

const STEREO_KEYS: [&str; 6] = ["version", "pixel_format", "zero_size", "too_large", "stride", "payload_length"];

#[test]
fn stereo_header_and_payload() {
    let counts = Fuzz::short("stereo", 10_000).run(stereo_inputs(), stereo_alloc_bound, decode_stereo);
    assert_coverage("stereo", &counts, &STEREO_KEYS);
}

#[test]
#[ignore = "long fuzz run: make fuzz"]
fn stereo_header_and_payload_long() {
    Fuzz::long("stereo").run(stereo_inputs(), stereo_alloc_bound, decode_stereo);
}

/// A message as a receiver decodes it, and what consumers then do with an accepted one.
fn decode_message<T: WireMessage + Pod>(bytes: &[u8], consume: impl Fn(&T)) -> Outcome {
    let m: T = from_bytes(bytes);
    m.validate().map_err(|e| e.key().to_string())?;
    consume(&m);
    Ok(())
}

fn robot_state(b: &Vec<u8>) -> Outcome {
    decode_message::<RobotState>(b, |s| {
        let _ = RejectReason::from_u32(s.reject).expect("a validated reject code is known").text();
        let _ = RejectReason::text_of(s.fault);
    })
}

fn robot_command(b: &Vec<u8>) -> Outcome {
    decode_message::<RobotCommand>(b, |c| {
        CommandKind::from_u32(c.kind).expect("a validated kind is known");
        GripperCommand::from_u32(c.gripper).expect("a validated gripper command is known");
    })
}

fn telemetry(b: &Vec<u8>) -> Outcome {
    decode_message::<Telemetry>(b, |t| {
        let _ = Phase::from_u32(t.phase).expect("a validated phase is known").name();
        let _ = t.reason_text();
    })
}

const MESSAGE_KEYS: [&str; 4] = ["version", "enum", "non_finite", "range"];
/// Decoding a message copies it out; consumers allocate only the reason text.
const MESSAGE_ALLOC_BOUND: usize = 4096;

fn valid_state() -> Vec<u8> {
    to_bytes(&RobotState { version: WIRE_VERSION, ..Default::default() })
}

fn valid_command() -> Vec<u8> {
    to_bytes(&RobotCommand { version: WIRE_VERSION, ..Default::default() })
}

#[test]
fn robot_state_message() {
    let counts = Fuzz::short("robot_state", 10_000).run(pod_bytes(valid_state()), |_| MESSAGE_ALLOC_BOUND, robot_state);
    assert_coverage("robot_state", &counts, &MESSAGE_KEYS);
}

#[test]
fn robot_command_message() {
    let counts = Fuzz::short("robot_command", 10_000).run(pod_bytes(valid_command()), |_| MESSAGE_ALLOC_BOUND, robot_command);
    assert_coverage("robot_command", &counts, &["version", "enum", "non_finite"]);
}

#[test]
fn telemetry_message() {
    let counts = Fuzz::short("telemetry", 10_000).run(pod_bytes(to_bytes(&Telemetry::default())), |_| MESSAGE_ALLOC_BOUND, telemetry);
    assert_coverage("telemetry", &counts, &MESSAGE_KEYS);
}

#[test]
#[ignore = "long fuzz run: make fuzz"]
fn robot_messages_long() {
    Fuzz::long("robot_state").run(pod_bytes(valid_state()), |_| MESSAGE_ALLOC_BOUND, robot_state);
    Fuzz::long("robot_command").run(pod_bytes(valid_command()), |_| MESSAGE_ALLOC_BOUND, robot_command);
    Fuzz::long("telemetry").run(pod_bytes(to_bytes(&Telemetry::default())), |_| MESSAGE_ALLOC_BOUND, telemetry);
}

/// A valid hint as the simulator writes one.
const HINT: &str = r#"{"version":1,"left_px":[[338.4,378.1],[375.0,364.1],[374.2,401.7],[338.2,416.0]],"right_px":[[323.7,380.4],[367.5,374.2],[367.0,411.8],[323.8,418.4]],"depth_mm":40.25,"note":"fuzz"}"#;

/// JSON text where a number or token breaks: beyond f64, NaN, a bare minus, deep nesting.
const JSON_RAW: &[&str] = &["1e999", "-1e999", "NaN", "-", "18446744073709551616", "-0", "0x10", "1.", ".5", "\"\\ud800\"", "[", "}", "nul", "\"\u{0}\""];

/// Random text, JSON-token soup, or the valid hint with a tree edit and byte edits.
fn hint_inputs() -> impl Strategy<Value = String> {
    let base: serde_json::Value = serde_json::from_str(HINT).expect("HINT is JSON");
    let tokens = prop::collection::vec(
        prop::sample::select(vec!["{", "}", "[", "]", ",", ":", "\"version\"", "\"left_px\"", "\"right_px\"", "\"depth_mm\"", "\"note\"", "1", "0", "-3.5", "1e400", "null", "\"x\""]),
        0..60,
    )
    .prop_map(|t| t.concat());
    let base2 = base.clone();
    let tree = (any::<usize>(), node_edit(JSON_RAW)).prop_map(move |(pick, edit)| edit_json(&base, pick, &edit));
    let tree_and_bytes = (any::<usize>(), node_edit(JSON_RAW), byte_edits(2)).prop_map(move |(pick, edit, bytes)| edit_text(&edit_json(&base2, pick, &edit), &bytes));
    prop_oneof![
        1 => prop::collection::vec(any::<u8>(), 0..300).prop_map(|b| String::from_utf8_lossy(&b).into_owned()),
        1 => tokens,
        4 => tree,
        2 => tree_and_bytes,
    ]
}

fn decode_hint(text: &String) -> Outcome {
    match OperatorHint::parse(text, Path::new("hint.json")) {
        Ok(h) => {
            // What the daemon relies on once a hint is read.
            assert!((3..=8).contains(&h.left_px.len()) && h.left_px.len() == h.right_px.len(), "{h:?}");
            assert!(h.left_px.iter().chain(&h.right_px).flatten().all(|v| v.is_finite()) && h.depth_mm > 0.0, "{h:?}");
            Ok(())
        }
        Err(HintError::Parse { .. }) => Err("parse".into()),
        Err(HintError::Invalid { field, .. }) => Err(field.into()),
        Err(HintError::Read { .. }) => Err("read".into()),
    }
}

/// serde_json builds the document: a bounded multiple of the text's length.
fn hint_alloc_bound(text: &String) -> usize {
    64 * 1024 + 64 * text.len()
}

#[test]
fn hint_json() {
    let counts = Fuzz::short("hint_json", 5000).run(hint_inputs(), hint_alloc_bound, decode_hint);
    assert_coverage("hint_json", &counts, &["parse", "version", "left_px", "right_px", "depth_mm"]);
}

#[test]
#[ignore = "long fuzz run: make fuzz"]
fn hint_json_long() {
    Fuzz::long("hint_json").run(hint_inputs(), hint_alloc_bound, decode_hint);
}

/// The harness itself: a decoder that panics on some input is reported with that input...
#[test]
#[should_panic(expected = "the decoder panicked (byte 0 is 7)")]
fn the_harness_reports_a_panic_with_its_input() {
    Fuzz::short("self_test_panic", 2000).run(prop::collection::vec(any::<u8>(), 1..4), |_| 1 << 20, |b: &Vec<u8>| {
        assert!(b[0] != 7, "byte 0 is 7");
        Ok(())
    });
}

/// ... and one that allocates more than its bound for an input is caught.
#[test]
#[should_panic(expected = "an allocation of")]
fn the_harness_catches_an_allocation_over_the_bound() {
    Fuzz::short("self_test_alloc", 2000).run(any::<u8>(), |_| 1 << 20, |&n: &u8| {
        let v: Vec<u8> = Vec::with_capacity(usize::from(n) << 16);
        std::hint::black_box(v);
        Ok(())
    });
}
