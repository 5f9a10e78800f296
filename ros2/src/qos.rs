//! QoS flags of the bridges and the ROS 2 profiles they stand for.
//!
//! As rmw maps them: the default profile is reliable, keep last 10, volatile;
//! sensor data is best effort, keep last 5, volatile. A best-effort reader
//! matches reliable and best-effort writers alike; a reliable reader matches
//! only reliable writers.

use ros2_client::QosProfile;
use ros2_client::qos::{Durability, History, Reliability, WhenFull};

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ReliabilityArg {
    Reliable,
    BestEffort,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum DurabilityArg {
    Volatile,
    TransientLocal,
}

/// The profile of the three flags (keep last `depth`, at least 1).
pub fn profile(reliability: ReliabilityArg, depth: usize, durability: DurabilityArg) -> QosProfile {
    QosProfile::subscription_default()
        .reliability(match reliability {
            // A full send window must never stall the bridge: give up on a sample after 20 ms.
            ReliabilityArg::Reliable => {
                Reliability::Reliable { when_full: WhenFull::Wait(std::time::Duration::from_millis(20)) }
            }
            ReliabilityArg::BestEffort => Reliability::BestEffort,
        })
        .history(History::KeepLast { depth: depth.max(1) })
        .durability(match durability {
            DurabilityArg::Volatile => Durability::Volatile,
            DurabilityArg::TransientLocal => Durability::TransientLocal,
        })
}

/// `/tf` as tf2 broadcasters publish it: reliable, keep last 100, volatile.
pub fn tf_profile() -> QosProfile {
    profile(ReliabilityArg::Reliable, 100, DurabilityArg::Volatile)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flags_build_the_ros_profiles() {
        let sensor = profile(ReliabilityArg::BestEffort, 5, DurabilityArg::Volatile);
        assert_eq!(sensor.reliability, Reliability::BestEffort);
        assert_eq!(sensor.history, History::KeepLast { depth: 5 });
        let latched = profile(ReliabilityArg::Reliable, 0, DurabilityArg::TransientLocal);
        assert!(matches!(latched.reliability, Reliability::Reliable { .. }));
        assert_eq!(latched.history, History::KeepLast { depth: 1 });
        assert_eq!(latched.durability, Durability::TransientLocal);
    }
}
