//! Running first and second moments of a pixel set: a region's centroid and the covariance
//! its axis and extents come from, accumulated one pixel at a time while the region is
//! grown (`locate`'s gripper plate regions, `pointing`'s finger components).

/// Running sums of a pixel set's coordinates, their squares and products.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Moments {
    pub n: f64,
    sx: f64,
    sy: f64,
    sxx: f64,
    syy: f64,
    sxy: f64,
}

impl Moments {
    pub fn add(&mut self, x: f64, y: f64) {
        self.n += 1.0;
        self.sx += x;
        self.sy += y;
        self.sxx += x * x;
        self.syy += y * y;
        self.sxy += x * y;
    }

    pub fn merge(&mut self, o: &Moments) {
        self.n += o.n;
        self.sx += o.sx;
        self.sy += o.sy;
        self.sxx += o.sxx;
        self.syy += o.syy;
        self.sxy += o.sxy;
    }

    /// Centroid and second central moments `([mx, my], cxx, cxy, cyy)`, px and px².
    pub fn central(&self) -> ([f64; 2], f64, f64, f64) {
        let (mx, my) = (self.sx / self.n, self.sy / self.n);
        ([mx, my], self.sxx / self.n - mx * mx, self.sxy / self.n - mx * my, self.syy / self.n - my * my)
    }
}
