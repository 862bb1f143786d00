//! The robust line `t(s)` through the middles of a silhouette's cross-sections (`s` along,
//! `t` across, pixels), with its standard errors: the arm's or the finger's midline.

/// `t = a + b (s - s_mean)` fitted to the selected midpoints, with its standard errors.
#[derive(Debug, Clone, Copy)]
pub(super) struct LineFit {
    pub a: f64,
    pub b: f64,
    pub s_mean: f64,
    pub s_min: f64,
    pub s_max: f64,
    pub count: usize,
    pub a_sigma: f64,
    pub b_sigma: f64,
}

impl LineFit {
    pub fn at(&self, s: f64) -> f64 {
        self.a + self.b * (s - self.s_mean)
    }
}

/// Least squares, then again three times without the sections more than 3 mean deviations
/// (at least 1 px) off the line.
pub(super) fn robust_fit(mids: &[[f64; 3]]) -> LineFit {
    let mut fit = fit_line(mids, |_| true);
    for _ in 0..3 {
        let dev = mids.iter().map(|m| (m[1] - fit.at(m[0])).abs()).sum::<f64>() / mids.len().max(1) as f64;
        let limit = (3.0 * 1.25 * dev).max(1.0);
        fit = fit_line(mids, |m| (m[1] - fit.at(m[0])).abs() <= limit);
    }
    fit
}

fn fit_line(mids: &[[f64; 3]], keep: impl Fn(&[f64; 3]) -> bool) -> LineFit {
    let (mut n, mut ss, mut st) = (0.0f64, 0.0f64, 0.0f64);
    let (mut s_min, mut s_max) = (f64::INFINITY, f64::NEG_INFINITY);
    for m in mids.iter().filter(|m| keep(m)) {
        n += 1.0;
        ss += m[0];
        st += m[1];
        s_min = s_min.min(m[0]);
        s_max = s_max.max(m[0]);
    }
    let (s_mean, t_mean) = (ss / n.max(1.0), st / n.max(1.0));
    let (mut sss, mut sst) = (0.0, 0.0);
    for m in mids.iter().filter(|m| keep(m)) {
        sss += (m[0] - s_mean).powi(2);
        sst += (m[0] - s_mean) * (m[1] - t_mean);
    }
    let b = if sss > 0.0 { sst / sss } else { 0.0 };
    let mut rss = 0.0;
    for m in mids.iter().filter(|m| keep(m)) {
        rss += (m[1] - t_mean - b * (m[0] - s_mean)).powi(2);
    }
    // Neighbouring sections share pixels' noise: count them as half as many independent ones.
    let sigma = (rss / (n - 2.0).max(1.0)).sqrt() * std::f64::consts::SQRT_2;
    LineFit {
        a: t_mean,
        b,
        s_mean,
        s_min,
        s_max,
        count: n as usize,
        a_sigma: sigma / n.max(1.0).sqrt(),
        b_sigma: sigma / sss.max(1e-9).sqrt(),
    }
}
