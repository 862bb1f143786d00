//! `handeye camera`: publishes real cameras (any GStreamer source) on `handeye/stereo`.
//!
//! `pipeline` builds each side's pipeline from the user's source part, `source` runs it and
//! hands over its frames and its end, `clock` maps buffer times onto CLOCK_MONOTONIC,
//! `pairing` pairs left and right frames by capture time, `start` sets up and `capture`
//! is the loop that publishes, `summary` counts and reports, and `args` holds the flags and the help.

mod args;
mod capture;
mod clock;
mod pairing;
mod pipeline;
mod source;
mod start;
mod summary;

use anyhow::{bail, Result};

pub use args::CameraArgs;

pub fn run(args: CameraArgs) -> Result<()> {
    if !(args.max_skew_ms.is_finite() && args.max_skew_ms >= 0.0) {
        bail!("--max-skew-ms must be a number >= 0 (got {})", args.max_skew_ms);
    }
    start::run(&args)
}
