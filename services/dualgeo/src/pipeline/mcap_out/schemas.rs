//! The channels of a run's MCAP file and their schemas: Foxglove's well-known schemas
//! (https://docs.foxglove.dev/docs/visualization/message-schemas) in their JSON Schema
//! form, messages JSON-encoded (`bytes` fields as base64, as Foxglove's JSON encoding
//! defines). Only the fields dualgeo fills are spelled out; the titles are what Foxglove
//! matches a panel on. Stage latency, the estimate's quality and the list of every
//! vehicle's track have no well-known schema: `dualgeo.StageLatency`,
//! `dualgeo.TargetQuality`, `dualgeo.Targets`.

/// Schema encoding of every schema here (MCAP's well-known `jsonschema`).
pub const SCHEMA_ENCODING: &str = "jsonschema";
/// Message encoding of every channel here.
pub const MESSAGE_ENCODING: &str = "json";

/// One channel of the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ChannelSpec {
    pub topic: &'static str,
    pub schema: &'static str,
}

/// What the recorder writes, in channel-id order. Per UAV: the frame as a JPEG, the
/// measured camera pose in the world ENU frame, the detection drawn on the image. Then
/// the target (a geodetic fix with covariance, and its ENU position) and the latency of
/// each stage for that estimate, then how far the estimate can be trusted (its
/// quality state, h_acc, v_acc and both yaw biases), then every vehicle's track at
/// the pair (`/targets`: the target as id 0 when its estimate is valid, and the other
/// vehicles' tracks with their ids).
pub const CHANNELS: [ChannelSpec; 11] = [
    ChannelSpec {
        topic: "/left/image",
        schema: "foxglove.CompressedImage",
    },
    ChannelSpec {
        topic: "/right/image",
        schema: "foxglove.CompressedImage",
    },
    ChannelSpec {
        topic: "/left/pose",
        schema: "foxglove.PoseInFrame",
    },
    ChannelSpec {
        topic: "/right/pose",
        schema: "foxglove.PoseInFrame",
    },
    ChannelSpec {
        topic: "/left/detection",
        schema: "foxglove.ImageAnnotations",
    },
    ChannelSpec {
        topic: "/right/detection",
        schema: "foxglove.ImageAnnotations",
    },
    ChannelSpec {
        topic: "/target/fix",
        schema: "foxglove.LocationFix",
    },
    ChannelSpec {
        topic: "/target/pose",
        schema: "foxglove.PoseInFrame",
    },
    ChannelSpec {
        topic: "/latency",
        schema: "dualgeo.StageLatency",
    },
    ChannelSpec {
        topic: "/target/quality",
        schema: "dualgeo.TargetQuality",
    },
    ChannelSpec {
        topic: "/targets",
        schema: "dualgeo.Targets",
    },
];

/// Index into [`CHANNELS`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Channel {
    Image(usize),
    Pose(usize),
    Detection(usize),
    TargetFix,
    TargetPose,
    Latency,
    TargetQuality,
    Targets,
}

impl Channel {
    pub fn index(self) -> usize {
        match self {
            Channel::Image(uav) => uav,
            Channel::Pose(uav) => 2 + uav,
            Channel::Detection(uav) => 4 + uav,
            Channel::TargetFix => 6,
            Channel::TargetPose => 7,
            Channel::Latency => 8,
            Channel::TargetQuality => 9,
            Channel::Targets => 10,
        }
    }
}

const TIME: &str = r#"{"type":"object","title":"time","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0,"maximum":999999999}}}"#;
const VECTOR3: &str = r#"{"title":"foxglove.Vector3","type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}},"required":["x","y","z"]}"#;
const QUATERNION: &str = r#"{"title":"foxglove.Quaternion","type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"w":{"type":"number"}},"required":["x","y","z","w"]}"#;
const COLOR: &str = r#"{"title":"foxglove.Color","type":"object","properties":{"r":{"type":"number"},"g":{"type":"number"},"b":{"type":"number"},"a":{"type":"number"}},"required":["r","g","b","a"]}"#;
const POINT2: &str = r#"{"title":"foxglove.Point2","type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"}},"required":["x","y"]}"#;

/// The JSON Schema text of a schema named in [`CHANNELS`].
pub fn schema_text(name: &str) -> Option<String> {
    let object = |title: &str, props: &[(&str, String)], required: &[&str]| {
        let props: Vec<String> = props.iter().map(|(k, v)| format!(r#""{k}":{v}"#)).collect();
        let required: Vec<String> = required.iter().map(|r| format!(r#""{r}""#)).collect();
        format!(
            r#"{{"title":"{title}","type":"object","properties":{{{}}},"required":[{}]}}"#,
            props.join(","),
            required.join(",")
        )
    };
    let s = |t: &str| format!(r#"{{"type":"{t}"}}"#);
    let array = |items: &str| format!(r#"{{"type":"array","items":{items}}}"#);
    let text = match name {
        "foxglove.CompressedImage" => object(
            name,
            &[
                ("timestamp", TIME.into()),
                ("frame_id", s("string")),
                (
                    "data",
                    r#"{"type":"string","contentEncoding":"base64"}"#.into(),
                ),
                ("format", s("string")),
            ],
            &["timestamp", "frame_id", "data", "format"],
        ),
        "foxglove.PoseInFrame" => {
            let pose = object(
                "foxglove.Pose",
                &[
                    ("position", VECTOR3.into()),
                    ("orientation", QUATERNION.into()),
                ],
                &["position", "orientation"],
            );
            object(
                name,
                &[
                    ("timestamp", TIME.into()),
                    ("frame_id", s("string")),
                    ("pose", pose),
                ],
                &["timestamp", "frame_id", "pose"],
            )
        }
        "foxglove.ImageAnnotations" => {
            let points = object(
                "foxglove.PointsAnnotation",
                &[
                    ("timestamp", TIME.into()),
                    ("type", s("integer")),
                    ("points", array(POINT2)),
                    ("outline_color", COLOR.into()),
                    ("outline_colors", array(COLOR)),
                    ("fill_color", COLOR.into()),
                    ("thickness", s("number")),
                ],
                &[
                    "timestamp",
                    "type",
                    "points",
                    "outline_color",
                    "outline_colors",
                    "fill_color",
                    "thickness",
                ],
            );
            object(
                name,
                &[
                    ("circles", array(r#"{"type":"object"}"#)),
                    ("points", array(&points)),
                    ("texts", array(r#"{"type":"object"}"#)),
                ],
                &["circles", "points", "texts"],
            )
        }
        "foxglove.LocationFix" => object(
            name,
            &[
                ("timestamp", TIME.into()),
                ("frame_id", s("string")),
                ("latitude", s("number")),
                ("longitude", s("number")),
                ("altitude", s("number")),
                (
                    "position_covariance",
                    r#"{"type":"array","items":{"type":"number"},"minItems":9,"maxItems":9}"#
                        .into(),
                ),
                ("position_covariance_type", s("integer")),
            ],
            &[
                "timestamp",
                "frame_id",
                "latitude",
                "longitude",
                "altitude",
                "position_covariance",
                "position_covariance_type",
            ],
        ),
        "dualgeo.StageLatency" => {
            let ms = s("number");
            object(
                name,
                &[
                    ("timestamp", TIME.into()),
                    ("pair_seq", s("integer")),
                    ("status", s("integer")),
                    ("acquisition_ms", ms.clone()),
                    ("detection_ms", ms.clone()),
                    ("matching_ms", ms.clone()),
                    ("geolocation_ms", ms.clone()),
                    ("end_to_end_ms", ms),
                ],
                &["timestamp", "pair_seq", "status", "end_to_end_ms"],
            )
        }
        "dualgeo.TargetQuality" => object(
            name,
            &[
                ("timestamp", TIME.into()),
                ("pair_seq", s("integer")),
                (
                    "quality",
                    r#"{"type":"string","enum":["converging","tracking","coasting"]}"#.into(),
                ),
                ("h_acc_m", s("number")),
                ("v_acc_m", s("number")),
                ("yaw_bias_left_deg", s("number")),
                ("yaw_bias_right_deg", s("number")),
            ],
            &["timestamp", "pair_seq", "quality", "h_acc_m", "v_acc_m"],
        ),
        "dualgeo.Targets" => {
            let target = object(
                "dualgeo.Target",
                &[
                    ("track_id", s("integer")),
                    ("latitude", s("number")),
                    ("longitude", s("number")),
                    ("altitude", s("number")),
                    ("h_acc_m", s("number")),
                    ("v_acc_m", s("number")),
                    (
                        "quality",
                        r#"{"type":"string","enum":["converging","tracking","coasting"]}"#.into(),
                    ),
                ],
                &["track_id", "latitude", "longitude", "altitude", "quality"],
            );
            object(
                name,
                &[
                    ("timestamp", TIME.into()),
                    ("pair_seq", s("integer")),
                    ("targets", array(&target)),
                ],
                &["timestamp", "pair_seq", "targets"],
            )
        }
        _ => return None,
    };
    Some(text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_channel_has_a_schema_that_is_json_with_its_title() {
        for c in CHANNELS {
            let text = schema_text(c.schema).expect(c.schema);
            let v: serde_json::Value = serde_json::from_str(&text).expect("valid JSON");
            assert_eq!(v["title"], c.schema);
            assert_eq!(v["type"], "object");
        }
        assert!(schema_text("foxglove.Unknown").is_none());
    }

    #[test]
    fn channel_indices_name_their_topics() {
        assert_eq!(CHANNELS[Channel::Image(1).index()].topic, "/right/image");
        assert_eq!(CHANNELS[Channel::Pose(0).index()].topic, "/left/pose");
        assert_eq!(
            CHANNELS[Channel::Detection(1).index()].topic,
            "/right/detection"
        );
        assert_eq!(CHANNELS[Channel::TargetFix.index()].topic, "/target/fix");
        assert_eq!(CHANNELS[Channel::TargetPose.index()].topic, "/target/pose");
        assert_eq!(CHANNELS[Channel::Latency.index()].topic, "/latency");
    }
}
