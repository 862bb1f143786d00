//! A batch's result as it leaves the process (the same for a batch and for a merge of its
//! shards): the JSON or the table on stdout, and with `--out DIR` DIR/batch.json and the
//! report pages, DIR/index.html (the table, a row per run) and DIR/<scenario>/seed-<S>/index.html
//! (a run's plan, convergence plot and key moments).

use std::path::Path;

use anyhow::{Context, Result};

use super::shard::BatchFile;
use super::summary::{table, Outcome};
use crate::cli::report::{as_json, holds_brief, loss_text, BatchResult, RunSummary};

/// The run page's table: a summary's fields as its JSON shows them (`null` throughout when
/// the run printed none).
fn page_rows(s: Option<&RunSummary>) -> Vec<(&'static str, String)> {
    let field = |f: &dyn Fn(&RunSummary) -> String| s.map_or_else(|| "null".to_string(), f);
    vec![
        ("target_block", field(&|s| as_json(&s.target_block))),
        ("targeted_block", field(&|s| as_json(&s.targeted_block))),
        ("targeted_face", field(&|s| as_json(&s.targeted_face))),
        ("indicated_point_m", field(&|s| as_json(&s.indicated_point_m))),
        ("plan_facets", field(&|s| as_json(&s.plan_facets))),
        ("plan_candidates", field(&|s| as_json(&s.plan_candidates))),
        ("plan_width_mm", field(&|s| as_json(&s.plan_width_mm))),
        ("planner_ms", field(&|s| as_json(&s.planner_ms))),
        ("planning_frames", field(&|s| as_json(&s.planning_frames))),
        ("gripper_updates_while_planning", field(&|s| as_json(&s.gripper_updates_while_planning))),
        ("servo_steps", field(&|s| as_json(&s.servo_steps))),
        ("final_plane_error_mm", field(&|s| as_json(&s.final_plane_error_mm))),
        ("final_angle_error_deg", field(&|s| as_json(&s.final_angle_error_deg))),
        ("grasp_plane_error_mm", field(&|s| as_json(&s.grasp_plane_error_mm))),
        ("max_lift_mm", field(&|s| as_json(&s.max_lift_mm))),
        ("held_block_moved", field(&|s| as_json(&s.held_block_moved))),
        ("loop_us_p50", field(&|s| as_json(&s.loop_us_p50))),
        ("loop_us_p99", field(&|s| as_json(&s.loop_us_p99))),
        ("calibration_residual_px", field(&|s| as_json(&s.calibration_residual_px))),
        ("sim_frames", field(&|s| as_json(&s.sim_frames))),
        ("wall_s", field(&|s| as_json(&s.wall_s))),
    ]
}

/// The run page's account of the arm's holds for lost trackers (issue 18): each loss, which
/// tracker and why, the search, how it ended and how the phase resumed; empty when the arm
/// never held.
fn holds_section(s: Option<&RunSummary>) -> String {
    let Some(h) = s.and_then(|s| s.recovery.as_ref()) else { return String::new() };
    let Some(brief) = holds_brief(h) else { return String::new() };
    let items: String = h.losses.iter().map(|l| format!("<li>{}</li>", esc(&loss_text(l)))).collect();
    format!("<h2>Holds for lost trackers</h2><p>{}</p><ol>{items}</ol>", esc(&brief))
}

fn esc(text: &str) -> String {
    text.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

/// The report pages: DIR/index.html and one page per run (see `BatchArgs`).
pub(super) fn write_pages(out: &Path, outcomes: &[Outcome], report: &BatchResult) -> Result<()> {
    use std::fmt::Write;
    let style = "<style>body{font-family:sans-serif;margin:1.5em}table{border-collapse:collapse}td,th{border:1px solid #bbb;padding:3px 8px;text-align:left}.ok{color:#070}.bad{color:#b00}img{max-width:100%;border:1px solid #ccc;margin:4px 0}</style>";
    let mut index = format!("<!doctype html><meta charset=utf-8><title>handeye batch</title>{style}<h1>handeye batch</h1><pre>{}</pre>", esc(&table(report)));
    let _ = write!(index, "<table><tr><th>scenario</th><th>seed</th><th>result</th><th>phase</th><th>reason</th><th>target</th><th>grasped facet</th><th>servo steps</th><th>holds</th><th>wall (s)</th></tr>");
    for o in outcomes {
        let rel = format!("{}/seed-{}/index.html", o.job.name, o.job.seed);
        let s = o.summary.as_ref();
        let text = |field: fn(&RunSummary) -> &Option<String>| s.and_then(|s| field(s).clone()).unwrap_or_default();
        let _ = write!(
            index,
            "<tr><td>{}</td><td><a href=\"{rel}\">{}</a></td><td class={}>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{} {}</td><td>{}</td><td>{}</td><td>{:.1}</td></tr>",
            esc(&o.job.name),
            o.job.seed,
            if o.success { "ok" } else { "bad" },
            if o.success { "lifted" } else { "failed" },
            esc(&o.phase),
            esc(o.reason().unwrap_or("")),
            esc(&text(|s| &s.target_block)),
            esc(&text(|s| &s.targeted_block)),
            esc(&text(|s| &s.targeted_face)),
            as_json(&s.and_then(|s| s.servo_steps)),
            esc(&s.and_then(|s| s.recovery.as_ref()).and_then(holds_brief).unwrap_or_default()),
            o.wall_s
        );
        if let Some(dir) = &o.job.out {
            write_run_page(dir, o, style)?;
        }
    }
    index.push_str("</table>");
    std::fs::write(out.join("index.html"), index).with_context(|| format!("writing {}", out.join("index.html").display()))
}

fn write_run_page(dir: &Path, o: &Outcome, style: &str) -> Result<()> {
    use std::fmt::Write;
    if !dir.is_dir() {
        return Ok(());
    }
    let mut pngs: Vec<String> = std::fs::read_dir(dir)?
        .filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().into_owned()))
        .filter(|n| n.ends_with(".png") && n.chars().next().is_some_and(|c| c.is_ascii_digit()))
        .collect();
    pngs.sort();
    let mut page = format!(
        "<!doctype html><meta charset=utf-8><title>{} seed {}</title>{style}<p><a href=\"../../index.html\">batch</a></p><h1>{} seed {}: <span class={}>{}</span></h1>",
        esc(&o.job.name),
        o.job.seed,
        esc(&o.job.name),
        o.job.seed,
        if o.success { "ok" } else { "bad" },
        if o.success { "lifted and held" } else { "failed" }
    );
    if let Some(r) = o.reason() {
        let _ = write!(page, "<p>in <b>{}</b>: {}</p>", esc(&o.phase), esc(r));
    }
    let _ = write!(page, "<table>");
    for (key, value) in page_rows(o.summary.as_ref()) {
        let _ = write!(page, "<tr><th>{key}</th><td>{}</td></tr>", esc(&value));
    }
    let _ = write!(page, "</table>");
    page.push_str(&holds_section(o.summary.as_ref()));
    let _ = write!(page, "<p>Files: <a href=\"run.json\">run.json</a> <a href=\"plan.json\">plan.json</a> <a href=\"daemon.json\">daemon.json</a> <a href=\"sim.json\">sim.json</a> <a href=\"daemon.stderr.log\">daemon log</a> <a href=\"sim.stderr.log\">sim log</a></p>");
    let caption = |name: &str| -> String {
        let label = name.trim_end_matches(".png").trim_start_matches(|c: char| c.is_ascii_digit() || c == '_').replace('_', " ");
        match label.as_str() {
            "plan" => "the plan: the planner's facets (colours; grey: left out; pink: hypothesised below a top face), rejected sites (yellow), candidates (white rings), the chosen site and its facet (red), the indicated point (magenta), the masked gripper (blue)".into(),
            other => format!("{other}: tracked contours (gripper green, target red, lost yellow)"),
        }
    };
    for png in pngs.iter().filter(|p| p.ends_with("_plan.png")) {
        let _ = write!(page, "<h2>Plan</h2><p>{}</p><img src=\"{png}\">", esc(&caption(png)));
    }
    if dir.join("servo_convergence.svg").exists() {
        let _ = write!(page, "<h2>Servo convergence</h2><p>the move the servo still estimated to its goal, per step: translation (mm, upper) and yaw (degrees, lower), log axes; dashed: the convergence tolerances</p><img src=\"servo_convergence.svg\">");
    }
    let _ = write!(page, "<h2>Key moments</h2>");
    for png in pngs.iter().filter(|p| !p.ends_with("_plan.png")) {
        let _ = write!(page, "<p>{}</p><img src=\"{png}\">", esc(&caption(png)));
    }
    std::fs::write(dir.join("index.html"), page).with_context(|| format!("writing {}", dir.join("index.html").display()))
}

/// The batch's result: DIR/batch.json and the pages with `out`, then the JSON or the table on
/// stdout. The same for a batch and for a merge of its shards.
pub(super) fn write_report(file: &BatchFile, outcomes: &[Outcome], out: Option<&Path>, json: bool) -> Result<()> {
    if let Some(out) = out {
        let path = out.join("batch.json");
        std::fs::write(&path, serde_json::to_string_pretty(file)?).with_context(|| format!("writing {}", path.display()))?;
        write_pages(out, outcomes, &file.result)?;
    }
    if json {
        println!("{}", serde_json::to_string(file)?);
    } else {
        print!("{}", table(&file.result));
        if let Some(out) = out {
            println!("report: {}", out.join("index.html").display());
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_run_page_lists_each_loss_and_a_calm_run_none() {
        let s = crate::cli::report::tests::summary();
        let html = holds_section(Some(&s));
        assert!(html.contains("<p>1 loss, 1 recovered, held 1.25 s</p>"), "{html}");
        assert!(html.contains("<li>servo, frame 812: target tracker (left view) lost"), "{html}");
        assert!(html.contains("3 search passes, 1 relapse; recovered; resumed: servo from fresh frames</li>"), "{html}");
        assert_eq!(holds_section(Some(&RunSummary { recovery: None, ..s.clone() })), "");
        assert_eq!(holds_section(None), "");
    }
}
