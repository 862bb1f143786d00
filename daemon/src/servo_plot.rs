//! The servo convergence plot of the run report (`servo_convergence.svg`): per servo step,
//! the move the servo still estimated to the goal, its translation in millimetres (upper
//! panel) and its yaw in degrees (lower panel), both on log axes, with the convergence
//! tolerances as dashed lines. A run that converges falls below both lines and stays there.
//!
//! Drawn with `plotters` into SVG: text is left to the viewer's fonts, so no font files are
//! needed to draw it (the report is written on machines without any).

use plotters::prelude::*;

use crate::mission::ServoTraceRow;

/// Smallest value shown: anything smaller (a converged step's zero) sits on the bottom edge.
const FLOOR: f64 = 1e-3;

/// One panel's series: `(step, value)`, values floored at [`FLOOR`].
fn series(rows: &[ServoTraceRow], value: impl Fn(&ServoTraceRow) -> f64) -> Vec<(u32, f64)> {
    rows.iter()
        .filter_map(|r| {
            let v = value(r).abs();
            v.is_finite().then_some((r.step, v.max(FLOOR)))
        })
        .collect()
}

/// The plot as an SVG document. `tolerance_mm` and `tolerance_deg` are the servo's
/// convergence tolerances (`servo.converged_m`, `servo.converged_deg`).
///
/// ```
/// use handeye_daemon::mission::ServoTraceRow;
/// let rows: Vec<ServoTraceRow> = (1..6)
///     .map(|i| ServoTraceRow { step: i, frame: 0, error: [0.0; 6], offset_m: 0.02 / f64::from(i * i), offset_yaw_rad: 0.05 / f64::from(i) })
///     .collect();
/// let svg = handeye_daemon::servo_plot::servo_plot_svg(&rows, 0.5, 0.3).unwrap();
/// assert!(svg.starts_with("<svg") && svg.contains("servo step") && svg.contains("translation (mm)"));
/// ```
pub fn servo_plot_svg(rows: &[ServoTraceRow], tolerance_mm: f64, tolerance_deg: f64) -> Result<String, String> {
    let translation = series(rows, |r| r.offset_m * 1e3);
    let yaw = series(rows, |r| r.offset_yaw_rad.to_degrees());
    let last_step = rows.iter().map(|r| r.step).max().unwrap_or(1).max(1);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (760, 560)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let (upper, lower) = root.split_vertically(280);
        let panels = [
            (&upper, &translation, tolerance_mm, "remaining translation (mm)", "servo's estimate of the move to the goal", RGBColor(30, 80, 200)),
            (&lower, &yaw, tolerance_deg, "remaining yaw (°)", "servo's estimate of the turn to the goal", RGBColor(200, 60, 30)),
        ];
        for (area, data, tolerance, y_desc, label, colour) in panels {
            let top = data.iter().map(|p| p.1).fold(tolerance.max(FLOOR) * 10.0, f64::max) * 1.5;
            let mut chart = ChartBuilder::on(area)
                .margin(12)
                .x_label_area_size(40)
                .y_label_area_size(70)
                .build_cartesian_2d(0u32..last_step + 1, (FLOOR..top).log_scale())
                .map_err(|e| e.to_string())?;
            chart
                .configure_mesh()
                .x_desc("servo step")
                .y_desc(y_desc)
                .x_labels((last_step as usize + 2).min(16))
                .y_label_formatter(&|y| format!("{y}"))
                .axis_desc_style(("sans-serif", 15))
                .label_style(("sans-serif", 13))
                .draw()
                .map_err(|e| e.to_string())?;
            chart
                .draw_series(LineSeries::new(data.iter().copied(), colour.stroke_width(2)))
                .map_err(|e| e.to_string())?
                .label(label)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2)));
            chart.draw_series(data.iter().map(|&p| Circle::new(p, 3, colour.filled()))).map_err(|e| e.to_string())?;
            if tolerance.is_finite() && tolerance > 0.0 {
                let grey = RGBColor(110, 110, 110);
                chart
                    .draw_series(DashedLineSeries::new([(0, tolerance), (last_step + 1, tolerance)], 6, 4, grey.stroke_width(1)))
                    .map_err(|e| e.to_string())?
                    .label(format!("convergence tolerance ({tolerance})"))
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], grey));
            }
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperRight)
                .label_font(("sans-serif", 13))
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .draw()
                .map_err(|e| e.to_string())?;
        }
        root.present().map_err(|e| e.to_string())?;
    }
    Ok(svg)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(step: u32, offset_mm: f64, yaw_deg: f64) -> ServoTraceRow {
        ServoTraceRow { step, frame: 0, error: [f64::NAN; 6], offset_m: offset_mm * 1e-3, offset_yaw_rad: yaw_deg.to_radians() }
    }

    #[test]
    fn the_plot_has_labelled_axes_a_legend_and_one_point_per_step() {
        let rows: Vec<ServoTraceRow> = (1..=6).map(|i| row(i, 20.0 / 3f64.powi(i as i32), 2.0 / f64::from(i))).collect();
        let svg = servo_plot_svg(&rows, 0.5, 0.3).unwrap();
        for want in ["servo step", "remaining translation (mm)", "remaining yaw (°)", "convergence tolerance (0.5)", "convergence tolerance (0.3)"] {
            assert!(svg.contains(want), "{want} missing");
        }
        // Six markers per panel, and whole steps on the step axis (each labelled once).
        assert_eq!(svg.matches("<circle").count(), 12, "{svg}");
        // (1 is also a decade of the log axes.)
        for step in [0, 2, 3, 4, 5, 6, 7] {
            let label = format!(">\n{step}\n</text>");
            assert_eq!(svg.matches(&label).count(), 2, "step {step} labelled once per panel");
        }
    }

    #[test]
    fn series_keep_their_values_floor_zeros_and_drop_gaps() {
        // Values in the panel's unit; a converged step's zero sits on the floor rather than
        // vanishing from a log axis.
        let s = series(&[row(1, 10.0, 0.0), row(2, 0.1, 0.0)], |r| r.offset_m * 1e3);
        assert_eq!(s, vec![(1, 10.0), (2, 0.1)]);
        let y = series(&[row(1, 1.0, 0.0)], |r| r.offset_yaw_rad.to_degrees());
        assert_eq!(y, vec![(1, FLOOR)]);
        // NaN rows (no estimate) are left out.
        assert!(series(&[row(1, f64::NAN, 0.0)], |r| r.offset_m).is_empty());
        // An empty trace still draws (axes, no line).
        assert!(servo_plot_svg(&[], 0.5, 0.3).unwrap().contains("servo step"));
    }
}
