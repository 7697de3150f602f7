//! Brute-force nearest neighbours of ORB descriptors by Hamming distance.
//!
//! Written by hand because OpenCV's `BFMatcher::knnMatch` spent ~2.6 ms per 500 × 500
//! pair here, mostly building nested `Vector<Vector<DMatch>>` through the bindings
//! (docs/matching.md). A descriptor is 256 bits held as four `u64`; the distance is
//! four XOR + popcounts. On x86-64 the loop is compiled a second time with the `popcnt`
//! instruction and picked at run time.

use crate::grid::PointGrid;

/// One 256-bit ORB descriptor.
pub type Descriptor = [u64; 4];

/// The best and second-best train neighbours of one query descriptor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Nearest2 {
    pub best_index: usize,
    pub best: u32,
    pub second: u32,
}

/// Packs OpenCV's 32-byte descriptor rows.
pub fn pack(row: &[u8]) -> Option<Descriptor> {
    if row.len() != 32 {
        return None;
    }
    let mut d = [0u64; 4];
    for (i, chunk) in row.chunks_exact(8).enumerate() {
        let mut bytes = [0u8; 8];
        bytes.copy_from_slice(chunk);
        d[i] = u64::from_le_bytes(bytes);
    }
    Some(d)
}

#[inline(always)]
fn distance(a: &Descriptor, b: &Descriptor) -> u32 {
    (a[0] ^ b[0]).count_ones()
        + (a[1] ^ b[1]).count_ones()
        + (a[2] ^ b[2]).count_ones()
        + (a[3] ^ b[3]).count_ones()
}

/// The two smallest distances offered so far, and the index of the smallest.
#[derive(Clone, Copy)]
struct Best2 {
    best: u32,
    second: u32,
    best_index: usize,
    seen: usize,
}

impl Best2 {
    const EMPTY: Self = Self {
        best: u32::MAX,
        second: u32::MAX,
        best_index: 0,
        seen: 0,
    };

    #[inline(always)]
    fn offer(&mut self, index: usize, d: u32) {
        self.seen += 1;
        if d < self.best {
            self.second = self.best;
            self.best = d;
            self.best_index = index;
        } else if d < self.second {
            self.second = d;
        }
    }

    /// `None` unless two candidates were offered (the ratio test needs a second).
    fn nearest2(self) -> Option<Nearest2> {
        (self.seen >= 2).then_some(Nearest2 {
            best_index: self.best_index,
            best: self.best,
            second: self.second,
        })
    }
}

#[inline(always)]
fn knn2_generic(query: &[Descriptor], train: &[Descriptor], out: &mut Vec<Option<Nearest2>>) {
    out.clear();
    out.extend(query.iter().map(|q| {
        let mut acc = Best2::EMPTY;
        for (j, t) in train.iter().enumerate() {
            acc.offer(j, distance(q, t));
        }
        acc.nearest2()
    }));
}

#[inline(always)]
fn knn2_within_generic(
    query: &[Descriptor],
    predicted: &[Option<[f32; 2]>],
    train: &[Descriptor],
    train_grid: &PointGrid,
    radius: f32,
    out: &mut Vec<Option<Nearest2>>,
) {
    out.clear();
    out.extend(query.iter().zip(predicted).map(|(q, p)| {
        let mut acc = Best2::EMPTY;
        if let Some(p) = p {
            train_grid.for_each_near(*p, radius, |j| acc.offer(j, distance(q, &train[j])));
        }
        acc.nearest2()
    }));
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "popcnt")]
fn knn2_popcnt(query: &[Descriptor], train: &[Descriptor], out: &mut Vec<Option<Nearest2>>) {
    knn2_generic(query, train, out)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "popcnt")]
fn knn2_within_popcnt(
    query: &[Descriptor],
    predicted: &[Option<[f32; 2]>],
    train: &[Descriptor],
    train_grid: &PointGrid,
    radius: f32,
    out: &mut Vec<Option<Nearest2>>,
) {
    knn2_within_generic(query, predicted, train, train_grid, radius, out)
}

/// For each query descriptor, its two nearest train descriptors (`None` when the train
/// set has fewer than two). Results go into `out` (cleared first) to reuse its buffer.
pub fn knn2(query: &[Descriptor], train: &[Descriptor], out: &mut Vec<Option<Nearest2>>) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("popcnt") {
        // SAFETY: the CPU supports popcnt (checked just above).
        return unsafe { knn2_popcnt(query, train, out) };
    }
    knn2_generic(query, train, out)
}

/// Guided matching: like [`knn2`], but each query is compared only with the train
/// keypoints within `radius` pixels (square window) of its predicted position
/// (`None`: no prediction, no neighbours). A query with fewer than two candidates gets
/// `None`, so the ratio test always has a second neighbour to compare with.
pub fn knn2_within(
    query: &[Descriptor],
    predicted: &[Option<[f32; 2]>],
    train: &[Descriptor],
    train_grid: &PointGrid,
    radius: f32,
    out: &mut Vec<Option<Nearest2>>,
) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("popcnt") {
        // SAFETY: the CPU supports popcnt (checked just above).
        return unsafe { knn2_within_popcnt(query, predicted, train, train_grid, radius, out) };
    }
    knn2_within_generic(query, predicted, train, train_grid, radius, out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn brute(query: &Descriptor, train: &[Descriptor]) -> (usize, u32, u32) {
        let mut d: Vec<(u32, usize)> = train
            .iter()
            .enumerate()
            .map(|(j, t)| (distance(query, t), j))
            .collect();
        d.sort();
        (d[0].1, d[0].0, d[1].0)
    }

    #[test]
    fn finds_the_two_nearest_like_a_sort() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let mut random = || [rng.random(), rng.random(), rng.random(), rng.random()];
        let train: Vec<Descriptor> = (0..300).map(|_| random()).collect();
        let query: Vec<Descriptor> = (0..50).map(|_| random()).collect();
        let mut out = Vec::new();
        knn2(&query, &train, &mut out);
        for (q, n) in query.iter().zip(&out) {
            let n = n.unwrap();
            let (_, best, second) = brute(q, &train);
            assert_eq!((n.best, n.second), (best, second));
            assert_eq!(distance(q, &train[n.best_index]), best);
        }
    }

    #[test]
    fn exact_copy_is_distance_zero_and_small_train_gives_none() {
        let a = [1, 2, 3, 4];
        let b = [u64::MAX, 0, 0, 0];
        let mut out = Vec::new();
        knn2(&[a], &[b, a], &mut out);
        assert_eq!(out[0].unwrap().best_index, 1);
        assert_eq!(out[0].unwrap().best, 0);
        assert_eq!(out[0].unwrap().second, distance(&a, &b));
        knn2(&[a], &[b], &mut out);
        assert_eq!(out, vec![None]);
    }

    #[test]
    fn guided_search_is_the_brute_force_one_restricted_to_the_window() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        let train: Vec<Descriptor> = (0..400)
            .map(|_| [rng.random(), rng.random(), rng.random(), rng.random()])
            .collect();
        let points: Vec<[f32; 2]> = (0..400)
            .map(|_| [rng.random_range(0.0..640.0), rng.random_range(0.0..480.0)])
            .collect();
        let grid = PointGrid::new(&points, 640, 480, 32.0);
        let query: Vec<Descriptor> = train.iter().step_by(7).copied().collect();
        let predicted: Vec<Option<[f32; 2]>> = points
            .iter()
            .step_by(7)
            .enumerate()
            .map(|(i, p)| (i % 5 != 0).then_some([p[0] + 3.0, p[1] - 2.0]))
            .collect();
        let mut out = Vec::new();
        let r = 40.0;
        knn2_within(&query, &predicted, &train, &grid, r, &mut out);
        for ((q, p), n) in query.iter().zip(&predicted).zip(&out) {
            let Some(p) = p else {
                assert!(n.is_none());
                continue;
            };
            // Brute force over the keypoints in the window.
            let window: Vec<Descriptor> = train
                .iter()
                .zip(&points)
                .filter(|(_, t)| (t[0] - p[0]).abs() <= r && (t[1] - p[1]).abs() <= r)
                .map(|(d, _)| *d)
                .collect();
            if window.len() < 2 {
                assert!(n.is_none());
                continue;
            }
            let n = n.expect("two candidates in the window");
            assert_eq!(n.best, 0);
            assert_eq!(train[n.best_index], *q);
            assert_eq!((n.best, n.second), (0, brute(q, &window).2));
        }
    }

    #[test]
    fn pack_reads_little_endian_rows() {
        let mut row = [0u8; 32];
        row[0] = 1;
        row[31] = 0x80;
        assert_eq!(pack(&row), Some([1, 0, 0, 1 << 63]));
        assert_eq!(pack(&row[..31]), None);
    }
}
