//! The pixels of some hue intervals, saturated and bright enough, and their connected
//! components: what the colour detector (`colour_blob.rs`) and the other vehicles'
//! colours (`other_colours.rs`) both look for. The buffers are kept from frame to frame,
//! so nothing is allocated per frame once they have their size.

use opencv::core as cv;

/// An HSV image and the buffers of its thresholds and components (as OpenCV's
/// `connected_components_with_stats` fills `labels`, `stats` and `centroids`).
#[derive(Default)]
pub(crate) struct Scratch {
    pub hsv: cv::Mat,
    pub mask: cv::Mat,
    pub part: cv::Mat,
    pub combined: cv::Mat,
    pub labels: cv::Mat,
    pub stats: cv::Mat,
    pub centroids: cv::Mat,
}

impl Scratch {
    /// Thresholds `hsv` to the hue intervals `hues` (OpenCV's 0–180) with saturation
    /// and value at least `saturation_min` and `value_min`, into `mask`, and labels its
    /// 8-connected components. Returns the number of labels (0 is the background).
    pub fn label(
        &mut self,
        hues: &[[u8; 2]],
        saturation_min: f64,
        value_min: f64,
    ) -> opencv::Result<i32> {
        self.threshold(hues, saturation_min, value_min)?;
        self.components()
    }

    /// `mask` = the pixels of `hsv` in the hue intervals `hues` with saturation and value
    /// at least `saturation_min` and `value_min` (all zero when `hues` is empty).
    pub fn threshold(
        &mut self,
        hues: &[[u8; 2]],
        saturation_min: f64,
        value_min: f64,
    ) -> opencv::Result<()> {
        if hues.is_empty() {
            // An empty range: all zeros, in `mask`'s own buffer (no allocation per frame).
            let (above, below) = (cv::Scalar::all(1.0), cv::Scalar::all(0.0));
            return cv::in_range(&self.hsv, &above, &below, &mut self.mask);
        }
        for (i, [lo, hi]) in hues.iter().enumerate() {
            let low = cv::Scalar::new(*lo as f64, saturation_min, value_min, 0.0);
            let high = cv::Scalar::new(*hi as f64, 255.0, 255.0, 0.0);
            if i == 0 {
                cv::in_range(&self.hsv, &low, &high, &mut self.mask)?;
            } else {
                cv::in_range(&self.hsv, &low, &high, &mut self.part)?;
                cv::bitwise_or_def(&self.mask, &self.part, &mut self.combined)?;
                std::mem::swap(&mut self.mask, &mut self.combined);
            }
        }
        Ok(())
    }

    /// `mask` |= `extra` (same size, 8-bit).
    pub fn add_to_mask(&mut self, extra: &cv::Mat) -> opencv::Result<()> {
        cv::bitwise_or_def(&self.mask, extra, &mut self.combined)?;
        std::mem::swap(&mut self.mask, &mut self.combined);
        Ok(())
    }

    /// Labels the 8-connected components of `mask`. Returns the number of labels (0 is
    /// the background).
    pub fn components(&mut self) -> opencv::Result<i32> {
        opencv::imgproc::connected_components_with_stats(
            &self.mask,
            &mut self.labels,
            &mut self.stats,
            &mut self.centroids,
            8,
            cv::CV_32S,
        )
    }
}
