//! Capture times: a buffer's timestamp on the pipeline's clock, mapped onto
//! `CLOCK_MONOTONIC`, the clock every time on the wire is read from.
//!
//! A GStreamer buffer's PTS is a position in its segment; the segment turns it into running
//! time, and running time plus the pipeline's base time is the moment on the pipeline clock
//! at which the frame was captured (live sources stamp their buffers so) or is due (a file
//! played at its own rate). Every pipeline here runs on a `GstSystemClock` of type
//! `MONOTONIC`, which reads `clock_gettime(CLOCK_MONOTONIC)` itself, so that moment *is* a
//! CLOCK_MONOTONIC time, with no offset to estimate and no drift between the two clocks;
//! and the two pipelines of a stereo pair stamp on the same clock, so their frames can be
//! paired by time. (GStreamer's default system clock is monotonic too, but that is a
//! build-time default of the library, and the shared default clock can be replaced by any
//! application in the process; asking for the type makes the mapping a property of this
//! code.)

use gstreamer as gst;
use gstreamer::prelude::*;

/// A new system clock that reads CLOCK_MONOTONIC (see the module docs for why).
pub fn monotonic_clock() -> gst::Clock {
    let clock: gst::SystemClock = gst::glib::Object::builder().property("clock-type", gst::ClockType::Monotonic).build();
    clock.upcast()
}

/// How a frame's capture time was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stamp {
    /// From the buffer's timestamp (the normal case).
    Buffer,
    /// The buffer had no usable timestamp: the time it reached handeye instead.
    Arrival,
}

/// The capture time of `sample`'s buffer in CLOCK_MONOTONIC ns, when its timestamp and
/// segment allow one: `base_time + running_time(pts)`.
pub fn capture_time_ns(sample: &gst::Sample, base_time: Option<gst::ClockTime>) -> Option<u64> {
    let pts = sample.buffer()?.pts()?;
    let segment = sample.segment()?.downcast_ref::<gst::ClockTime>()?;
    let running = segment.to_running_time(pts)?;
    Some(base_time?.nseconds() + running.nseconds())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pipeline_clock_reads_clock_monotonic() {
        gst::init().unwrap();
        let clock = monotonic_clock();
        // Sandwich one clock reading between two CLOCK_MONOTONIC readings: with the same
        // clock underneath, it lies between them (a realtime clock would be ~56 years off).
        let before = handeye_wire::monotonic_ns();
        let t = clock.time().nseconds();
        let after = handeye_wire::monotonic_ns();
        assert!(before <= t && t <= after, "{before} <= {t} <= {after}");
    }

    #[test]
    fn capture_time_is_base_time_plus_running_time() {
        gst::init().unwrap();
        let mut buffer = gst::Buffer::with_size(4).unwrap();
        buffer.get_mut().unwrap().set_pts(gst::ClockTime::from_mseconds(1500));
        let mut segment = gst::FormattedSegment::<gst::ClockTime>::new();
        // A segment that starts at 1 s: running time = pts - 1 s.
        segment.set_start(gst::ClockTime::from_seconds(1));
        let sample = gst::Sample::builder().buffer(&buffer).segment(&segment).build();
        let base = gst::ClockTime::from_seconds(100);
        assert_eq!(capture_time_ns(&sample, Some(base)), Some(100_500_000_000));
        assert_eq!(capture_time_ns(&sample, None), None);
        let unstamped = gst::Sample::builder().buffer(&gst::Buffer::with_size(4).unwrap()).segment(&segment).build();
        assert_eq!(capture_time_ns(&unstamped, Some(base)), None);
    }
}
