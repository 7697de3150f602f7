//! What moves against the ground: differences of the newest frame with older frames
//! warped onto it, the blobs they leave, and a mover's outline.
//!
//! **The difference tolerates registration.** A pixel has changed when it lies outside
//! the range of the warped old frame's 3 × 3 neighbourhood in some colour channel
//! (`max(now − dilate(old), erode(old) − now)`): a sub-pixel misregistration of a
//! textured ground, or a road marking's edge, stays inside that range, while a vehicle
//! over asphalt does not. Colour, not grey: a red car and grey asphalt can have one
//! grey level.
//!
//! **Double difference.** A mover leaves a blob where it is now and a ghost where it
//! was. The newest frame differs from *both* the frame `k` back and `2k` back only where
//! the mover is now (at the ghost of `k` back, the frame `2k` back shows the same
//! ground), so the minimum of the two differences keeps the mover and drops its ghosts
//! (Kameda & Minoh's three-frame difference, with the ground's motion compensated).
//! A building's parallax leaves thin strips along its edges: blobs thinner than
//! `min_side_px` are dropped.
//!
//! **Outline.** With a short gap a uniform car overlaps itself: only its front shows.
//! The mover's outline comes from one long-gap difference in a window around it (the
//! car has left its old place; the ghost is another blob) and the component nearest
//! the short-gap blob. Its top face (the target point is the top's centre) is the
//! brighter part of the outline when the outline splits cleanly in two by brightness
//! (Otsu): the sides of a box are in shade.

use nalgebra::{Matrix3, Vector3};
use opencv::core as cv;
use opencv::prelude::*;

/// A blob that moved against the ground, full-resolution pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mover {
    pub centre: [f64; 2],
    /// Left, top, width, height.
    pub bbox: [f64; 4],
    pub area_px: f64,
    /// Its mean colour (BGR) in the newest frame: how a track tells it from another
    /// mover.
    pub bgr: [f64; 3],
}

impl Mover {
    /// As a candidate beside the target (several targets).
    pub fn as_detection(&self) -> crate::Detection {
        crate::Detection {
            bbox: self.bbox,
            centre: self.centre,
            confidence: 1.0,
        }
    }
}

/// Reusable buffers for the differences.
#[derive(Default)]
pub struct Differencer {
    warped: cv::Mat,
    scratch: cv::Mat,
    high: cv::Mat,
    low: cv::Mat,
    above: cv::Mat,
    below: cv::Mat,
    channels: cv::Vector<cv::Mat>,
    diff: [cv::Mat; 2],
    both: cv::Mat,
    mask: cv::Mat,
    labels: cv::Mat,
    stats: cv::Mat,
    centroids: cv::Mat,
}

fn to_cv(m: &Matrix3<f64>) -> opencv::Result<cv::Mat> {
    cv::Mat::from_slice_2d(&[
        [m[(0, 0)], m[(0, 1)], m[(0, 2)]],
        [m[(1, 0)], m[(1, 1)], m[(1, 2)]],
        [m[(2, 0)], m[(2, 1)], m[(2, 2)]],
    ])
}

impl Differencer {
    /// How much `now` differs from `old` warped by `h` (old pixels → `now`'s pixels, the
    /// window's origin included), per pixel, into `self.diff[slot]`. Where the old frame
    /// does not reach, its border is replicated: [`covered`] keeps blobs there out.
    fn difference(
        &mut self,
        now: &cv::Mat,
        old: &cv::Mat,
        h: &Matrix3<f64>,
        slot: usize,
    ) -> opencv::Result<()> {
        let size = now.size()?;
        let m = to_cv(h)?;
        opencv::imgproc::warp_perspective(
            old,
            &mut self.warped,
            &m,
            size,
            opencv::imgproc::INTER_LINEAR,
            cv::BORDER_REPLICATE,
            cv::Scalar::default(),
        )?;
        let kernel = cv::Mat::default(); // 3 × 3 rectangle
        opencv::imgproc::dilate_def(&self.warped, &mut self.high, &kernel)?;
        opencv::imgproc::erode_def(&self.warped, &mut self.low, &kernel)?;
        cv::subtract_def(now, &self.high, &mut self.above)?;
        cv::subtract_def(&self.low, now, &mut self.below)?;
        cv::max(&self.above, &self.below, &mut self.high)?;
        // The largest channel: a change in any colour counts.
        cv::split(&self.high, &mut self.channels)?;
        let out = &mut self.diff[slot];
        match self.channels.len() {
            3 => {
                let (b, g, r) = (
                    self.channels.get(0)?,
                    self.channels.get(1)?,
                    self.channels.get(2)?,
                );
                cv::max(&b, &g, &mut self.scratch)?;
                cv::max(&self.scratch, &r, out)?;
            }
            _ => self.channels.get(0)?.copy_to(out)?,
        }
        Ok(())
    }

    /// Blobs of `now` (small image) that differ from both `near` and `far` (small
    /// images, registered by `near_h` and `far_h`) by more than `threshold`, mapped to
    /// full-resolution pixels by `to_full`; thinner than `min_side` or smaller than
    /// `min_area` (small pixels) dropped.
    #[allow(clippy::too_many_arguments)]
    pub fn movers(
        &mut self,
        now: &cv::Mat,
        (near, near_h): (&cv::Mat, &Matrix3<f64>),
        (far, far_h): (&cv::Mat, &Matrix3<f64>),
        threshold: f64,
        (min_side, min_area): (i32, i32),
        to_full: &Matrix3<f64>,
        out: &mut Vec<Mover>,
    ) -> opencv::Result<()> {
        out.clear();
        self.difference(now, near, near_h, 0)?;
        self.difference(now, far, far_h, 1)?;
        cv::min(&self.diff[0], &self.diff[1], &mut self.both)?;
        let n = self.blobs(threshold)?;
        let s = to_full[(0, 0)];
        for i in 1..n {
            let stat = |k: i32| self.stats.at_2d::<i32>(i, k).copied();
            let (x, y, w, h, area) = (
                stat(opencv::imgproc::CC_STAT_LEFT)?,
                stat(opencv::imgproc::CC_STAT_TOP)?,
                stat(opencv::imgproc::CC_STAT_WIDTH)?,
                stat(opencv::imgproc::CC_STAT_HEIGHT)?,
                stat(opencv::imgproc::CC_STAT_AREA)?,
            );
            if w.min(h) < min_side || area < min_area {
                continue;
            }
            let corners = [
                [x as f64, y as f64],
                [(x + w - 1) as f64, (y + h - 1) as f64],
                [x as f64, (y + h - 1) as f64],
                [(x + w - 1) as f64, y as f64],
            ];
            let seen_by = |old: &cv::Mat, h: &Matrix3<f64>| -> opencv::Result<bool> {
                let size = old.size()?;
                Ok(corners.iter().all(|p| covered(h, size, *p)))
            };
            if !seen_by(near, near_h)? || !seen_by(far, far_h)? {
                continue;
            }
            let c = to_full
                * Vector3::new(
                    *self.centroids.at_2d::<f64>(i, 0)?,
                    *self.centroids.at_2d::<f64>(i, 1)?,
                    1.0,
                );
            let bgr = self.mean_colour(now, i, [x, y, w, h])?;
            // Small pixel x covers full pixels s·x ..= s·x + s − 1.
            out.push(Mover {
                bgr,
                centre: [c.x, c.y],
                bbox: [x as f64 * s, y as f64 * s, w as f64 * s, h as f64 * s],
                area_px: area as f64 * s * s,
            });
        }
        Ok(())
    }

    /// The mean colour of `image` over the pixels labelled `label` inside `bbox`.
    fn mean_colour(
        &self,
        image: &cv::Mat,
        label: i32,
        [x, y, w, h]: [i32; 4],
    ) -> opencv::Result<[f64; 3]> {
        let (mut sum, mut n) = ([0.0; 3], 0.0f64);
        for v in y..y + h {
            for u in x..x + w {
                if *self.labels.at_2d::<i32>(v, u)? == label {
                    let p = image.at_2d::<cv::Vec3b>(v, u)?;
                    for (s, c) in sum.iter_mut().zip(p.0) {
                        *s += c as f64;
                    }
                    n += 1.0;
                }
            }
        }
        Ok(sum.map(|s| s / n.max(1.0)))
    }

    /// Thresholds `self.both`, closes one-pixel gaps and labels the blobs; the count
    /// (label 0 is the background).
    fn blobs(&mut self, threshold: f64) -> opencv::Result<i32> {
        opencv::imgproc::threshold(
            &self.both,
            &mut self.mask,
            threshold,
            255.0,
            opencv::imgproc::THRESH_BINARY,
        )?;
        let kernel = cv::Mat::default();
        let mut closed = cv::Mat::default();
        opencv::imgproc::morphology_ex_def(
            &self.mask,
            &mut closed,
            opencv::imgproc::MORPH_CLOSE,
            &kernel,
        )?;
        opencv::imgproc::connected_components_with_stats(
            &closed,
            &mut self.labels,
            &mut self.stats,
            &mut self.centroids,
            8,
            cv::CV_32S,
        )
    }

    /// The outline of the mover whose short-gap blob is `mover`, from the difference of
    /// the full-resolution `now` with `old` (registered by `old_h`) in a window around
    /// it: the blob nearest `mover`'s centre with at least `min_area` pixels, and its
    /// top (see the module). `None` when nothing in the window changed enough.
    pub fn outline(
        &mut self,
        now: &cv::Mat,
        (old, old_h): (&cv::Mat, &Matrix3<f64>),
        mover: &Mover,
        threshold: f64,
        min_area: i32,
    ) -> opencv::Result<Option<Mover>> {
        let [bx, by, bw, bh] = mover.bbox;
        let margin = 2.0 * bw.max(bh);
        let (cols, rows) = (now.cols(), now.rows());
        let x0 = ((bx - margin).floor() as i32).clamp(0, cols - 1);
        let y0 = ((by - margin).floor() as i32).clamp(0, rows - 1);
        let x1 = ((bx + bw + margin).ceil() as i32).clamp(x0 + 1, cols);
        let y1 = ((by + bh + margin).ceil() as i32).clamp(y0 + 1, rows);
        let rect = cv::Rect::new(x0, y0, x1 - x0, y1 - y0);
        let window = cv::Mat::roi(now, rect)?.try_clone()?;
        let shift = Matrix3::new(1.0, 0.0, -x0 as f64, 0.0, 1.0, -y0 as f64, 0.0, 0.0, 1.0);
        self.difference(&window, old, &(shift * old_h), 0)?;
        self.diff[0].copy_to(&mut self.both)?;
        let n = self.blobs(threshold)?;
        let (mx, my) = (mover.centre[0] - x0 as f64, mover.centre[1] - y0 as f64);
        let mut best: Option<(f64, i32)> = None;
        for i in 1..n {
            if *self.stats.at_2d::<i32>(i, opencv::imgproc::CC_STAT_AREA)? < min_area {
                continue;
            }
            let (cx, cy) = (
                *self.centroids.at_2d::<f64>(i, 0)?,
                *self.centroids.at_2d::<f64>(i, 1)?,
            );
            let d = (cx - mx).hypot(cy - my);
            let at = [cx + x0 as f64, cy + y0 as f64];
            if !covered(old_h, old.size()?, at) {
                continue;
            }
            if best.is_none_or(|(b, _)| d < b) {
                best = Some((d, i));
            }
        }
        let Some((_, label)) = best else {
            return Ok(None);
        };
        let stat = |k: i32| self.stats.at_2d::<i32>(label, k).map(|v| *v as f64);
        let bbox = [
            stat(opencv::imgproc::CC_STAT_LEFT)? + x0 as f64,
            stat(opencv::imgproc::CC_STAT_TOP)? + y0 as f64,
            stat(opencv::imgproc::CC_STAT_WIDTH)?,
            stat(opencv::imgproc::CC_STAT_HEIGHT)?,
        ];
        let area = stat(opencv::imgproc::CC_STAT_AREA)?;
        let label_box = [0, 1, 2, 3].map(|i| bbox[i] as i32 - [x0, y0, 0, 0][i]);
        let centre = top_centre(&window, &self.labels, label, label_box)?.unwrap_or([
            *self.centroids.at_2d::<f64>(label, 0)?,
            *self.centroids.at_2d::<f64>(label, 1)?,
        ]);
        Ok(Some(Mover {
            centre: [centre[0] + x0 as f64, centre[1] + y0 as f64],
            bbox,
            area_px: area,
            bgr: mover.bgr,
        }))
    }
}

/// Whether the pixel `p` of the newest frame was seen by an old frame of `size` that
/// `h` maps onto it, 2 pixels inside its border (outside, the warp replicated the
/// border and any difference there is not motion).
fn covered(h: &Matrix3<f64>, size: cv::Size, p: [f64; 2]) -> bool {
    let Some(back) = h.try_inverse() else {
        return false;
    };
    let q = back * Vector3::new(p[0], p[1], 1.0);
    if q.z.abs() < 1e-12 {
        return false;
    }
    let (u, v) = (q.x / q.z, q.y / q.z);
    u >= 2.0 && v >= 2.0 && u <= size.width as f64 - 3.0 && v <= size.height as f64 - 3.0
}

/// Smallest brightness step between a box's top and its sides that the split trusts.
const MIN_TOP_STEP: f64 = 20.0;

/// The centroid of the brighter part of the blob `label` of `labels`, inside its
/// bounding box (left, top, width, height) (brightness: the largest channel of `window`), split at Otsu's threshold, when the two parts' means
/// differ by at least [`MIN_TOP_STEP`] and the brighter one holds at least 30 % of the
/// blob; window coordinates.
fn top_centre(
    window: &cv::Mat,
    labels: &cv::Mat,
    label: i32,
    [bx, by, bw, bh]: [i32; 4],
) -> opencv::Result<Option<[f64; 2]>> {
    let mut pixels: Vec<(i32, i32, u8)> = Vec::with_capacity((bw * bh).max(0) as usize);
    for y in by..by + bh {
        for x in bx..bx + bw {
            if *labels.at_2d::<i32>(y, x)? == label {
                let p = window.at_2d::<cv::Vec3b>(y, x)?;
                pixels.push((x, y, p[0].max(p[1]).max(p[2])));
            }
        }
    }
    let Some(t) = otsu(pixels.iter().map(|p| p.2)) else {
        return Ok(None);
    };
    // Sums of x, y, brightness and the count, above and at-or-below the threshold.
    let (mut hi, mut lo) = ([0.0; 4], [0.0; 4]);
    for &(x, y, v) in &pixels {
        let part = if v > t { &mut hi } else { &mut lo };
        for (s, a) in part.iter_mut().zip([x as f64, y as f64, v as f64, 1.0]) {
            *s += a;
        }
    }
    if lo[3] == 0.0 || hi[3] == 0.0 {
        return Ok(None);
    }
    let step = hi[2] / hi[3] - lo[2] / lo[3];
    if step < MIN_TOP_STEP || hi[3] < 0.3 * (hi[3] + lo[3]) {
        return Ok(None);
    }
    Ok(Some([hi[0] / hi[3], hi[1] / hi[3]]))
}

/// Otsu's threshold of 8-bit values: the level that maximises the between-class
/// variance of `≤ t` and `> t`; `None` for fewer than two distinct values.
pub fn otsu(values: impl Iterator<Item = u8>) -> Option<u8> {
    let mut hist = [0u64; 256];
    let mut n = 0u64;
    for v in values {
        hist[v as usize] += 1;
        n += 1;
    }
    let total: f64 = hist
        .iter()
        .enumerate()
        .map(|(i, c)| i as f64 * *c as f64)
        .sum();
    let (mut w0, mut sum0, mut best) = (0u64, 0.0, None::<(f64, u8)>);
    for (t, count) in hist.iter().enumerate().take(255) {
        w0 += count;
        sum0 += t as f64 * *count as f64;
        let w1 = n - w0;
        if w0 == 0 || w1 == 0 {
            continue;
        }
        let (m0, m1) = (sum0 / w0 as f64, (total - sum0) / w1 as f64);
        let between = w0 as f64 * w1 as f64 * (m0 - m1).powi(2);
        if best.is_none_or(|(b, _)| between > b) {
            best = Some((between, t as u8));
        }
    }
    best.map(|(_, t)| t)
}

#[cfg(test)]
mod tests {
    use super::*;

    use super::super::test_scene;

    fn shift(dx: f64) -> Matrix3<f64> {
        Matrix3::new(1.0, 0.0, dx, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    }

    #[test]
    fn a_box_moving_over_moving_ground_is_the_only_mover() {
        // The ground moves 2 px a frame; the box 4 px a frame on top of that; frames 0,
        // 10 and 20 (the newest). A second box is parked: it moves with the ground.
        let ground = test_scene::ground(320, 240, 99);
        let frame = |k: i32| {
            let mut f = test_scene::shifted(&ground, 2.0 * k as f64, 0.0);
            let silver = [200.0, 200.0, 205.0];
            test_scene::draw_box(&mut f, cv::Rect::new(100 + 6 * k, 120, 12, 6), silver);
            test_scene::draw_box(&mut f, cv::Rect::new(40 + 2 * k, 60, 12, 6), silver);
            f
        };
        let (now, near, far) = (frame(20), frame(10), frame(0));
        let mut d = Differencer::default();
        let mut out = Vec::new();
        d.movers(
            &now,
            (&near, &shift(20.0)),
            (&far, &shift(40.0)),
            30.0,
            (3, 12),
            &Matrix3::identity(),
            &mut out,
        )
        .unwrap();
        assert_eq!(out.len(), 1, "{out:?}");
        // The box now spans x 220..232, y 120..126: its part not covered 10 frames
        // ago (by then at 160..172, carried to 180..192) is all of it.
        let m = out[0];
        assert!(
            (m.centre[0] - 225.5).abs() < 1.0 && (m.centre[1] - 122.5).abs() < 1.0,
            "{m:?}"
        );
        assert!(m.bgr[0] > 150.0, "{m:?}");
        // Its outline from the far frame is the whole box.
        let o = d
            .outline(&now, (&far, &shift(40.0)), &m, 30.0, 20)
            .unwrap()
            .unwrap();
        assert!(
            (o.centre[0] - 225.5).abs() < 0.3 && (o.centre[1] - 122.5).abs() < 0.3,
            "{o:?}"
        );
    }

    #[test]
    fn only_pixels_an_old_frame_saw_are_covered() {
        let size = cv::Size::new(100, 80);
        assert!(covered(&shift(10.0), size, [50.0, 40.0]));
        assert!(!covered(&shift(10.0), size, [5.0, 40.0]));
        assert!(covered(&shift(-10.0), size, [5.0, 40.0]));
        assert!(!covered(&shift(-10.0), size, [95.0, 40.0]));
    }

    #[test]
    fn otsu_splits_two_levels_between_them() {
        let v = [10u8, 12, 11, 200, 201, 199, 10];
        let t = otsu(v.into_iter()).unwrap();
        assert!((12..199).contains(&t), "{t}");
        assert_eq!(otsu([5u8, 5, 5].into_iter()), None);
    }
}
