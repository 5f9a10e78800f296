//! Uniform rotation hypotheses for ICP initialisation.
//!
//! Super-Fibonacci spirals (Alexa, CVPR 2022): `n` unit quaternions spread
//! near-uniformly over SO(3) for any `n`, deterministic, no tables. With 60
//! rotations every rotation lies within about 60° of a hypothesis (most
//! within 40°); 120 bring that to about 45°.

use nalgebra::{Quaternion, UnitQuaternion};

/// `n` near-uniform rotations (the first is not necessarily the identity).
pub fn super_fibonacci(n: usize) -> Vec<UnitQuaternion<f64>> {
    const PHI: f64 = std::f64::consts::SQRT_2;
    const PSI: f64 = 1.533_751_168_755_204_3;
    (0..n)
        .map(|i| {
            let s = i as f64 + 0.5;
            let r = (s / n as f64).sqrt();
            let big_r = (1.0 - s / n as f64).sqrt();
            let alpha = std::f64::consts::TAU * s / PHI;
            let beta = std::f64::consts::TAU * s / PSI;
            UnitQuaternion::from_quaternion(Quaternion::new(
                big_r * beta.cos(),
                r * alpha.sin(),
                r * alpha.cos(),
                big_r * beta.sin(),
            ))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn sixty_rotations_cover_so3_within_60_degrees() {
        let grid = super_fibonacci(60);
        assert_eq!(grid.len(), 60);
        // Probe a deterministic spread of rotations.
        let mut worst: f64 = 0.0;
        for i in 0..500 {
            let t = i as f64;
            let axis = Vector3::new((t * 0.37).sin(), (t * 0.71).cos(), (t * 0.13).sin() + 0.1);
            let q = UnitQuaternion::from_scaled_axis(axis.normalize() * ((t * 0.917) % std::f64::consts::PI));
            let best = grid.iter().map(|g| g.angle_to(&q)).fold(f64::MAX, f64::min);
            worst = worst.max(best);
        }
        eprintln!("worst {:.1}°", worst.to_degrees());
        assert!(worst < 60f64.to_radians(), "worst {:.1}°", worst.to_degrees());
        let mut worst_120: f64 = 0.0;
        let fine = super_fibonacci(120);
        for i in 0..500 {
            let t = i as f64;
            let axis = Vector3::new((t * 0.37).sin(), (t * 0.71).cos(), (t * 0.13).sin() + 0.1);
            let q = UnitQuaternion::from_scaled_axis(axis.normalize() * ((t * 0.917) % std::f64::consts::PI));
            worst_120 = worst_120.max(fine.iter().map(|g| g.angle_to(&q)).fold(f64::MAX, f64::min));
        }
        eprintln!("worst 120: {:.1}°", worst_120.to_degrees());
        assert!(worst_120 < worst);
    }
}
