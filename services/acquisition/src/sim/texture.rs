//! Procedural BGR textures sampled in metres, with bilinear filtering. Everything is a
//! pure function of a seed, so the same seed renders the same town.

/// A BGR8 texture mapped onto a plane at `metres_per_texel`, repeating outside.
#[derive(Debug, Clone)]
pub struct Texture {
    width: usize,
    height: usize,
    metres_per_texel: f64,
    data: Vec<u8>,
}

impl Texture {
    /// Fills a `width × height` texture from `texel(x_m, y_m) -> BGR`, rows split over
    /// all cores; `texel` must be a pure function of its position.
    pub fn generate(
        width: usize,
        height: usize,
        metres_per_texel: f64,
        texel: impl Fn(f64, f64) -> [u8; 3] + Sync,
    ) -> Self {
        let mut data = vec![0u8; width * height * 3];
        let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
        let rows_per_chunk = height.div_ceil(threads).max(1);
        std::thread::scope(|s| {
            for (chunk, rows) in data.chunks_mut(rows_per_chunk * width * 3).enumerate() {
                let texel = &texel;
                s.spawn(move || {
                    for (k, px) in rows.chunks_exact_mut(3).enumerate() {
                        let (row, col) = (chunk * rows_per_chunk + k / width, k % width);
                        let (x, y) = (col as f64 * metres_per_texel, row as f64 * metres_per_texel);
                        px.copy_from_slice(&texel(x, y));
                    }
                });
            }
        });
        Self {
            width,
            height,
            metres_per_texel,
            data,
        }
    }

    /// Wraps an existing BGR8 image (e.g. a user's orthophoto).
    pub fn from_bgr(width: usize, height: usize, metres_per_texel: f64, data: Vec<u8>) -> Self {
        assert_eq!(data.len(), width * height * 3, "BGR buffer size");
        Self {
            width,
            height,
            metres_per_texel,
            data,
        }
    }

    /// The texture with its contrast about each channel's mean scaled by `k` (1 = as is).
    pub fn with_contrast(mut self, k: f64) -> Self {
        if k == 1.0 || self.data.is_empty() {
            return self;
        }
        let texels = (self.data.len() / 3) as f64;
        let mean: [f64; 3] = std::array::from_fn(|c| {
            self.data
                .iter()
                .skip(c)
                .step_by(3)
                .map(|v| *v as f64)
                .sum::<f64>()
                / texels
        });
        for (i, v) in self.data.iter_mut().enumerate() {
            let m = mean[i % 3];
            *v = clamp_u8(m + k * (*v as f64 - m));
        }
        self
    }

    pub fn texel_mut(&mut self, col: usize, row: usize) -> &mut [u8] {
        let i = (row * self.width + col) * 3;
        &mut self.data[i..i + 3]
    }

    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    pub fn metres_per_texel(&self) -> f64 {
        self.metres_per_texel
    }

    /// Bilinear sample at (x, y) metres from the texture origin; repeats outside.
    #[inline]
    pub fn sample(&self, x_m: f64, y_m: f64) -> [f32; 3] {
        let fx = x_m / self.metres_per_texel;
        let fy = y_m / self.metres_per_texel;
        let x0 = fx.floor();
        let y0 = fy.floor();
        let (ax, ay) = ((fx - x0) as f32, (fy - y0) as f32);
        let (w, h) = (self.width as i64, self.height as i64);
        let xa = (x0 as i64).rem_euclid(w) as usize;
        let ya = (y0 as i64).rem_euclid(h) as usize;
        let xb = if xa + 1 == self.width { 0 } else { xa + 1 };
        let yb = if ya + 1 == self.height { 0 } else { ya + 1 };
        let at = |x: usize, y: usize| (y * self.width + x) * 3;
        let (p00, p10, p01, p11) = (at(xa, ya), at(xb, ya), at(xa, yb), at(xb, yb));
        let d = &self.data;
        let mut out = [0.0f32; 3];
        for (c, o) in out.iter_mut().enumerate() {
            let top = d[p00 + c] as f32 * (1.0 - ax) + d[p10 + c] as f32 * ax;
            let bottom = d[p01 + c] as f32 * (1.0 - ax) + d[p11 + c] as f32 * ax;
            *o = top * (1.0 - ay) + bottom * ay;
        }
        out
    }
}

/// A 64-bit integer hash (splitmix64 finaliser).
#[inline]
pub fn hash(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    x ^ (x >> 31)
}

/// Hash of a lattice point to [0, 1).
#[inline]
fn lattice(seed: u64, ix: i64, iy: i64) -> f64 {
    let h = hash(seed ^ hash((ix as u64).wrapping_mul(0x1f1f_1f1f) ^ hash(iy as u64)));
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// Smooth value noise in [0, 1) with features of about `scale_m` metres.
pub fn value_noise(seed: u64, x_m: f64, y_m: f64, scale_m: f64) -> f64 {
    let (fx, fy) = (x_m / scale_m, y_m / scale_m);
    let (x0, y0) = (fx.floor(), fy.floor());
    let (ix, iy) = (x0 as i64, y0 as i64);
    let s = |t: f64| t * t * (3.0 - 2.0 * t);
    let (tx, ty) = (s(fx - x0), s(fy - y0));
    let v00 = lattice(seed, ix, iy);
    let v10 = lattice(seed, ix + 1, iy);
    let v01 = lattice(seed, ix, iy + 1);
    let v11 = lattice(seed, ix + 1, iy + 1);
    let top = v00 + (v10 - v00) * tx;
    let bottom = v01 + (v11 - v01) * tx;
    top + (bottom - top) * ty
}

/// Sum of octaves of value noise, normalised to [0, 1).
pub fn fractal_noise(seed: u64, x_m: f64, y_m: f64, scales_m: &[f64]) -> f64 {
    let mut sum = 0.0;
    let mut weight = 0.0;
    for (k, scale) in scales_m.iter().enumerate() {
        let w = 1.0 / (k as f64 + 1.0);
        sum += w * value_noise(seed.wrapping_add(k as u64 * 7919), x_m, y_m, *scale);
        weight += w;
    }
    sum / weight
}

pub fn clamp_u8(v: f64) -> u8 {
    v.clamp(0.0, 255.0) as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bilinear_sample_interpolates_and_repeats() {
        let t = Texture::from_bgr(2, 1, 1.0, vec![0, 0, 0, 100, 200, 50]);
        assert_eq!(t.sample(0.0, 0.0), [0.0, 0.0, 0.0]);
        assert_eq!(t.sample(0.5, 0.0), [50.0, 100.0, 25.0]);
        assert_eq!(t.sample(2.0, 0.0), [0.0, 0.0, 0.0]); // wraps
        assert_eq!(t.sample(-1.0, 0.0), [100.0, 200.0, 50.0]);
    }

    #[test]
    fn noise_is_deterministic_and_bounded() {
        for i in 0..1000 {
            let (x, y) = (i as f64 * 0.37, i as f64 * -1.3);
            let v = fractal_noise(5, x, y, &[8.0, 2.0, 0.5]);
            assert!((0.0..1.0).contains(&v));
            assert_eq!(v, fractal_noise(5, x, y, &[8.0, 2.0, 0.5]));
        }
        assert_ne!(value_noise(1, 3.3, 4.4, 1.0), value_noise(2, 3.3, 4.4, 1.0));
    }
}
