//! `[detection]`: which detector the service runs, and its settings.
//!
//! ```toml
//! [detection]
//! kind = "yolo"            # "colour" (default), "yolo" or "motion"
//! saturation_min = 150     # the colour detector's keys stay at this level
//!
//! [detection.yolo]
//! model = "data/models/yolov2-tiny/yolov2-tiny.weights"
//! config = "data/models/yolov2-tiny/yolov2-tiny.cfg"
//! names = "data/models/yolov2-tiny/coco.names"
//! classes = ["car", "bus", "truck"]
//!
//! [detection.motion]       # optional with kind = "motion": every key has a default
//! threshold = 30
//!
//! [detection.others]       # other vehicles' colours (several targets); defaults:
//! saturation_min = 150     # every vivid hue the target's hue_ranges leave
//! whites = true            # and white vehicles: value >= 200, saturation <= 40,
//! white_min_width_px = 6   # strokes narrower than 6 px (road markings) left out
//! ```
//!
//! Unknown keys are refused at every level, as everywhere in the configuration.

use crate::motion::MotionConfig;
use crate::other_colours::OtherColoursConfig;
use crate::yolo::YoloConfig;
use crate::ColourBlobConfig;
use serde::{Deserialize, Serialize};

/// The detector `[detection] kind` selects.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DetectorKind {
    /// The colour-blob detector with each camera's track (`tracked.rs`).
    #[default]
    Colour,
    /// A YOLO model through OpenCV DNN, carried between its runs by a template tracker
    /// (`learned.rs`).
    Yolo,
    /// Whatever moves against the ground, any colour, no model (`motion`).
    Motion,
}

/// The whole `[detection]` section.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(try_from = "toml::Table")]
pub struct DetectionConfig {
    pub kind: DetectorKind,
    /// `candidates`: publish every other object found (every blob of the colour, every
    /// mover) beside the target, for several targets (default true; the learned
    /// detector publishes none yet).
    pub candidates: bool,
    /// The colour detector's settings (the section's own keys).
    pub colour: ColourBlobConfig,
    /// `[detection.yolo]`, required with `kind = "yolo"`.
    pub yolo: Option<YoloConfig>,
    /// `[detection.motion]` (defaults when absent).
    pub motion: MotionConfig,
    /// `[detection.others]`: the other vehicles' colours, with the colour detector and
    /// `candidates` (defaults when absent).
    pub others: OtherColoursConfig,
}

impl Default for DetectionConfig {
    fn default() -> Self {
        Self {
            kind: DetectorKind::default(),
            candidates: true,
            colour: ColourBlobConfig::default(),
            yolo: None,
            motion: MotionConfig::default(),
            others: OtherColoursConfig::default(),
        }
    }
}

impl TryFrom<toml::Table> for DetectionConfig {
    type Error = String;

    fn try_from(mut table: toml::Table) -> Result<Self, String> {
        let kind = match table.remove("kind") {
            Some(v) => v
                .try_into::<DetectorKind>()
                .map_err(|e| format!("kind: {e} (expected \"colour\", \"yolo\" or \"motion\")"))?,
            None => DetectorKind::default(),
        };
        let candidates = match table.remove("candidates") {
            Some(v) => v
                .try_into::<bool>()
                .map_err(|e| format!("candidates: {e} (expected true or false)"))?,
            None => true,
        };
        let yolo = match table.remove("yolo") {
            Some(v) => Some(
                v.try_into::<YoloConfig>()
                    .map_err(|e| format!("[detection.yolo]: {e}"))?,
            ),
            None => None,
        };
        let motion = match table.remove("motion") {
            Some(v) => {
                let m = v
                    .try_into::<MotionConfig>()
                    .map_err(|e| format!("[detection.motion]: {e}"))?;
                m.validate()
                    .map_err(|e| format!("[detection.motion]: {e}"))?;
                m
            }
            None => MotionConfig::default(),
        };
        let others = match table.remove("others") {
            Some(v) => {
                let o = v
                    .try_into::<OtherColoursConfig>()
                    .map_err(|e| format!("[detection.others]: {e}"))?;
                o.validate()
                    .map_err(|e| format!("[detection.others]: {e}"))?;
                o
            }
            None => OtherColoursConfig::default(),
        };
        if kind == DetectorKind::Yolo && yolo.is_none() {
            return Err("kind = \"yolo\" needs a [detection.yolo] table with its model".into());
        }
        let colour = toml::Value::Table(table)
            .try_into::<ColourBlobConfig>()
            .map_err(|e| e.to_string())?;
        Ok(Self {
            kind,
            candidates,
            colour,
            yolo,
            motion,
            others,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<DetectionConfig, String> {
        shared_types::shell::parse_section(text, "detection")
    }

    #[test]
    fn colour_is_the_default_and_its_keys_stay_at_the_top() {
        let c = parse("[detection]\nsaturation_min = 120\n").unwrap();
        assert_eq!(c.kind, DetectorKind::Colour);
        assert_eq!(c.colour.saturation_min, 120);
        assert!(c.yolo.is_none());
        assert!(c.candidates);
        assert_eq!(parse("").unwrap(), DetectionConfig::default());
        assert!(
            !parse("[detection]\ncandidates = false\n")
                .unwrap()
                .candidates
        );
        assert!(parse("[detection]\ncandidates = 3\n")
            .unwrap_err()
            .contains("candidates"));
    }

    #[test]
    fn the_other_colours_take_their_optional_table() {
        let c = parse(
            "[detection.others]
hue_ranges = [[100, 130]]
min_area_px = 50
whites = false
",
        )
        .unwrap();
        assert_eq!(c.others.hue_ranges, Some(vec![[100, 130]]));
        assert_eq!(c.others.min_area_px, 50);
        assert!(!c.others.whites);
        assert!(
            parse(
                "[detection.others]
"
            )
            .unwrap()
            .others
            .whites
        );
        for (bad, says) in [
            (
                "[detection.others]
hue_ranges = [[130, 100]]
",
                "hue_ranges",
            ),
            (
                "[detection.others]
saturation = 3
",
                "saturation",
            ),
            (
                "[detection.others]
max_area_px = 1
",
                "max_area_px",
            ),
            (
                "[detection.others]
white_min_width_px = 0
",
                "white_min_width_px",
            ),
        ] {
            let e = parse(bad).unwrap_err();
            assert!(
                e.contains("[detection.others]") && e.contains(says),
                "{bad}: {e}"
            );
        }
    }

    #[test]
    fn motion_takes_its_optional_table() {
        let c = parse("[detection]\nkind = \"motion\"\n").unwrap();
        assert_eq!(c.kind, DetectorKind::Motion);
        assert_eq!(c.motion, MotionConfig::default());
        let c =
            parse("[detection]\nkind = \"motion\"\n[detection.motion]\nthreshold = 40\n").unwrap();
        assert_eq!(c.motion.threshold, 40.0);
    }

    #[test]
    fn yolo_takes_its_table_and_bad_keys_are_refused() {
        let c = parse(
            "[detection]\nkind = \"yolo\"\n[detection.yolo]\nmodel = \"m.weights\"\nconfig = \"m.cfg\"\nclasses = [\"car\", 7]\n",
        )
        .unwrap();
        assert_eq!(c.kind, DetectorKind::Yolo);
        let y = c.yolo.unwrap();
        assert_eq!(y.config.as_deref(), Some(std::path::Path::new("m.cfg")));
        assert_eq!(
            y.classes,
            vec![
                crate::yolo::ClassRef::Name("car".into()),
                crate::yolo::ClassRef::Index(7)
            ]
        );
        for (bad, says) in [
            ("[detection]\nkind = \"yolo\"\n", "needs a [detection.yolo]"),
            ("[detection]\nkind = \"sonar\"\n", "kind"),
            (
                "[detection]\nkind = \"motion\"\n[detection.motion]\nthreshold = 0\n",
                "threshold",
            ),
            ("[detection.motion]\nradius = 3\n", "radius"),
            (
                "[detection.motion]\nacquire_bgr = [300.0, 0.0, 0.0]\n",
                "acquire_bgr",
            ),
            ("[detection]\nhue = 3\n", "hue"),
            (
                "[detection]\nkind = \"yolo\"\n[detection.yolo]\nmodel = \"m\"\nconfidence = 0.3\n",
                "confidence",
            ),
        ] {
            let e = parse(bad).unwrap_err();
            assert!(e.contains(says), "{bad}: {e}");
        }
    }
}
