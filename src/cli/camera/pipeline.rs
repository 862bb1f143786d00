//! The user's pipeline and what handeye appends to it.
//!
//! The user describes a source in `gst-launch-1.0` syntax up to the point where it gives
//! raw video (`v4l2src device=/dev/video0`, `filesrc location=a.mp4 ! decodebin`, ...);
//! handeye appends the conversion to 8-bit gray at the requested size and its own sink:
//! `USER ! videoconvert ! videoscale ! video/x-raw,format=GRAY8,width=W,height=H ! appsink`.

use std::fmt;

use anyhow::{bail, Result};

/// Which camera a source feeds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Side {
    Left,
    Right,
}

impl fmt::Display for Side {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Side::Left => "left",
            Side::Right => "right",
        })
    }
}

/// The name of the appsink handeye appends, to find it in the parsed pipeline.
pub const SINK_NAME: &str = "handeye_sink";

/// The full pipeline description for the user's `source` part: converted to GRAY8, scaled to
/// exactly `width_px` x `height_px` (the aspect ratio is not kept: choose the camera's own
/// mode in the source part to avoid scaling), into handeye's appsink.
///
/// A trailing `!` is forgiven; an empty description, or one that brings its own appsink, is
/// an error that names the side.
pub fn full_description(side: Side, source: &str, width_px: u32, height_px: u32) -> Result<String> {
    let source = source.trim().trim_end_matches('!').trim_end();
    if source.is_empty() {
        bail!("--{side}: the pipeline is empty; give a source such as 'v4l2src device=/dev/video0' or 'videotestsrc'");
    }
    if source.split(|c: char| c.is_whitespace() || c == '!').any(|word| word == "appsink") {
        bail!("--{side} '{source}': end the pipeline before its sink; handeye appends its own appsink");
    }
    if width_px == 0 || height_px == 0 {
        bail!("--width-px and --height-px must be at least 1 (got {width_px}x{height_px})");
    }
    // No `sync`, `max-buffers` or `drop` here: the source sets them once it knows whether the
    // pipeline is live.
    Ok(format!(
        "{source} ! videoconvert ! videoscale ! video/x-raw,format=GRAY8,width={width_px},height={height_px} \
         ! appsink name={SINK_NAME} emit-signals=false"
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_conversion_and_sink_are_appended() {
        let d = full_description(Side::Left, "videotestsrc pattern=ball", 640, 480).unwrap();
        assert_eq!(
            d,
            "videotestsrc pattern=ball ! videoconvert ! videoscale ! video/x-raw,format=GRAY8,width=640,height=480 \
             ! appsink name=handeye_sink emit-signals=false"
        );
    }

    #[test]
    fn a_trailing_link_is_forgiven() {
        let d = full_description(Side::Right, "  filesrc location=a.mp4 ! decodebin !  ", 32, 24).unwrap();
        assert!(d.starts_with("filesrc location=a.mp4 ! decodebin ! videoconvert"), "{d}");
    }

    #[test]
    fn bad_descriptions_name_the_side() {
        let e = full_description(Side::Right, " ! ", 640, 480).unwrap_err().to_string();
        assert!(e.contains("--right") && e.contains("empty"), "{e}");
        let e = full_description(Side::Left, "videotestsrc ! appsink", 640, 480).unwrap_err().to_string();
        assert!(e.contains("--left") && e.contains("appsink"), "{e}");
        // An element whose name merely contains "appsink" is fine.
        assert!(full_description(Side::Left, "myappsinkish", 640, 480).is_ok());
        assert!(full_description(Side::Left, "videotestsrc", 0, 480).is_err());
    }
}
