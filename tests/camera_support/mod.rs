//! Helpers of the `handeye camera` tests (`tests/camera_*.rs`): a real H.264 video made from
//! the camera frames of `visp-cube`, and GStreamer's own decoding of it, independent of
//! `handeye camera`.
#![allow(dead_code)]

use std::path::Path;
use std::time::Duration;

use gstreamer as gst;
use gstreamer::prelude::*;
use gstreamer_app as gst_app;
use gstreamer_video as gst_video;
use gstreamer_video::prelude::*;
use handeye_wire::checksum::PixelChecksum;

/// Runs a `gst-launch-1.0` style pipeline to its end; panics with GStreamer's error.
pub fn run_to_eos(description: &str, timeout: Duration) {
    gst::init().unwrap();
    let pipeline = gst::parse::launch(description).unwrap_or_else(|e| {
        panic!("cannot build '{description}': {e} (scripts/setup.sh installs the GStreamer plugins the tests use)")
    });
    pipeline.set_state(gst::State::Playing).unwrap_or_else(|e| panic!("cannot play '{description}': {e}"));
    let bus = pipeline.bus().unwrap();
    let msg = bus
        .timed_pop_filtered(gst::ClockTime::from_nseconds(timeout.as_nanos() as u64), &[gst::MessageType::Eos, gst::MessageType::Error])
        .unwrap_or_else(|| panic!("'{description}' did not finish within {timeout:?}"));
    let _ = pipeline.set_state(gst::State::Null);
    if let gst::MessageView::Error(e) = msg.view() {
        panic!("'{description}' failed: {} ({:?})", e.error(), e.debug());
    }
}

/// Encodes the first `frames` images of `cube` (`image0000.png` ...) as an H.264 MP4 at 30
/// frames/s: a real camera sequence in a real container, as a user's recording would be.
pub fn make_cube_video(cube: &Path, frames: u32, out: &Path) {
    let description = format!(
        "multifilesrc location={}/image%04d.png index=0 stop-index={} caps=image/png,framerate=30/1 \
         ! pngdec ! videoconvert ! x264enc speed-preset=ultrafast key-int-max=30 ! mp4mux ! filesink location={}",
        cube.display(),
        frames - 1,
        out.display()
    );
    run_to_eos(&description, Duration::from_secs(120));
}

/// The checksum `handeye monitor --checksum` must report for the first `frames` frames of
/// `video` sent with `--mono` (each image as both views), decoded here by GStreamer itself
/// to GRAY8 at `width` x `height`. Also returns how many frames the file has in all.
pub fn decoded_checksum(video: &Path, frames: usize, width: u32, height: u32) -> (String, usize) {
    gst::init().unwrap();
    let description = format!(
        "filesrc location={} ! decodebin ! videoconvert ! videoscale ! video/x-raw,format=GRAY8,width={width},height={height} \
         ! appsink name=sink sync=false",
        video.display()
    );
    let pipeline = gst::parse::launch(&description).unwrap().downcast::<gst::Pipeline>().unwrap();
    let sink = pipeline.by_name("sink").unwrap().downcast::<gst_app::AppSink>().unwrap();
    pipeline.set_state(gst::State::Playing).unwrap();
    let mut checksum = PixelChecksum::new();
    let mut n = 0;
    while let Some(sample) = sink.try_pull_sample(gst::ClockTime::from_seconds(30)) {
        if n < frames {
            let info = gst_video::VideoInfo::from_caps(sample.caps().unwrap()).unwrap();
            let frame = gst_video::VideoFrameRef::from_buffer_ref_readable(sample.buffer().unwrap(), &info).unwrap();
            let stride = frame.plane_stride()[0] as usize;
            let data = frame.plane_data(0).unwrap();
            for _view in 0..2 {
                checksum.add_image(data, width as usize, height as usize, stride);
            }
        }
        n += 1;
    }
    let _ = pipeline.set_state(gst::State::Null);
    (format!("{:016x}", checksum.value()), n)
}
