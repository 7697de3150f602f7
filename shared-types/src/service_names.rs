//! iceoryx2 service names. Every run has its own prefix (`dualgeo/<run-id>/…`) so that
//! parallel tests and two runs on one host never share a service.

use crate::conventions::Uav;

/// The publish-subscribe services of the pipeline.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Topic {
    Frames(Uav),
    Detections,
    Observations,
    Estimates,
    Latency,
}

impl Topic {
    fn suffix(self) -> String {
        match self {
            Topic::Frames(uav) => format!("frames/{}", uav.name()),
            Topic::Detections => "detections".into(),
            Topic::Observations => "observations".into(),
            Topic::Estimates => "estimates".into(),
            Topic::Latency => "latency".into(),
        }
    }
}

/// `dualgeo/<run_id>/<topic>`.
pub fn service_name(run_id: &str, topic: Topic) -> String {
    format!("dualgeo/{run_id}/{}", topic.suffix())
}

/// A run id unique on this host: process id and wall-clock nanoseconds, in hex.
pub fn new_run_id() -> String {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos())
        .unwrap_or(0);
    format!("{:x}-{:x}", std::process::id(), nanos & 0xffff_ffff_ffff)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_carry_the_run_prefix() {
        assert_eq!(
            service_name("abc", Topic::Frames(Uav::Right)),
            "dualgeo/abc/frames/right"
        );
        assert_ne!(new_run_id(), "");
    }
}
