//! Every other object a detector found in a frame (several targets): a
//! [`DetectionMsg`]'s candidates, with the colour at each one's point for telling them
//! apart across the two views.

use crate::{DetectError, Detection};
use opencv::core as cv;
use opencv::prelude::*;
use shared_types::messages::{Candidate, DetectionMsg, MAX_CANDIDATES};

/// The frame's colour at `centre` (BGR, per-channel median of the 3 × 3 pixels around
/// it, clipped to the frame); black outside it.
pub fn centre_colour(frame: &cv::Mat, centre: [f64; 2]) -> Result<[u8; 3], DetectError> {
    crate::check_bgr(frame)?;
    let (cols, rows) = (frame.cols(), frame.rows());
    let (u, v) = (centre[0].round(), centre[1].round());
    if !(u.is_finite() && v.is_finite()) || u < 0.0 || v < 0.0 {
        return Ok([0; 3]);
    }
    let (u, v) = (u as i32, v as i32);
    if u >= cols || v >= rows {
        return Ok([0; 3]);
    }
    // At most 3 × 3 pixels: fixed arrays, no allocation per candidate and frame.
    let mut samples = [[0u8; 9]; 3];
    let mut n = 0;
    for y in (v - 1).max(0)..=(v + 1).min(rows - 1) {
        for x in (u - 1).max(0)..=(u + 1).min(cols - 1) {
            let p = frame.at_2d::<cv::Vec3b>(y, x)?;
            for c in 0..3 {
                samples[c][n] = p[c];
            }
            n += 1;
        }
    }
    Ok(samples.map(|mut s| {
        let s = &mut s[..n];
        s.sort_unstable();
        s[n / 2]
    }))
}

/// Fills `msg`'s candidates from `found` (everything the detector found in `frame`):
/// the target (`msg.centre` when `msg.found`: the object whose box holds it, nearest
/// it) is left out, and beyond [`MAX_CANDIDATES`] the smallest boxes. Returns how many
/// were left out for room (also in `msg.candidates_dropped`).
pub fn fill(
    msg: &mut DetectionMsg,
    found: &[Detection],
    frame: &cv::Mat,
) -> Result<u32, DetectError> {
    let holds = |d: &Detection, p: [f64; 2]| {
        let [x, y, w, h] = d.bbox;
        p[0] >= x - 0.5 && p[1] >= y - 0.5 && p[0] <= x + w - 0.5 && p[1] <= y + h - 0.5
    };
    let distance = |d: &Detection| (d.centre[0] - msg.centre[0]).hypot(d.centre[1] - msg.centre[1]);
    let target = (msg.found == 1)
        .then(|| {
            found
                .iter()
                .enumerate()
                .filter(|(_, d)| holds(d, msg.centre))
                .min_by(|a, b| distance(a.1).total_cmp(&distance(b.1)))
                .map(|(i, _)| i)
        })
        .flatten();
    let mut others: Vec<&Detection> = found
        .iter()
        .enumerate()
        .filter(|(i, d)| Some(*i) != target && d.centre.iter().all(|v| v.is_finite()))
        .map(|(_, d)| d)
        .collect();
    // Largest first when there is not room for all (a stable sort: the detector's
    // order otherwise).
    let dropped = others.len().saturating_sub(MAX_CANDIDATES) as u32;
    if dropped > 0 {
        others.sort_by(|a, b| (b.bbox[2] * b.bbox[3]).total_cmp(&(a.bbox[2] * a.bbox[3])));
        others.truncate(MAX_CANDIDATES);
    }
    for (slot, d) in msg.candidates.iter_mut().zip(&others) {
        *slot = Candidate {
            bbox: d.bbox,
            centre: d.centre,
            confidence: d.confidence,
            bgr: centre_colour(frame, d.centre)?,
            _reserved: 0,
        };
    }
    msg.candidate_count = others.len() as u8;
    msg.candidates_dropped = dropped;
    Ok(dropped)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn blob(x: f64, y: f64) -> Detection {
        Detection {
            bbox: [x - 5.0, y - 3.0, 10.0, 6.0],
            centre: [x, y],
            confidence: 0.9,
        }
    }

    fn frame() -> cv::Mat {
        let mut m =
            cv::Mat::new_rows_cols_with_default(48, 64, cv::CV_8UC3, cv::Scalar::all(0.0)).unwrap();
        *m.at_2d_mut::<cv::Vec3b>(10, 20).unwrap() = cv::Vec3b::from([1, 2, 3]);
        for (y, x) in [(9, 19), (9, 20), (10, 19), (11, 21), (11, 20)] {
            *m.at_2d_mut::<cv::Vec3b>(y, x).unwrap() = cv::Vec3b::from([200, 100, 50]);
        }
        m
    }

    #[test]
    fn the_colour_is_the_median_around_the_point_and_black_outside() {
        let f = frame();
        assert_eq!(centre_colour(&f, [20.0, 10.0]).unwrap(), [200, 100, 50]);
        assert_eq!(centre_colour(&f, [-3.0, 10.0]).unwrap(), [0, 0, 0]);
        assert_eq!(centre_colour(&f, [f64::NAN, 10.0]).unwrap(), [0, 0, 0]);
        // A corner: only the pixels inside count.
        assert_eq!(centre_colour(&f, [63.0, 47.0]).unwrap(), [0, 0, 0]);
    }

    #[test]
    fn the_target_is_left_out_and_the_rest_kept_in_order() {
        let mut msg = DetectionMsg {
            found: 1,
            centre: [30.4, 20.2],
            ..Default::default()
        };
        let found = [blob(10.0, 10.0), blob(30.0, 20.0), blob(50.0, 40.0)];
        assert_eq!(fill(&mut msg, &found, &frame()).unwrap(), 0);
        let c: Vec<[f64; 2]> = msg.candidates().iter().map(|c| c.centre).collect();
        assert_eq!(c, vec![[10.0, 10.0], [50.0, 40.0]]);
        // Without a target every object is a candidate.
        msg.found = 0;
        fill(&mut msg, &found, &frame()).unwrap();
        assert_eq!(msg.candidates().len(), 3);
    }

    #[test]
    fn beyond_the_capacity_the_smallest_are_dropped_and_counted() {
        let mut msg = DetectionMsg::default();
        let found: Vec<Detection> = (0..MAX_CANDIDATES + 3)
            .map(|i| Detection {
                bbox: [0.0, 0.0, 1.0 + i as f64, 1.0],
                centre: [i as f64, 1.0],
                confidence: 1.0,
            })
            .collect();
        assert_eq!(fill(&mut msg, &found, &frame()).unwrap(), 3);
        assert_eq!(msg.candidates_dropped, 3);
        assert_eq!(msg.candidates().len(), MAX_CANDIDATES);
        assert!(msg.candidates().iter().all(|c| c.bbox[2] >= 4.0));
    }
}
