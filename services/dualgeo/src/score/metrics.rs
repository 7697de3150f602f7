//! Multi-target scores of a run against every vehicle's truth: pure functions over
//! plain data (one [`Frame`] per stereo pair).
//!
//! Choices (the literature leaves them to the user):
//! - **Distance**: horizontal (x, y), what a map shows; the per-target MAE keeps x, y
//!   and z apart.
//! - **Truth at a pair**: the vehicles whose top centre both UAVs' images show (in
//!   view, not hidden). A vehicle present but not in view of both is *don't care*: an
//!   estimate within the threshold of one (and of no vehicle in view) is neither a
//!   hit nor a false track (MOTChallenge's rule for ignored objects), so coasting under
//!   a bridge is not punished.
//! - **GOSPA** (Rahmathullah, García-Fernández, Svensson 2017) with c = cutoff, p = 2,
//!   α = 2, per pair, optimal assignment; its **switching term** as in trajectory
//!   GOSPA (García-Fernández et al. 2020) taken over the per-pair assignments: a
//!   vehicle whose assigned track changes since it was last in view costs γ², one
//!   that gains or loses its track γ²/2 (its first pair in view costs nothing).
//! - **CLEAR MOT** (Bernardin & Stiefelhagen 2008) at the threshold: correspondences
//!   kept from the previous pair while still within it, the rest by optimal
//!   assignment; an identity switch is a vehicle matched to another track than the
//!   one it last had.
//! - **IDF1** (Ristani et al. 2016): the truth-to-track bijection maximising the pairs
//!   where both are within the threshold.

use serde::Serialize;
use shared_types::assignment;
use std::collections::{BTreeMap, BTreeSet};

/// One object at one pair: a vehicle (truth) or a track's estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Object {
    /// Vehicle id (truth_targets.csv's target_id) or track id.
    pub id: u32,
    /// ENU metres.
    pub p: [f64; 3],
    /// An estimate's stated horizontal accuracy (1σ, metres), when it has one.
    pub h_acc_m: Option<f64>,
    /// An estimate's stated vertical accuracy (1σ, metres), when it has one.
    pub v_acc_m: Option<f64>,
}

/// Everything known at one stereo pair.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Frame {
    pub t_s: f64,
    /// Vehicles in view of both UAVs.
    pub truth: Vec<Object>,
    /// Vehicles present but not in view of both (don't care).
    pub dont_care: Vec<[f64; 3]>,
    /// The run's estimates at this pair, one per track.
    pub estimates: Vec<Object>,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Params {
    /// GOSPA's cutoff c, metres.
    pub cutoff_m: f64,
    /// CLEAR MOT's, IDF1's and the don't-care rule's match threshold, metres.
    pub threshold_m: f64,
    /// GOSPA's switching penalty γ, metres.
    pub switch_penalty_m: f64,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            cutoff_m: 5.0,
            threshold_m: 2.0,
            switch_penalty_m: 2.0,
        }
    }
}

/// GOSPA over the pairs: the mean of the per-pair value (switching term included) and
/// its parts.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Gospa {
    pub mean_m: f64,
    /// √(mean d²) over the assigned pairs closer than the cutoff.
    pub localisation_rms_m: f64,
    pub missed_per_pair: f64,
    pub false_per_pair: f64,
    /// Switches (a change of track 1, a gain or loss ½).
    pub switches: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ClearMot {
    /// Σ vehicles in view over the pairs.
    pub truth: u64,
    pub matches: u64,
    pub misses: u64,
    pub false_positives: u64,
    pub id_switches: u64,
    /// 1 − (misses + false positives + switches) / truth.
    pub mota: f64,
    /// Mean horizontal distance of the matches, metres.
    pub motp_m: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct IdScores {
    pub idtp: u64,
    pub idfp: u64,
    pub idfn: u64,
    pub idf1: f64,
}

/// One vehicle's figures.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PerVehicle {
    pub id: u32,
    /// Pairs it was in view of both UAVs.
    pub in_view: u64,
    /// Of those, pairs some track was matched to it (CLEAR MOT).
    pub located: u64,
    pub located_share: f64,
    /// Mean |error| of the matched estimates, x / y / z, metres; `None` when never
    /// located.
    pub mae_m: Option<[f64; 3]>,
    /// Share of the matched estimates that state an h_acc whose horizontal error is
    /// within it (a calibrated 2-D 1σ holds ~63 %; the match's 2 m threshold leaves
    /// the farthest out, so this is an upper bound); `None` without any.
    pub inside_h_acc: Option<f64>,
    /// The same for the vertical error and v_acc (a calibrated 1-D 1σ holds ~68 %).
    pub inside_v_acc: Option<f64>,
    pub id_switches: u64,
    /// The tracks that were matched to it, by id.
    pub tracks: Vec<u32>,
}

/// One CLEAR MOT identity switch: when, which vehicle, the track it last had and the
/// one it has now (the list a reader needs to find the moment in a replay).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct IdSwitch {
    pub t_s: f64,
    pub vehicle: u32,
    pub from_track: u32,
    pub to_track: u32,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MultiScore {
    pub pairs: u64,
    /// Estimates dropped as matching a vehicle out of view (don't care).
    pub dont_care_estimates: u64,
    pub params: Params,
    pub gospa: Gospa,
    pub clear: ClearMot,
    pub id: IdScores,
    pub vehicles: Vec<PerVehicle>,
    /// Every identity switch, in time order (`clear.id_switches` of them).
    pub switch_events: Vec<IdSwitch>,
}

fn horizontal(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

fn distances(truth: &[Object], estimates: &[Object]) -> Vec<Vec<f64>> {
    truth
        .iter()
        .map(|g| estimates.iter().map(|e| horizontal(&g.p, &e.p)).collect())
        .collect()
}

/// The estimates that count at `frame`: all but those within the threshold of a
/// don't-care vehicle and of no vehicle in view.
fn scored_estimates(frame: &Frame, threshold: f64) -> Vec<Object> {
    frame
        .estimates
        .iter()
        .filter(|e| {
            let near = |p: &[f64; 3]| horizontal(p, &e.p) < threshold;
            !frame.dont_care.iter().any(near) || frame.truth.iter().any(|g| near(&g.p))
        })
        .copied()
        .collect()
}

/// GOSPA at one pair (without the switching term): per vehicle the track it got (if
/// closer than the cutoff), Σ d², missed and false counts.
fn gospa_pair(truth: &[Object], est: &[Object], c: f64) -> (Vec<Option<u32>>, f64, u64, u64) {
    let d = distances(truth, est);
    let cost: Vec<Vec<f64>> = d
        .iter()
        .map(|row| row.iter().map(|x| x.min(c).powi(2)).collect())
        .collect();
    let a = assignment::min_cost(&cost);
    let mut sum_d2 = 0.0;
    let mut got = vec![None; truth.len()];
    for (g, e) in a.iter().enumerate() {
        if let Some(e) = *e {
            if d[g][e] < c {
                sum_d2 += d[g][e].powi(2);
                got[g] = Some(est[e].id);
            }
        }
    }
    let assigned = got.iter().flatten().count() as u64;
    (
        got,
        sum_d2,
        truth.len() as u64 - assigned,
        est.len() as u64 - assigned,
    )
}

/// Scores `frames` (one per pair, in time order).
pub fn score(frames: &[Frame], params: Params) -> MultiScore {
    let (c, t, gamma) = (params.cutoff_m, params.threshold_m, params.switch_penalty_m);
    let mut gospa_sum = 0.0;
    let (mut loc_d2, mut loc_n, mut missed, mut false_n, mut switches) = (0.0, 0u64, 0, 0, 0.0);
    let mut gospa_last: BTreeMap<u32, Option<u32>> = BTreeMap::new();
    let mut clear = ClearMot {
        truth: 0,
        matches: 0,
        misses: 0,
        false_positives: 0,
        id_switches: 0,
        mota: 0.0,
        motp_m: 0.0,
    };
    let mut match_d_sum = 0.0;
    // CLEAR MOT: each vehicle's current and last track.
    let mut current: BTreeMap<u32, u32> = BTreeMap::new();
    let mut last_track: BTreeMap<u32, u32> = BTreeMap::new();
    // IDF1: co-occurrence within the threshold, and the totals.
    let mut within: BTreeMap<(u32, u32), u64> = BTreeMap::new();
    let (mut truth_total, mut est_total, mut dont_care) = (0u64, 0u64, 0u64);
    // Per vehicle: its figures, the sum of |error| per axis of its matched estimates,
    // and how many of those state an h_acc and how many lie within it, then the same
    // for v_acc.
    let mut vehicles: BTreeMap<u32, (PerVehicle, [f64; 3], [u64; 4])> = BTreeMap::new();
    let mut switch_events = Vec::new();

    for frame in frames {
        let est = scored_estimates(frame, t);
        dont_care += (frame.estimates.len() - est.len()) as u64;
        let truth = &frame.truth;
        truth_total += truth.len() as u64;
        est_total += est.len() as u64;

        // GOSPA and its switching term.
        let (got, d2, miss, fals) = gospa_pair(truth, &est, c);
        // A vehicle's assignment against the one it had when last in view (none the
        // first time): trajectory GOSPA keeps an assignment through an absence.
        let mut switch_here = 0.0;
        for (g, e) in truth.iter().zip(&got) {
            switch_here += match (gospa_last.insert(g.id, *e), e) {
                (Some(Some(a)), Some(b)) if a != *b => 1.0,
                (Some(Some(_)), None) | (Some(None), Some(_)) => 0.5,
                _ => 0.0,
            };
        }
        let pair_value =
            (d2 + c * c / 2.0 * (miss + fals) as f64 + gamma * gamma * switch_here).sqrt();
        gospa_sum += pair_value;
        loc_d2 += d2;
        loc_n += got.iter().flatten().count() as u64;
        missed += miss;
        false_n += fals;
        switches += switch_here;

        // CLEAR MOT: keep last pair's correspondences still within the threshold.
        let d = distances(truth, &est);
        let mut truth_match: Vec<Option<usize>> = vec![None; truth.len()];
        let mut est_taken = vec![false; est.len()];
        for (g, obj) in truth.iter().enumerate() {
            if let Some(track) = current.get(&obj.id) {
                let kept = est
                    .iter()
                    .position(|e| e.id == *track)
                    .filter(|&e| !est_taken[e] && d[g][e] < t);
                if let Some(e) = kept {
                    truth_match[g] = Some(e);
                    est_taken[e] = true;
                }
            }
        }
        let free_truth: Vec<usize> = (0..truth.len())
            .filter(|&g| truth_match[g].is_none())
            .collect();
        let free_est: Vec<usize> = (0..est.len()).filter(|&e| !est_taken[e]).collect();
        // Pairs beyond the threshold cost more than any set of pairs within it, so
        // the assignment first maximises the matches, then minimises their distance.
        let forbidden = t * (free_truth.len() + 1) as f64;
        let cost: Vec<Vec<f64>> = free_truth
            .iter()
            .map(|&g| {
                free_est
                    .iter()
                    .map(|&e| if d[g][e] < t { d[g][e] } else { forbidden })
                    .collect()
            })
            .collect();
        for (i, a) in assignment::min_cost(&cost).into_iter().enumerate() {
            if let Some(j) = a {
                let (g, e) = (free_truth[i], free_est[j]);
                if d[g][e] < t {
                    truth_match[g] = Some(e);
                    est_taken[e] = true;
                }
            }
        }
        current.clear();
        for (g, obj) in truth.iter().enumerate() {
            let entry = vehicles.entry(obj.id).or_insert_with(|| {
                (
                    PerVehicle {
                        id: obj.id,
                        in_view: 0,
                        located: 0,
                        located_share: 0.0,
                        mae_m: None,
                        inside_h_acc: None,
                        inside_v_acc: None,
                        id_switches: 0,
                        tracks: Vec::new(),
                    },
                    [0.0; 3],
                    [0u64; 4],
                )
            });
            entry.0.in_view += 1;
            let Some(e) = truth_match[g] else {
                clear.misses += 1;
                continue;
            };
            let track = est[e].id;
            clear.matches += 1;
            match_d_sum += d[g][e];
            if let Some(&last) = last_track.get(&obj.id).filter(|&&last| last != track) {
                clear.id_switches += 1;
                entry.0.id_switches += 1;
                switch_events.push(IdSwitch {
                    t_s: frame.t_s,
                    vehicle: obj.id,
                    from_track: last,
                    to_track: track,
                });
            }
            last_track.insert(obj.id, track);
            current.insert(obj.id, track);
            entry.0.located += 1;
            if !entry.0.tracks.contains(&track) {
                entry.0.tracks.push(track);
            }
            for (k, abs) in entry.1.iter_mut().enumerate() {
                *abs += (est[e].p[k] - obj.p[k]).abs();
            }
            if let Some(h_acc) = est[e].h_acc_m {
                // `d` is the horizontal distance.
                entry.2[0] += 1;
                entry.2[1] += u64::from(d[g][e] <= h_acc);
            }
            if let Some(v_acc) = est[e].v_acc_m {
                entry.2[2] += 1;
                entry.2[3] += u64::from((est[e].p[2] - obj.p[2]).abs() <= v_acc);
            }
        }
        clear.false_positives += est_taken.iter().filter(|&&taken| !taken).count() as u64;

        // IDF1's co-occurrences.
        for (g, obj) in truth.iter().enumerate() {
            for (e, track) in est.iter().enumerate() {
                if d[g][e] < t {
                    *within.entry((obj.id, track.id)).or_default() += 1;
                }
            }
        }
    }

    clear.truth = truth_total;
    clear.mota = if truth_total == 0 {
        0.0
    } else {
        1.0 - (clear.misses + clear.false_positives + clear.id_switches) as f64 / truth_total as f64
    };
    clear.motp_m = if clear.matches == 0 {
        0.0
    } else {
        match_d_sum / clear.matches as f64
    };

    let id = id_scores(&within, truth_total, est_total);
    let pairs = frames.len() as u64;
    let per_pair = |n: u64| {
        if pairs == 0 {
            0.0
        } else {
            n as f64 / pairs as f64
        }
    };
    let gospa = Gospa {
        mean_m: if pairs == 0 {
            0.0
        } else {
            gospa_sum / pairs as f64
        },
        localisation_rms_m: if loc_n == 0 {
            0.0
        } else {
            (loc_d2 / loc_n as f64).sqrt()
        },
        missed_per_pair: per_pair(missed),
        false_per_pair: per_pair(false_n),
        switches,
    };
    let vehicles = vehicles
        .into_values()
        .map(|(mut v, abs, [stating, inside, stating_v, inside_v])| {
            if v.located > 0 {
                v.mae_m = Some(abs.map(|a| a / v.located as f64));
            }
            if stating > 0 {
                v.inside_h_acc = Some(inside as f64 / stating as f64);
            }
            if stating_v > 0 {
                v.inside_v_acc = Some(inside_v as f64 / stating_v as f64);
            }
            v.located_share = v.located as f64 / v.in_view.max(1) as f64;
            v.tracks.sort_unstable();
            v
        })
        .collect();
    MultiScore {
        pairs,
        dont_care_estimates: dont_care,
        params,
        gospa,
        clear,
        id,
        vehicles,
        switch_events,
    }
}

/// IDF1 from the co-occurrence counts: the vehicle-to-track bijection of most pairs
/// within the threshold.
fn id_scores(within: &BTreeMap<(u32, u32), u64>, truth_total: u64, est_total: u64) -> IdScores {
    let vehicles: Vec<u32> = within
        .keys()
        .map(|k| k.0)
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect();
    let tracks: Vec<u32> = within
        .keys()
        .map(|k| k.1)
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect();
    let weight: Vec<Vec<u64>> = vehicles
        .iter()
        .map(|v| {
            tracks
                .iter()
                .map(|t| within.get(&(*v, *t)).copied().unwrap_or(0))
                .collect()
        })
        .collect();
    let idtp: u64 = assignment::max_weight(&weight)
        .iter()
        .enumerate()
        .filter_map(|(r, c)| c.map(|c| weight[r][c]))
        .sum();
    let idfn = truth_total.saturating_sub(idtp);
    let idfp = est_total.saturating_sub(idtp);
    let idf1 = if truth_total + est_total == 0 {
        0.0
    } else {
        2.0 * idtp as f64 / (truth_total + est_total) as f64
    };
    IdScores {
        idtp,
        idfp,
        idfn,
        idf1,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn obj(id: u32, x: f64, y: f64) -> Object {
        Object {
            id,
            p: [x, y, 13.5],
            h_acc_m: None,
            v_acc_m: None,
        }
    }

    fn frame(truth: Vec<Object>, estimates: Vec<Object>) -> Frame {
        Frame {
            t_s: 0.0,
            truth,
            dont_care: Vec::new(),
            estimates,
        }
    }

    #[test]
    fn perfect_tracks_score_perfectly() {
        let frames: Vec<Frame> = (0..10)
            .map(|k| {
                let x = k as f64;
                frame(
                    vec![obj(0, x, 0.0), obj(1, x, 10.0)],
                    vec![obj(7, x, 0.0), obj(8, x, 10.0)],
                )
            })
            .collect();
        let s = score(&frames, Params::default());
        assert_eq!(s.gospa.mean_m, 0.0);
        assert_eq!(s.gospa.switches, 0.0);
        assert_eq!(s.clear.mota, 1.0);
        assert_eq!(s.clear.id_switches, 0);
        assert_eq!(s.id.idf1, 1.0);
        assert_eq!(s.vehicles[0].tracks, vec![7]);
        assert_eq!(s.vehicles[1].located_share, 1.0);
    }

    /// GOSPA by hand: one vehicle 1 m off, one missed, one false track far away.
    #[test]
    fn gospa_adds_localisation_misses_and_false_tracks() {
        let frames = vec![frame(
            vec![obj(0, 0.0, 0.0), obj(1, 50.0, 0.0)],
            vec![obj(3, 1.0, 0.0), obj(4, -40.0, 0.0)],
        )];
        let p = Params {
            switch_penalty_m: 0.0,
            ..Params::default()
        };
        let s = score(&frames, p);
        let expected = (1.0 + 25.0 / 2.0 * 2.0_f64).sqrt();
        assert!(
            (s.gospa.mean_m - expected).abs() < 1e-9,
            "{}",
            s.gospa.mean_m
        );
        assert_eq!(s.gospa.missed_per_pair, 1.0);
        assert_eq!(s.gospa.false_per_pair, 1.0);
        assert_eq!(s.clear.misses, 1);
        assert_eq!(s.clear.false_positives, 1);
        assert!((s.clear.mota - 0.0).abs() < 1e-12);
    }

    /// Two tracks swap their vehicles halfway: CLEAR counts two switches, GOSPA two
    /// full switches, IDF1 keeps half.
    #[test]
    fn a_swap_is_counted_by_every_metric() {
        let frames: Vec<Frame> = (0..10)
            .map(|k| {
                let (a, b) = if k < 5 { (7, 8) } else { (8, 7) };
                Frame {
                    t_s: 0.1 * k as f64,
                    ..frame(
                        vec![obj(0, 0.0, 0.0), obj(1, 0.0, 10.0)],
                        vec![obj(a, 0.0, 0.0), obj(b, 0.0, 10.0)],
                    )
                }
            })
            .collect();
        let s = score(&frames, Params::default());
        assert_eq!(s.clear.id_switches, 2);
        assert_eq!(s.gospa.switches, 2.0);
        assert_eq!(s.id.idtp, 10);
        assert!((s.id.idf1 - 0.5).abs() < 1e-12);
        assert_eq!(s.vehicles[0].tracks, vec![7, 8]);
        let at = frames[5].t_s;
        assert_eq!(
            s.switch_events,
            vec![
                IdSwitch {
                    t_s: at,
                    vehicle: 0,
                    from_track: 7,
                    to_track: 8
                },
                IdSwitch {
                    t_s: at,
                    vehicle: 1,
                    from_track: 8,
                    to_track: 7
                },
            ]
        );
    }

    /// Losing a track and regaining it are half switches each; an absence from view
    /// in between changes nothing.
    #[test]
    fn losing_and_regaining_a_track_are_half_switches() {
        let frames = vec![
            frame(vec![obj(0, 0.0, 0.0)], vec![obj(7, 0.0, 0.0)]),
            frame(vec![obj(0, 0.0, 0.0)], vec![]),
            frame(vec![], vec![]),
            frame(vec![obj(0, 0.0, 0.0)], vec![obj(7, 0.0, 0.0)]),
            frame(vec![], vec![]),
            frame(vec![obj(0, 0.0, 0.0)], vec![obj(7, 0.0, 0.0)]),
        ];
        let s = score(&frames, Params::default());
        assert_eq!(s.gospa.switches, 1.0);
        assert_eq!(s.clear.id_switches, 0);
        assert_eq!(s.clear.misses, 1);
    }

    /// CLEAR MOT keeps a correspondence while it stays within the threshold even when
    /// another track comes closer.
    #[test]
    fn a_kept_correspondence_is_not_switched_by_a_closer_track() {
        let frames = vec![
            frame(vec![obj(0, 0.0, 0.0)], vec![obj(7, 1.5, 0.0)]),
            frame(
                vec![obj(0, 0.0, 0.0)],
                vec![obj(7, 1.5, 0.0), obj(8, 0.1, 0.0)],
            ),
        ];
        let s = score(&frames, Params::default());
        assert_eq!(s.clear.id_switches, 0);
        assert_eq!(s.clear.false_positives, 1);
        assert_eq!(s.vehicles[0].tracks, vec![7]);
    }

    /// An estimate of a vehicle out of view (under a bridge) is neither hit nor false;
    /// one far from everything is false.
    #[test]
    fn estimates_of_vehicles_out_of_view_do_not_count() {
        let mut f = frame(vec![], vec![obj(7, 0.5, 0.0), obj(8, 30.0, 0.0)]);
        f.dont_care.push([0.0, 0.0, 13.5]);
        let s = score(&[f], Params::default());
        assert_eq!(s.dont_care_estimates, 1);
        assert_eq!(s.clear.false_positives, 1);
        assert_eq!(s.clear.truth, 0);
    }

    #[test]
    fn per_vehicle_errors_are_per_axis() {
        let frames = vec![
            frame(
                vec![obj(0, 0.0, 0.0)],
                vec![Object {
                    id: 1,
                    p: [0.5, -1.0, 12.5],
                    h_acc_m: Some(1.0),
                    v_acc_m: Some(1.5),
                }],
            ),
            frame(
                vec![obj(0, 0.0, 0.0)],
                vec![Object {
                    id: 1,
                    p: [-0.5, 0.0, 14.5],
                    h_acc_m: Some(1.0),
                    v_acc_m: Some(0.5),
                }],
            ),
            frame(vec![obj(0, 0.0, 0.0)], vec![]),
        ];
        let s = score(&frames, Params::default());
        let v = &s.vehicles[0];
        assert_eq!((v.in_view, v.located), (3, 2));
        assert_eq!(v.mae_m, Some([0.5, 0.5, 1.0]));
        assert!((v.located_share - 2.0 / 3.0).abs() < 1e-12);
        // 1.12 m off against ±1 m, then 0.5 m: one of the two inside.
        assert_eq!(v.inside_h_acc, Some(0.5));
        // 1 m low against ±1.5 m, then 1 m high against ±0.5 m.
        assert_eq!(v.inside_v_acc, Some(0.5));
    }
}
