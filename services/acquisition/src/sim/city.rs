//! The simulated town: a grid of roads, box buildings 5–40 m tall in the blocks between
//! them, and procedural textures rich enough for ORB (asphalt with lane markings,
//! sidewalks with slab joints, grass with shrubs and parked cars, gravel roofs with
//! vents, facades with windows). Tall buildings stand in the middle of their block, so
//! two UAVs 70 m apart at 100 m rarely lose the vehicle behind a facade.

use super::texture::{clamp_u8, fractal_noise, hash, value_noise, Texture};
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CityConfig {
    pub seed: u64,
    /// The textured ground covers [−half_extent, half_extent]² (it repeats beyond).
    pub half_extent_m: f64,
    /// Distance between parallel road centrelines.
    pub block_m: f64,
    pub road_width_m: f64,
    pub sidewalk_m: f64,
    /// Ground altitude (ENU z), metres.
    pub ground_z_m: f64,
    pub ground_metres_per_texel: f64,
    /// Height range of the buildings on a block's outer lots, metres.
    pub height_m: [f64; 2],
    /// Height range of the building on a block's central lot, metres.
    pub central_height_m: [f64; 2],
    /// Share of lots left empty (yards, car parks, fields).
    pub empty_lot_share: f64,
    /// Contrast of the procedural textures about their mean (1 = as designed; below 1
    /// a washed-out, low-texture scene for ORB).
    pub texture_contrast: f64,
    /// Scale of a `roof_image` photograph tiled over the roofs, metres per pixel.
    pub roof_image_metres_per_pixel: f64,
}

impl Default for CityConfig {
    fn default() -> Self {
        Self {
            seed: 1,
            half_extent_m: 320.0,
            block_m: 90.0,
            road_width_m: 16.0,
            sidewalk_m: 4.0,
            ground_z_m: 12.0,
            ground_metres_per_texel: 0.2,
            height_m: [5.0, 25.0],
            central_height_m: [15.0, 40.0],
            empty_lot_share: 0.15,
            texture_contrast: 1.0,
            roof_image_metres_per_pixel: 0.1,
        }
    }
}

impl CityConfig {
    /// Checks the layout knobs (the dimensions are checked by the scenario).
    pub fn validate_layout(&self) -> Result<(), String> {
        let range_ok =
            |r: [f64; 2]| r[0].is_finite() && r[1].is_finite() && r[0] > 0.0 && r[1] >= r[0];
        if !range_ok(self.height_m) || !range_ok(self.central_height_m) {
            return Err(
                "city height_m and central_height_m must be [min, max] with 0 < min <= max".into(),
            );
        }
        if !(0.0..=1.0).contains(&self.empty_lot_share) {
            return Err("city empty_lot_share must be within 0..=1".into());
        }
        if !(self.texture_contrast.is_finite() && (0.0..=4.0).contains(&self.texture_contrast)) {
            return Err("city texture_contrast must be within 0..=4".into());
        }
        if !(self.roof_image_metres_per_pixel.is_finite() && self.roof_image_metres_per_pixel > 0.0)
        {
            return Err("city roof_image_metres_per_pixel must be > 0".into());
        }
        Ok(())
    }
}

/// An axis-aligned box building.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Building {
    pub min: [f64; 2],
    pub max: [f64; 2],
    pub height_m: f64,
    /// Multiplier of the roof and facade textures, per channel (BGR).
    pub tint: [f32; 3],
    /// Offset into the shared roof/facade textures so buildings do not look alike.
    pub texture_offset: [f64; 2],
    /// False for a deck on pillars (a bridge, a canopy): only its top is drawn, and what
    /// is below it is hidden from above but not from the side.
    pub walls: bool,
}

/// An overpass, canopy or dense tree crown over the road: a flat deck at `height_m`
/// covering `[centre ± size/2]`, under which the target disappears from both UAVs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Occluder {
    pub centre: [f64; 2],
    pub size: [f64; 2],
    pub height_m: f64,
}

impl Occluder {
    pub fn is_valid(&self) -> bool {
        let finite = self.centre.iter().chain(&self.size).all(|v| v.is_finite());
        finite
            && self.size.iter().all(|s| *s > 0.0)
            && self.height_m.is_finite()
            && self.height_m > 0.0
    }
}

pub struct City {
    pub config: CityConfig,
    pub buildings: Vec<Building>,
    /// Height of the tallest building, metres (bounds the footprint the renderer culls to).
    pub tallest_m: f64,
    pub ground: Texture,
    pub roof: Texture,
    pub facade: Texture,
}

impl City {
    pub fn generate(config: CityConfig) -> Self {
        let buildings = layout_buildings(&config);
        let contrast = config.texture_contrast;
        Self {
            tallest_m: buildings.iter().map(|b| b.height_m).fold(0.0, f64::max),
            ground: ground_texture(&config, &buildings).with_contrast(contrast),
            roof: roof_texture(config.seed).with_contrast(contrast),
            facade: facade_texture(config.seed).with_contrast(contrast),
            buildings,
            config,
        }
    }

    /// Adds decks over the scene (after the textures: nothing is painted under them).
    pub fn with_occluders(mut self, occluders: &[Occluder]) -> Self {
        for o in occluders {
            let half = [o.size[0] / 2.0, o.size[1] / 2.0];
            self.buildings.push(Building {
                min: [o.centre[0] - half[0], o.centre[1] - half[1]],
                max: [o.centre[0] + half[0], o.centre[1] + half[1]],
                height_m: o.height_m,
                tint: [0.8, 0.85, 0.8],
                texture_offset: [o.centre[0], o.centre[1]],
                walls: false,
            });
            self.tallest_m = self.tallest_m.max(o.height_m);
        }
        self
    }

    /// Replaces the procedural roof texture by a photograph (BGR8), tiled.
    pub fn with_roof_image(mut self, width: usize, height: usize, bgr: Vec<u8>) -> Self {
        self.roof = Texture::from_bgr(width, height, self.config.roof_image_metres_per_pixel, bgr);
        self
    }

    /// Replaces the procedural ground by a user orthophoto (BGR8) covering the map.
    pub fn with_ground_image(mut self, width: usize, height: usize, bgr: Vec<u8>) -> Self {
        let mpt = 2.0 * self.config.half_extent_m / width.max(height) as f64;
        self.ground = Texture::from_bgr(width, height, mpt, bgr);
        self
    }

    /// Ground colour at world (x, y).
    #[inline]
    pub fn ground_colour(&self, x: f64, y: f64) -> [f32; 3] {
        let h = self.config.half_extent_m;
        self.ground.sample(x + h, y + h)
    }

    /// The coordinate of the road centreline nearest to `v` (roads run along x and y).
    pub fn nearest_road(&self, v: f64) -> f64 {
        (v / self.config.block_m).round() * self.config.block_m
    }

    pub fn tallest_m(&self) -> f64 {
        self.buildings
            .iter()
            .map(|b| b.height_m)
            .fold(0.0, f64::max)
    }
}

fn unit(seed: u64, k: u64) -> f64 {
    (hash(seed ^ hash(k)) >> 11) as f64 / (1u64 << 53) as f64
}

fn layout_buildings(c: &CityConfig) -> Vec<Building> {
    let mut out = Vec::new();
    let setback = c.road_width_m / 2.0 + c.sidewalk_m;
    let n = (c.half_extent_m / c.block_m).ceil() as i64;
    let mut k = 0u64;
    let mut next = || {
        k += 1;
        unit(c.seed ^ 0xb111d, k)
    };
    for bi in -n..n {
        for bj in -n..n {
            let x0 = bi as f64 * c.block_m + setback;
            let y0 = bj as f64 * c.block_m + setback;
            let size = c.block_m - 2.0 * setback;
            if size <= 6.0 {
                continue;
            }
            // 3 × 3 lots with jittered splits; the centre lot holds the tall building.
            let split = |r: f64| {
                [
                    0.0,
                    size * (0.30 + 0.08 * r),
                    size * (0.70 - 0.08 * r),
                    size,
                ]
            };
            let xs = split(next());
            let ys = split(next());
            for li in 0..3 {
                for lj in 0..3 {
                    if next() < c.empty_lot_share {
                        continue; // a yard or a car park
                    }
                    let centre = li == 1 && lj == 1;
                    let inset = |r: f64| 1.0 + 3.0 * r;
                    let min = [x0 + xs[li] + inset(next()), y0 + ys[lj] + inset(next())];
                    let max = [
                        x0 + xs[li + 1] - inset(next()),
                        y0 + ys[lj + 1] - inset(next()),
                    ];
                    if max[0] - min[0] < 4.0 || max[1] - min[1] < 4.0 {
                        continue;
                    }
                    let [lo, hi] = if centre {
                        c.central_height_m
                    } else {
                        c.height_m
                    };
                    let height_m = lo + (hi - lo) * next();
                    let grey = 0.75 + 0.35 * next() as f32;
                    let warm = 0.12 * next() as f32;
                    out.push(Building {
                        min,
                        max,
                        height_m,
                        tint: [grey * (1.0 - warm), grey, grey * (1.0 + warm)],
                        texture_offset: [400.0 * next(), 400.0 * next()],
                        walls: true,
                    });
                }
            }
        }
    }
    out
}

fn ground_texture(c: &CityConfig, buildings: &[Building]) -> Texture {
    let size = (2.0 * c.half_extent_m / c.ground_metres_per_texel).round() as usize;
    let half_road = c.road_width_m / 2.0;
    let seed = c.seed;
    let mut tex = Texture::generate(size, size, c.ground_metres_per_texel, |tx, ty| {
        let (x, y) = (tx - c.half_extent_m, ty - c.half_extent_m);
        let rx = x - (x / c.block_m).round() * c.block_m; // offset from nearest N-S road
        let ry = y - (y / c.block_m).round() * c.block_m; // offset from nearest E-W road
        let fine = fractal_noise(seed, x, y, &[6.0, 1.5, 0.4]);
        if rx.abs() < half_road || ry.abs() < half_road {
            asphalt(seed, x, y, rx, ry, half_road, fine)
        } else if rx.abs() < half_road + c.sidewalk_m || ry.abs() < half_road + c.sidewalk_m {
            let joint = (x.rem_euclid(1.5) < 0.06) || (y.rem_euclid(1.5) < 0.06);
            let v = 150.0 + 40.0 * fine - if joint { 45.0 } else { 0.0 };
            [clamp_u8(v - 4.0), clamp_u8(v), clamp_u8(v + 2.0)]
        } else {
            yard(seed, x, y, fine)
        }
    });
    // Building footprints get a dark base (their walls hide most of it anyway).
    let m = c.ground_metres_per_texel;
    for b in buildings {
        let to = |v: f64| {
            ((v + c.half_extent_m) / m)
                .round()
                .clamp(0.0, size as f64 - 1.0) as usize
        };
        for row in to(b.min[1])..=to(b.max[1]) {
            for col in to(b.min[0])..=to(b.max[0]) {
                tex.texel_mut(col, row).copy_from_slice(&[40, 42, 45]);
            }
        }
    }
    tex
}

fn asphalt(seed: u64, x: f64, y: f64, rx: f64, ry: f64, half_road: f64, fine: f64) -> [u8; 3] {
    let mut v = 62.0 + 45.0 * fine + 18.0 * value_noise(seed ^ 77, x, y, 0.25);
    let along_x = ry.abs() < half_road && rx.abs() >= half_road; // an E-W road
    let along_y = rx.abs() < half_road && ry.abs() >= half_road; // a N-S road
    let (across, along) = if along_x { (ry, x) } else { (rx, y) };
    if along_x || along_y {
        let centre_dash = across.abs() < 0.1 && along.rem_euclid(9.0) < 4.5;
        let edge_line = (across.abs() - (half_road - 0.6)).abs() < 0.1;
        let lane_dash =
            (across.abs() - half_road / 2.0).abs() < 0.08 && along.rem_euclid(6.0) < 2.0;
        if centre_dash || edge_line || lane_dash {
            v = 215.0 + 20.0 * fine;
        }
        // Patches and cracks.
        if value_noise(seed ^ 991, x, y, 3.0) > 0.82 {
            v -= 18.0;
        }
    } else {
        // Intersection: zebra crossings just inside each side.
        let near_edge = |r: f64| (half_road - r.abs()) < 3.0;
        if (near_edge(rx) && (y.rem_euclid(1.2) < 0.6))
            || (near_edge(ry) && (x.rem_euclid(1.2) < 0.6))
        {
            v = 205.0;
        }
    }
    [clamp_u8(v), clamp_u8(v), clamp_u8(v + 3.0)]
}

fn yard(seed: u64, x: f64, y: f64, fine: f64) -> [u8; 3] {
    let dirt = value_noise(seed ^ 5, x, y, 12.0);
    let mut bgr = if dirt > 0.6 {
        [70.0 + 50.0 * fine, 105.0 + 45.0 * fine, 125.0 + 50.0 * fine] // dry earth
    } else {
        [40.0 + 35.0 * fine, 95.0 + 70.0 * fine, 55.0 + 35.0 * fine] // grass
    };
    // Clutter on a 3 m lattice: shrubs (dark disks) and parked cars (rectangles).
    let (cx, cy) = ((x / 3.0).floor(), (y / 3.0).floor());
    let h = hash(seed ^ hash(cx as i64 as u64) ^ hash((cy as i64 as u64) << 1));
    let r = |k: u32| ((h >> (k * 8)) & 0xff) as f64 / 255.0;
    let (px, py) = ((cx + 0.2 + 0.6 * r(1)) * 3.0, (cy + 0.2 + 0.6 * r(2)) * 3.0);
    match h % 10 {
        0..=2 => {
            let radius = 0.4 + 0.5 * r(3);
            let d2 = (x - px).powi(2) + (y - py).powi(2);
            if d2 < radius * radius {
                let s = 0.6 + 0.4 * (d2 / (radius * radius));
                bgr = [25.0 * s, 70.0 * s, 30.0 * s];
            }
        }
        3 => {
            // A parked car, never red (red is the target's colour).
            let (hx, hy) = if r(4) < 0.5 { (1.0, 0.45) } else { (0.45, 1.0) };
            if (x - px).abs() < hx && (y - py).abs() < hy {
                let palette = [
                    [230.0, 230.0, 230.0],
                    [40.0, 40.0, 40.0],
                    [160.0, 110.0, 60.0],
                    [150.0, 150.0, 150.0],
                ];
                bgr = palette[(h >> 40) as usize % 4];
            }
        }
        _ => {}
    }
    [clamp_u8(bgr[0]), clamp_u8(bgr[1]), clamp_u8(bgr[2])]
}

fn roof_texture(seed: u64) -> Texture {
    Texture::generate(512, 512, 0.08, |x, y| {
        let g = fractal_noise(seed ^ 0x700f, x, y, &[3.0, 0.6, 0.15]);
        let mut v = 95.0 + 90.0 * g;
        // Vents and AC units on a 5 m lattice.
        let (cx, cy) = ((x / 5.0).floor(), (y / 5.0).floor());
        let h = hash(seed ^ 0xac ^ hash(cx as u64) ^ hash((cy as u64) << 1));
        if h.is_multiple_of(3) {
            let (ux, uy) = ((cx + 0.3) * 5.0, (cy + 0.3) * 5.0);
            let (w, d) = (
                0.8 + (h >> 8 & 7) as f64 * 0.2,
                0.6 + (h >> 12 & 7) as f64 * 0.2,
            );
            if x > ux && x < ux + w && y > uy && y < uy + d {
                v = if (h >> 20).is_multiple_of(2) {
                    225.0
                } else {
                    55.0
                };
            }
        }
        [clamp_u8(v), clamp_u8(v), clamp_u8(v)]
    })
}

fn facade_texture(seed: u64) -> Texture {
    Texture::generate(256, 256, 0.1, |s, z| {
        let g = fractal_noise(seed ^ 0xfacade, s, z, &[2.0, 0.4]);
        let in_window = s.rem_euclid(3.0) > 0.8
            && s.rem_euclid(3.0) < 2.2
            && z.rem_euclid(3.2) > 1.0
            && z.rem_euclid(3.2) < 2.6;
        if in_window {
            [
                clamp_u8(90.0 + 40.0 * g),
                clamp_u8(70.0 + 30.0 * g),
                clamp_u8(50.0 + 25.0 * g),
            ]
        } else {
            let v = 150.0 + 60.0 * g;
            [clamp_u8(v - 10.0), clamp_u8(v), clamp_u8(v + 8.0)]
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buildings_stay_in_blocks_and_heights_in_range() {
        let c = CityConfig {
            half_extent_m: 100.0,
            ..CityConfig::default()
        };
        let city = City::generate(c);
        assert!(city.buildings.len() > 10);
        let setback = c.road_width_m / 2.0 + c.sidewalk_m;
        for b in &city.buildings {
            assert!((5.0..=40.0).contains(&b.height_m), "{b:?}");
            for axis in 0..2 {
                for v in [b.min[axis], b.max[axis]] {
                    let off = v - city.nearest_road(v);
                    assert!(off.abs() >= setback - 1e-9, "{b:?} on a road");
                }
            }
        }
        let again = City::generate(c);
        assert_eq!(city.buildings, again.buildings);
    }
}
