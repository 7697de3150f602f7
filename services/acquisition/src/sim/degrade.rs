//! What a real camera does to the image after the lens: exposure (a different gain on
//! each UAV), motion blur, sensor noise and JPEG compression, applied in that order to
//! the rendered BGR8 pixels. Deterministic: the noise comes from the preset's seed and
//! the frame's sequence number.

use super::SimError;
use opencv::core as cv;
use opencv::prelude::*;
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

/// `[image]` of a preset: every field off by default.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ImageEffects {
    /// Gain of each UAV's exposure (left, right): 1 = as rendered.
    pub exposure_gain: [f64; 2],
    /// Length of a horizontal box blur, pixels (0 = none): motion during the exposure.
    pub motion_blur_px: f64,
    /// σ of additive Gaussian sensor noise, grey levels (0 = none).
    pub noise_sigma: f64,
    /// JPEG quality the frame goes through (0 = none, 1–100).
    pub jpeg_quality: u8,
}

impl Default for ImageEffects {
    fn default() -> Self {
        Self {
            exposure_gain: [1.0, 1.0],
            motion_blur_px: 0.0,
            noise_sigma: 0.0,
            jpeg_quality: 0,
        }
    }
}

impl ImageEffects {
    pub fn is_identity(&self) -> bool {
        *self == Self::default()
    }

    pub fn validate(&self) -> Result<(), SimError> {
        let gain_ok = self
            .exposure_gain
            .iter()
            .all(|g| g.is_finite() && (0.05..=20.0).contains(g));
        let ok = gain_ok
            && self.motion_blur_px.is_finite()
            && (0.0..=50.0).contains(&self.motion_blur_px)
            && self.noise_sigma.is_finite()
            && (0.0..=100.0).contains(&self.noise_sigma)
            && self.jpeg_quality <= 100;
        if ok {
            Ok(())
        } else {
            Err(SimError::Config(format!(
                "image effects out of range (gain 0.05..=20, blur 0..=50 px, noise 0..=100, jpeg 0..=100): {self:?}"
            )))
        }
    }

    /// Applies the effects to one UAV's frame (`uav` 0 = left) in place: BGR8 rows of
    /// `stride` bytes.
    pub fn apply(
        &self,
        uav: usize,
        seed: u64,
        out: &mut [u8],
        width: usize,
        height: usize,
        stride: usize,
    ) -> Result<(), SimError> {
        if self.is_identity() {
            return Ok(());
        }
        let cv_err = |e: opencv::Error| SimError::OpenCv(e.message);
        let mut img = cv::Mat::new_rows_cols_with_default(
            height as i32,
            width as i32,
            cv::CV_8UC3,
            cv::Scalar::all(0.0),
        )
        .map_err(cv_err)?;
        {
            let bytes = img.data_bytes_mut().map_err(cv_err)?;
            for (row, dst) in bytes.chunks_exact_mut(3 * width).enumerate() {
                dst.copy_from_slice(&out[row * stride..row * stride + 3 * width]);
            }
        }
        let gain = self.exposure_gain[uav.min(1)];
        if gain != 1.0 {
            let mut scaled = cv::Mat::default();
            img.convert_to(&mut scaled, cv::CV_8UC3, gain, 0.0)
                .map_err(cv_err)?;
            img = scaled;
        }
        let blur = self.motion_blur_px.round() as i32;
        if blur >= 2 {
            let mut blurred = cv::Mat::default();
            opencv::imgproc::blur_def(&img, &mut blurred, cv::Size::new(blur, 1))
                .map_err(cv_err)?;
            img = blurred;
        }
        let bytes = img.data_bytes_mut().map_err(cv_err)?;
        if self.noise_sigma > 0.0 {
            let mut rng = StdRng::seed_from_u64(seed ^ 0x5e_50_12);
            let normal = Normal::new(0.0, self.noise_sigma)
                .map_err(|e| SimError::Config(format!("noise_sigma: {e}")))?;
            for b in bytes.iter_mut() {
                *b = (*b as f64 + normal.sample(&mut rng))
                    .round()
                    .clamp(0.0, 255.0) as u8;
            }
        }
        if self.jpeg_quality > 0 {
            let mut encoded = cv::Vector::<u8>::new();
            let params = cv::Vector::from_slice(&[
                opencv::imgcodecs::IMWRITE_JPEG_QUALITY,
                self.jpeg_quality as i32,
            ]);
            opencv::imgcodecs::imencode(".jpg", &img, &mut encoded, &params).map_err(cv_err)?;
            img = opencv::imgcodecs::imdecode(&encoded, opencv::imgcodecs::IMREAD_COLOR)
                .map_err(cv_err)?;
        }
        let bytes = img.data_bytes().map_err(cv_err)?;
        for (row, src) in bytes.chunks_exact(3 * width).enumerate() {
            out[row * stride..row * stride + 3 * width].copy_from_slice(src);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stripes(w: usize, h: usize) -> Vec<u8> {
        (0..w * h * 3)
            .map(|i| {
                if ((i / 3 % w) / 4).is_multiple_of(2) {
                    40
                } else {
                    200
                }
            })
            .collect()
    }

    #[test]
    fn identity_leaves_the_pixels_alone() {
        let mut img = stripes(32, 8);
        let before = img.clone();
        ImageEffects::default()
            .apply(0, 1, &mut img, 32, 8, 96)
            .unwrap();
        assert_eq!(img, before);
    }

    #[test]
    fn each_effect_changes_the_image_and_is_deterministic() {
        let effects = [
            ImageEffects {
                exposure_gain: [1.0, 0.5],
                ..Default::default()
            },
            ImageEffects {
                motion_blur_px: 4.0,
                ..Default::default()
            },
            ImageEffects {
                noise_sigma: 5.0,
                ..Default::default()
            },
            ImageEffects {
                jpeg_quality: 30,
                ..Default::default()
            },
        ];
        for e in effects {
            e.validate().unwrap();
            let mut a = stripes(32, 8);
            let mut b = stripes(32, 8);
            e.apply(1, 9, &mut a, 32, 8, 96).unwrap();
            e.apply(1, 9, &mut b, 32, 8, 96).unwrap();
            assert_eq!(a, b, "{e:?} not deterministic");
            assert_ne!(a, stripes(32, 8), "{e:?} changed nothing");
        }
        let bad = ImageEffects {
            noise_sigma: f64::NAN,
            ..Default::default()
        };
        assert!(bad.validate().is_err());
    }
}
