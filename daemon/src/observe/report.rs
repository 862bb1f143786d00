//! Observe mode's report: `observe.json` ([`ObserveReport`]: frames, drops and the camera's
//! rate from the capture stamps, per tracker the frames tracked and lost, when it was lost
//! and found again, the trackers' update time; with `--plane`, the pointing gestures:
//! [`super::pointing::PointingReport`]) and `observe_plot.svg` (confidence of every watched
//! contour and the stereo tracker update time over the stream's camera time).

use plotters::prelude::*;
use serde::{Deserialize, Serialize};

use super::pointing::PointingReport;
use super::watch::WatchCounts;
use crate::camera_clock::ClockStats;
use crate::outcome::TrackerTiming;

/// `observe.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObserveReport {
    /// Frames processed.
    pub frames: u64,
    /// The camera clock: dropped frames (gaps in the ids), bad stamps, rates, time steps.
    pub camera: ClockStats,
    /// Times the camera went away (and the stream was reported gone).
    pub camera_gone: u32,
    /// Every watched contour (`target_left`, ...).
    pub trackers: Vec<WatchCounts>,
    /// The stereo tracker update per frame (all running contours), µs.
    pub tracker_update: TrackerTiming,
    /// Frame received → telemetry published, µs.
    pub loop_us: LoopTiming,
    /// The two views' tracks against the stereo model (`None` without one).
    pub epipolar: Option<EpipolarStats>,
    /// The pointing gestures read (`None` without `--plane`).
    #[serde(default)]
    pub pointing: Option<PointingReport>,
    /// How the run ended: `stream ended`, `interrupted`.
    pub end: String,
    pub wall_s: f64,
}

/// Frame received → telemetry published, µs (histogram bucket edges).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LoopTiming {
    pub p50: f64,
    pub p99: f64,
}

/// The views' agreement: per frame with a contour tracked in both views, the RMS epipolar
/// residual of its corners (the worse contour's), px; the median is a histogram bucket's
/// upper edge (at most 1/16 above the true value).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EpipolarStats {
    pub frames: u64,
    pub rms_px_p50: Option<f64>,
    pub rms_px_max: Option<f64>,
    /// `target.max_epipolar_px`: above it the telemetry says the views disagree.
    pub limit_px: f64,
    pub over_limit_frames: u64,
}

/// One frame of the plot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SeriesRow {
    pub frame_id: u64,
    /// Camera time since the first frame, s.
    pub time_s: f64,
    /// Per telemetry slot: confidence (0 while lost), NaN when off.
    pub confidence: [f64; 4],
    /// Stereo tracker update, µs.
    pub update_us: f64,
}

const COLOURS: [RGBColor; 4] = [RGBColor(40, 160, 60), RGBColor(20, 100, 30), RGBColor(220, 40, 40), RGBColor(140, 20, 140)];

/// The plot as SVG: confidence per contour (upper panel) and update time (lower) against
/// camera time. `names` label the four slots.
///
/// ```
/// use handeye_daemon::observe::report::{observe_plot_svg, SeriesRow};
/// let rows: Vec<SeriesRow> = (0..30)
///     .map(|i| SeriesRow { frame_id: i, time_s: i as f64 / 30.0, confidence: [f64::NAN, f64::NAN, 0.8, f64::NAN], update_us: 40.0 })
///     .collect();
/// let svg = observe_plot_svg(&rows, ["gripper_left", "gripper_right", "target_left", "target_right"]).unwrap();
/// assert!(svg.contains("camera time (s)") && svg.contains("target_left") && !svg.contains("target_right"));
/// ```
pub fn observe_plot_svg(rows: &[SeriesRow], names: [&str; 4]) -> Result<String, String> {
    let end_s = rows.iter().map(|r| r.time_s).fold(0.0, f64::max).max(1e-3);
    let top_us = rows.iter().map(|r| r.update_us).filter(|v| v.is_finite()).fold(1.0, f64::max) * 1.2;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (800, 560)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let (upper, lower) = root.split_vertically(300);
        let mut chart = ChartBuilder::on(&upper)
            .margin(12)
            .x_label_area_size(36)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..end_s, 0.0..1.05)
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc("camera time (s)")
            .y_desc("tracker confidence")
            .axis_desc_style(("sans-serif", 15))
            .label_style(("sans-serif", 13))
            .draw()
            .map_err(|e| e.to_string())?;
        for (i, name) in names.iter().enumerate() {
            let points: Vec<(f64, f64)> = rows.iter().filter(|r| r.confidence[i].is_finite()).map(|r| (r.time_s, r.confidence[i])).collect();
            if points.is_empty() {
                continue;
            }
            let colour = COLOURS[i];
            chart
                .draw_series(LineSeries::new(points, colour.stroke_width(2)))
                .map_err(|e| e.to_string())?
                .label(*name)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2)));
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::LowerRight)
            .label_font(("sans-serif", 13))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(|e| e.to_string())?;
        let mut chart = ChartBuilder::on(&lower)
            .margin(12)
            .x_label_area_size(36)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..end_s, 0.0..top_us)
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc("camera time (s)")
            .y_desc("tracker update (µs)")
            .axis_desc_style(("sans-serif", 15))
            .label_style(("sans-serif", 13))
            .draw()
            .map_err(|e| e.to_string())?;
        let blue = RGBColor(30, 80, 200);
        chart
            .draw_series(LineSeries::new(rows.iter().filter(|r| r.update_us.is_finite()).map(|r| (r.time_s, r.update_us)), blue.stroke_width(1)))
            .map_err(|e| e.to_string())?;
        root.present().map_err(|e| e.to_string())?;
    }
    Ok(svg)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn observe_json_reads_back_and_names_a_renamed_key() {
        let r = ObserveReport {
            frames: 218,
            camera: ClockStats { frames: 218, dropped_frames: 72, ..ClockStats::default() },
            camera_gone: 0,
            trackers: vec![WatchCounts { name: "target_left".into(), acquired_frame_id: Some(15), tracked_frames: 218, ..WatchCounts::default() }],
            tracker_update: TrackerTiming { us_p50: 30.0, us_p99: 60.0, us_max: 90.0, us_mean: 32.0, cycles: 218 },
            loop_us: LoopTiming { p50: 50.0, p99: 90.0 },
            epipolar: None,
            pointing: None,
            end: "stream ended".into(),
            wall_s: 7.5,
        };
        let text = serde_json::to_string(&r).unwrap();
        assert_eq!(serde_json::from_str::<ObserveReport>(&text).unwrap(), r);
        let err = serde_json::from_str::<ObserveReport>(&text.replace("\"dropped_frames\"", "\"drops\"")).unwrap_err().to_string();
        assert!(err.contains("drops"), "{err}");
    }
}
