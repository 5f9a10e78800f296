//! First and second moments of 3D points: least-squares planes and normals.

/// First and second moments of 3D points, for a least-squares plane.
#[derive(Default)]
pub(crate) struct Moments {
    n: f32,
    s: [f32; 3],
    ss: [[f32; 3]; 3],
}

impl Moments {
    pub(crate) fn add(&mut self, p: [f32; 3]) {
        self.n += 1.0;
        for i in 0..3 {
            self.s[i] += p[i];
            for j in 0..3 {
                self.ss[i][j] += p[i] * p[j];
            }
        }
    }

    /// The points' mean, their axis of least variance (unit) and that
    /// variance; `None` with fewer than `min_points`.
    pub(crate) fn least_axis(&self, min_points: f32) -> Option<([f32; 3], [f32; 3], f32)> {
        if self.n < min_points {
            return None;
        }
        let mean = self.s.map(|v| v / self.n);
        let cov = nalgebra::Matrix3::from_fn(|i, j| self.ss[i][j] / self.n - mean[i] * mean[j]);
        let eig = nalgebra::SymmetricEigen::new(cov);
        let k = eig.eigenvalues.imin();
        let axis = eig.eigenvectors.column(k);
        Some((mean, [axis[0], axis[1], axis[2]], eig.eigenvalues[k]))
    }

    /// The best-fit plane `n·x = d` (unit `n`) when the points lie within
    /// `max_rms` of it and there are enough of them; else `None`.
    pub(crate) fn flat_plane(&self, max_rms: f32) -> Option<([f32; 3], f32)> {
        let (mean, n, variance) = self.least_axis(12.0)?;
        (variance.max(0.0).sqrt() <= max_rms).then(|| (n, n[0] * mean[0] + n[1] * mean[1] + n[2] * mean[2]))
    }
}
