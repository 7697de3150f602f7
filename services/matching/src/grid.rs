//! A bucket grid over keypoint positions: the keypoints in a window around a pixel
//! without scanning them all (guided matching, [`crate::hamming::knn2_within`]).

/// Keypoint indices bucketed by square cells of `cell` pixels (counting sort).
#[derive(Debug, Clone, Default)]
pub struct PointGrid {
    cell: f32,
    cols: usize,
    rows: usize,
    /// `order[start[c]..start[c + 1]]`: the keypoints in cell `c` (row-major).
    start: Vec<u32>,
    order: Vec<u32>,
    points: Vec<[f32; 2]>,
}

impl PointGrid {
    /// Buckets `points` (pixels). Points outside `[0, width) × [0, height)` are clamped
    /// into the border cells, so none is lost.
    pub fn new(points: &[[f32; 2]], width: u32, height: u32, cell: f32) -> Self {
        let cell = cell.max(1.0);
        let cols = ((width as f32 / cell).ceil() as usize).max(1);
        let rows = ((height as f32 / cell).ceil() as usize).max(1);
        let mut grid = Self {
            cell,
            cols,
            rows,
            start: vec![0; cols * rows + 1],
            order: vec![0; points.len()],
            points: points.to_vec(),
        };
        let cells: Vec<usize> = points.iter().map(|p| grid.cell_of(p)).collect();
        for &c in &cells {
            grid.start[c + 1] += 1;
        }
        for c in 0..cols * rows {
            grid.start[c + 1] += grid.start[c];
        }
        let mut fill = grid.start.clone();
        for (i, &c) in cells.iter().enumerate() {
            grid.order[fill[c] as usize] = i as u32;
            fill[c] += 1;
        }
        grid
    }

    fn cell_of(&self, p: &[f32; 2]) -> usize {
        let clamp = |v: f32, n: usize| ((v / self.cell).floor().max(0.0) as usize).min(n - 1);
        clamp(p[1], self.rows) * self.cols + clamp(p[0], self.cols)
    }

    /// Calls `f` with the index of every point in the square window of half-side
    /// `radius` around `centre`.
    pub fn for_each_near(&self, centre: [f32; 2], radius: f32, mut f: impl FnMut(usize)) {
        if self.order.is_empty() || !centre.iter().all(|v| v.is_finite()) {
            return;
        }
        let span = |v: f32, n: usize| {
            // Clamped like the points were, so border cells hold what lies beyond.
            let at = |v: f32| ((v / self.cell).floor().max(0.0) as usize).min(n - 1);
            (at(v - radius), at(v + radius))
        };
        let ((c0, c1), (r0, r1)) = (span(centre[0], self.cols), span(centre[1], self.rows));
        for r in r0..=r1 {
            let (a, b) = (
                self.start[r * self.cols + c0] as usize,
                self.start[r * self.cols + c1 + 1] as usize,
            );
            for &i in &self.order[a..b] {
                let p = self.points[i as usize];
                if (p[0] - centre[0]).abs() <= radius && (p[1] - centre[1]).abs() <= radius {
                    f(i as usize);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_exactly_the_points_a_scan_finds() {
        let mut points = Vec::new();
        let mut s = 1u64;
        for _ in 0..400 {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let x = (s >> 40) as f32 / (1u64 << 24) as f32 * 660.0 - 10.0;
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let y = (s >> 40) as f32 / (1u64 << 24) as f32 * 500.0 - 10.0;
            points.push([x, y]);
        }
        let grid = PointGrid::new(&points, 640, 480, 32.0);
        for centre in [
            [0.0, 0.0],
            [320.5, 240.2],
            [639.0, 479.0],
            [700.0, -50.0],
            [100.0, 460.0],
        ] {
            let r = 40.0;
            let mut found = Vec::new();
            grid.for_each_near(centre, r, |i| found.push(i));
            found.sort();
            let len = found.len();
            found.dedup();
            assert_eq!(found.len(), len, "a point reported twice");
            for (i, p) in points.iter().enumerate() {
                let inside = (p[0] - centre[0]).abs() <= r && (p[1] - centre[1]).abs() <= r;
                assert_eq!(found.contains(&i), inside, "{p:?} near {centre:?}");
            }
        }
        let mut none = 0;
        grid.for_each_near([f32::NAN, 0.0], 10.0, |_| none += 1);
        assert_eq!(none, 0);
    }
}
