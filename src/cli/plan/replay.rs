//! `handeye plan --run DIR`: the daemon's whole plan (planner, grasp scene, hypothesised
//! faces, rear edges in the images, grasp rules, the chosen site) rerun on a run's saved
//! pair with the run's own configuration and calibration, in seconds instead of a run.

use std::path::Path;

use anyhow::{Context, Result};
use handeye_daemon::planning::{plan, replay_request, PlanOutput, PlanSummary, SiteSummary};
use handeye_daemon::DaemonConfig;
use handeye_vision::image::ImageBuf;

/// A saved view as 8-bit grey (the same reader as `handeye plan --left`).
fn load_gray(path: &Path) -> Result<ImageBuf> {
    // cli's png (or the fuzz test's own, where it includes plan.rs at its root).
    let img = super::super::png::read_gray(path)?;
    let (w, h) = img.dimensions();
    ImageBuf::from_vec(img.into_raw(), w as usize, h as usize).with_context(|| format!("image {} is empty", path.display()))
}

/// Replays the plan of the run reported in `dir` (see `PLAN_HELP`).
pub fn replay(dir: &Path) -> Result<PlanOutput> {
    let cfg_path = dir.join("daemon.toml");
    let cfg = DaemonConfig::load(&cfg_path).with_context(|| format!("{}: the run's daemon configuration", cfg_path.display()))?;
    let json_path = dir.join("plan.json");
    let text = std::fs::read_to_string(&json_path).with_context(|| format!("cannot read {} (did the run reach its plan?)", json_path.display()))?;
    let summary: PlanSummary = serde_json::from_str(&text).with_context(|| format!("{} is not a plan report", json_path.display()))?;
    let images = [load_gray(&dir.join("plan_left.png"))?, load_gray(&dir.join("plan_right.png"))?];
    let request = replay_request(&cfg, &summary, images).with_context(|| format!("{}", json_path.display()))?;
    Ok(plan(request))
}

fn site_line(s: &SiteSummary) -> String {
    let distance = s.place.distance_mm.map(|d| format!(", {d:.0} mm from the point")).unwrap_or_default();
    let why = s.reason.as_ref().map(|r| format!(" — {r}")).unwrap_or_default();
    format!(
        "facet {}{}: width {:.1} mm, site ({:.3}, {:.3}, {:.3}) m{distance}{why}",
        s.plan_facet,
        if s.hypothesised_facet { " (hypothesised)" } else { "" },
        s.grasp.width_mm,
        s.place.site_m[0],
        s.place.site_m[1],
        s.place.site_m[2]
    )
}

/// What the replay decided, in lines a person reads.
pub fn replay_summary(out: &PlanOutput) -> String {
    let s = &out.summary;
    let mut text = format!(
        "segments {:?}, matches {}, planes {}, facets in the scene {} (superseded {:?}), planner {:.0} ms, plan {:.0} ms\n",
        s.counts.segments, s.counts.matches, s.counts.planes, s.scene.facets.len(), s.scene.superseded_facets, s.timing.planner_ms, s.timing.total_ms
    );
    for f in &s.scene.facets {
        let corners = f.corners_m.as_ref().map(|c| {
            let z: Vec<String> = c.iter().map(|p| format!("{:.0}", p[2] * 1e3)).collect();
            format!("corner heights {} mm", z.join("/"))
        });
        text += &format!(
            "  facet {}{}: object {:?}, {}\n",
            f.plan_facet,
            if f.hypothesised { " (hypothesised)" } else { "" },
            f.component,
            corners.unwrap_or_else(|| "no corners".into())
        );
    }
    for (facet, depth_mm, support) in &s.scene.image_rear_edges {
        text += &format!("rear edge in the images behind facet {facet}: {depth_mm:.0} mm deep, support {support:.2}\n");
    }
    for (facet, why) in &s.sites.facet_rejections {
        text += &format!("facet {facet} rejected: {why}\n");
    }
    for r in &s.sites.rejected_sites {
        text += &format!("rejected site: {}\n", site_line(r));
    }
    for c in &s.sites.candidates {
        text += &format!("candidate: {}\n", site_line(c));
    }
    match (&s.sites.chosen, &out.refusal, &out.unjudged) {
        (Some(c), _, _) => text += &format!("chosen: {}\n", site_line(c)),
        (None, Some(why), _) => text += &format!("no site: refused: {why}\n"),
        (None, None, Some(seen)) => text += &format!("no site, not a refusal: {seen}\n"),
        (None, None, None) => text += "no site near the indicated point\n",
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_run_dir_without_a_plan_says_which_file_is_missing() {
        let dir = std::env::temp_dir().join(format!("handeye-replay-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("daemon.toml"), "").unwrap();
        let err = replay(&dir).err().expect("no plan.json: no replay");
        assert!(format!("{err:#}").contains("plan.json"), "{err:#}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
