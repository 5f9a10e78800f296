//! The two knobs every caller of the synthetic-data pipeline sets: how much
//! domain randomisation a frame gets ([`Randomize`]) and which depth-sensor
//! model corrupts its depth ([`DepthSensor`]). Both parse from and print as
//! the lower-case names the `fusepose render` flags use.

use std::fmt;
use std::str::FromStr;

/// How strongly scenes and frames are randomised (lights, textures,
/// distractors, shadows, specular highlights, camera pipeline, intrinsics).
/// `Off` reproduces the frames rendered before randomisation existed.
/// `Randomize::default()` is `Default` (the training recommendation), while
/// `SamplerConfig::default()` keeps `Off` so existing callers are unchanged.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Randomize {
    /// No randomisation: the pre-randomisation scenes and images, bit for bit.
    Off,
    /// The recommended training ranges.
    #[default]
    Default,
    /// Every range widened (harsher lights, colours, blur, JPEG, jitter).
    Strong,
}

impl Randomize {
    /// All values, in the order the CLI lists them.
    pub const ALL: [Randomize; 3] = [Randomize::Off, Randomize::Default, Randomize::Strong];

    pub fn name(self) -> &'static str {
        match self {
            Randomize::Off => "off",
            Randomize::Default => "default",
            Randomize::Strong => "strong",
        }
    }

    /// True unless `Off`.
    pub fn is_on(self) -> bool {
        self != Randomize::Off
    }
}

impl fmt::Display for Randomize {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A name that is not one of the accepted values.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown {what} '{got}': expected one of {expected}")]
pub struct ParseModeError {
    pub what: &'static str,
    pub got: String,
    pub expected: &'static str,
}

impl FromStr for Randomize {
    type Err = ParseModeError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Randomize::ALL.into_iter().find(|r| r.name().eq_ignore_ascii_case(s.trim())).ok_or_else(|| ParseModeError {
            what: "randomisation level",
            got: s.to_string(),
            expected: "off, default, strong",
        })
    }
}

/// Which depth-sensor model corrupts the rendered depth (see
/// [`super::apply_depth_sensor`]). Colour noise is separate: the camera pipeline.
/// `DepthSensor::default()` is `StructuredLight` (the training recommendation
/// and the CLI default); `SamplerConfig::default()` keeps `Basic`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum DepthSensor {
    /// Exact rendered depth, no noise.
    Ideal,
    /// The original generic model: exactly `NoiseConfig::default()`'s depth part.
    Basic,
    /// Active stereo / structured light (RealSense D4xx, Kinect v1 class):
    /// see [`super::StructuredLightParams`].
    #[default]
    StructuredLight,
    /// Continuous-wave time of flight (Kinect v2 / Azure Kinect class):
    /// see [`super::TofParams`].
    Tof,
}

impl DepthSensor {
    /// All values, in the order the CLI lists them.
    pub const ALL: [DepthSensor; 4] =
        [DepthSensor::Ideal, DepthSensor::Basic, DepthSensor::StructuredLight, DepthSensor::Tof];

    pub fn name(self) -> &'static str {
        match self {
            DepthSensor::Ideal => "ideal",
            DepthSensor::Basic => "basic",
            DepthSensor::StructuredLight => "structured-light",
            DepthSensor::Tof => "tof",
        }
    }
}

impl fmt::Display for DepthSensor {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for DepthSensor {
    type Err = ParseModeError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let s = s.trim();
        DepthSensor::ALL
            .into_iter()
            .find(|d| {
                d.name().eq_ignore_ascii_case(s)
                    || (s.eq_ignore_ascii_case("structured_light") && d.name() == "structured-light")
            })
            .ok_or_else(|| ParseModeError {
                what: "depth sensor",
                got: s.to_string(),
                expected: "ideal, basic, structured-light, tof",
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_bad_names_say_what_is_accepted() {
        for r in Randomize::ALL {
            assert_eq!(r.to_string().parse::<Randomize>().unwrap(), r);
        }
        for d in DepthSensor::ALL {
            assert_eq!(d.to_string().parse::<DepthSensor>().unwrap(), d);
        }
        assert_eq!("Strong".parse::<Randomize>().unwrap(), Randomize::Strong);
        assert_eq!("structured_light".parse::<DepthSensor>().unwrap(), DepthSensor::StructuredLight);
        assert_eq!(Randomize::default(), Randomize::Default);
        assert_eq!(DepthSensor::default(), DepthSensor::StructuredLight);
        let e = "kinect".parse::<DepthSensor>().unwrap_err();
        assert!(e.to_string().contains("structured-light, tof"), "{e}");
        assert!("wild".parse::<Randomize>().is_err());
    }
}
