//! Lens distortion rendered into the pixels. The renderer is an exact pinhole; a
//! distorted camera's image is the pinhole image of a larger canvas (same focal
//! lengths, the principal point moved by the margin) resampled through OpenCV's model:
//! recorded pixel `p_d` shows the canvas at `undistort(p_d) + margin`. The map is
//! computed once per camera.

use super::SimError;
use shared_types::conventions::Intrinsics;
use shared_types::lens::Distortion;

/// The resampling map of one distorted camera.
#[derive(Debug, Clone)]
pub struct LensMap {
    /// Canvas size and the offset of the image's origin in it, pixels.
    pub canvas: [usize; 2],
    pub margin: [usize; 2],
    /// For each recorded pixel (row-major), the canvas position it samples.
    source: Vec<[f32; 2]>,
    width: usize,
}

impl LensMap {
    /// The map of a `width` × `height` camera with `k` and `lens`; an error when the
    /// lens model cannot be inverted somewhere in the image (coefficients too strong).
    pub fn new(
        k: &Intrinsics,
        lens: &Distortion,
        width: u32,
        height: u32,
    ) -> Result<Self, SimError> {
        let (w, h) = (width as usize, height as usize);
        let mut source = Vec::with_capacity(w * h);
        let (mut lo, mut hi) = ([0.0f64; 2], [w as f64 - 1.0, h as f64 - 1.0]);
        for v in 0..h {
            for u in 0..w {
                let [x, y] = lens.undistort_pixel(k, u as f64, v as f64).ok_or_else(|| {
                    SimError::Config(format!(
                        "camera distortion {:?} cannot be inverted at pixel ({u}, {v})",
                        lens.0
                    ))
                })?;
                lo = [lo[0].min(x), lo[1].min(y)];
                hi = [hi[0].max(x), hi[1].max(y)];
                source.push([x as f32, y as f32]);
            }
        }
        // Two pixels more than the farthest sample, for the bilinear neighbours.
        let margin_for = |lo: f64, hi: f64, size: usize| {
            let need = (-lo).max(hi - (size as f64 - 1.0)).max(0.0);
            need.ceil() as usize + 2
        };
        let margin = [margin_for(lo[0], hi[0], w), margin_for(lo[1], hi[1], h)];
        if margin[0] > 2 * w || margin[1] > 2 * h {
            return Err(SimError::Config(format!(
                "camera distortion {:?} needs a canvas over 5x the image",
                lens.0
            )));
        }
        for s in &mut source {
            s[0] += margin[0] as f32;
            s[1] += margin[1] as f32;
        }
        Ok(Self {
            canvas: [w + 2 * margin[0], h + 2 * margin[1]],
            margin,
            source,
            width: w,
        })
    }

    /// The pinhole camera to render the canvas with.
    pub fn canvas_intrinsics(&self, k: &Intrinsics) -> Intrinsics {
        Intrinsics::new(
            k.fx,
            k.fy,
            k.cx + self.margin[0] as f64,
            k.cy + self.margin[1] as f64,
        )
    }

    /// Resamples a rendered BGR8 canvas (packed rows) into the recorded image (rows of
    /// `stride` bytes), bilinearly.
    pub fn resample(&self, canvas: &[u8], out: &mut [u8], stride: usize) {
        let cw = self.canvas[0];
        for (v, row_sources) in self.source.chunks_exact(self.width).enumerate() {
            let row = &mut out[v * stride..v * stride + 3 * self.width];
            for (u, s) in row_sources.iter().enumerate() {
                let (x0, y0) = (s[0].floor(), s[1].floor());
                let (fx, fy) = (s[0] - x0, s[1] - y0);
                let (x0, y0) = (x0 as usize, y0 as usize);
                let at = |x: usize, y: usize, c: usize| canvas[(y * cw + x) * 3 + c] as f32;
                for c in 0..3 {
                    let top = at(x0, y0, c) * (1.0 - fx) + at(x0 + 1, y0, c) * fx;
                    let bottom = at(x0, y0 + 1, c) * (1.0 - fx) + at(x0 + 1, y0 + 1, c) * fx;
                    row[3 * u + c] = (top * (1.0 - fy) + bottom * fy + 0.5) as u8;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_distorted_image_samples_where_the_model_says() {
        let k = Intrinsics::from_hfov(64, 48, 70.0);
        let lens = Distortion([-0.3, 0.1, 0.0, 0.0, 0.0]);
        let map = LensMap::new(&k, &lens, 64, 48).unwrap();
        assert!(map.margin[0] > 2 && map.margin[1] > 2, "{:?}", map.margin);
        // A canvas whose blue channel is its column and green its row: the resampled
        // image must show, at each pixel, the canvas position of its undistorted point.
        let [cw, ch] = map.canvas;
        let mut canvas = vec![0u8; cw * ch * 3];
        for y in 0..ch {
            for x in 0..cw {
                canvas[(y * cw + x) * 3] = (x % 256) as u8;
                canvas[(y * cw + x) * 3 + 1] = (y % 256) as u8;
            }
        }
        let mut out = vec![0u8; 64 * 48 * 3];
        map.resample(&canvas, &mut out, 64 * 3);
        let kc = map.canvas_intrinsics(&k);
        for (u, v) in [(0usize, 0usize), (63, 0), (31, 24), (10, 40)] {
            let [x, y] = lens.undistort_pixel(&k, u as f64, v as f64).unwrap();
            let (x, y) = (x - k.cx + kc.cx, y - k.cy + kc.cy);
            let got = [
                out[(v * 64 + u) * 3] as f64,
                out[(v * 64 + u) * 3 + 1] as f64,
            ];
            assert!(
                (got[0] - x).abs() < 0.6 && (got[1] - y).abs() < 0.6,
                "({u},{v}): {got:?} vs ({x},{y})"
            );
        }
    }

    #[test]
    fn an_impossible_lens_is_a_config_error() {
        let k = Intrinsics::from_hfov(64, 48, 120.0);
        let e = LensMap::new(&k, &Distortion([5.0, 5.0, 0.0, 0.0, 5.0]), 64, 48);
        assert!(e.is_err());
    }
}
