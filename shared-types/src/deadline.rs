//! Deadlines: every frame's work is due one frame period after its *moment*
//! (`capture_ns`, the end-to-end clock's start, docs/pipeline.md). A stage that starts
//! a frame after its deadline is *late*; a late frame with a newer one of the same
//! stream already waiting behind it is *shed*: its result could not be on time, and
//! working on it would make the newer one late too.
//!
//! Choices, since no paper or standard fixes them:
//! - **The budget is one frame period** (the latency target: every estimate within a
//!   period), measured from the stream itself — the median of a UAV's last
//!   [`PERIOD_WINDOW`] intervals between consecutive frames' stream times — so a 10, 30
//!   or 60 FPS source needs no setting, and a dropped frame (one interval of two
//!   periods) does not move it.
//! - **Late alone is not enough to shed.** A late frame with nothing newer waiting is
//!   still the freshest the stage has: it is finished (and counted late), since the
//!   CPU would otherwise idle and the ground station would get nothing.
//! - **No deadlines with `--rate max`** (flow-controlled): there is no clock to be late
//!   against, and shedding would make a replay depend on the machine's load.

/// Intervals the frame period is the median of.
pub const PERIOD_WINDOW: usize = 9;

/// One stream's frame period, from the stream times of its frames.
#[derive(Debug, Clone, Copy, Default)]
pub struct FramePeriod {
    last_t_s: Option<f64>,
    intervals: [f64; PERIOD_WINDOW],
    count: usize,
    next: usize,
}

impl FramePeriod {
    /// A frame of the stream at stream time `t_s` (seconds). A time not after the
    /// previous one (a restart of the stream, a bad header) starts over.
    pub fn see(&mut self, t_s: f64) {
        if !t_s.is_finite() {
            return;
        }
        match self.last_t_s {
            Some(last) if t_s > last => {
                self.intervals[self.next] = t_s - last;
                self.next = (self.next + 1) % PERIOD_WINDOW;
                self.count = (self.count + 1).min(PERIOD_WINDOW);
            }
            Some(last) if t_s == last => return,
            Some(_) => *self = Self::default(),
            None => {}
        }
        self.last_t_s = Some(t_s);
    }

    /// The median interval in nanoseconds; none before two frames.
    pub fn period_ns(&self) -> Option<u64> {
        if self.count == 0 {
            return None;
        }
        let mut sorted = self.intervals;
        let seen = &mut sorted[..self.count];
        seen.sort_by(f64::total_cmp);
        Some((seen[self.count / 2] * 1e9).round() as u64)
    }
}

/// What a stage decides for one frame (or pair) it is about to work on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// Before its deadline (or no deadlines in force).
    OnTime,
    /// After its deadline, and the freshest there is: worked on, counted late.
    Late,
    /// After its deadline with a newer one waiting: skipped, counted shed.
    Shed,
}

/// The deadlines of one stage over its streams (the two UAVs, or one stream of pairs).
#[derive(Debug, Clone, Copy)]
pub struct Deadlines<const N: usize> {
    enabled: bool,
    periods: [FramePeriod; N],
}

impl<const N: usize> Deadlines<N> {
    /// Deadlines in force unless `flow_controlled` (`--rate max`).
    pub fn new(flow_controlled: bool) -> Self {
        Self {
            enabled: !flow_controlled,
            periods: [FramePeriod::default(); N],
        }
    }

    /// A frame of `stream` at stream time `t_s` (before [`Self::verdict`] on it).
    pub fn see(&mut self, stream: usize, t_s: f64) {
        if let Some(p) = self.periods.get_mut(stream) {
            p.see(t_s);
        }
    }

    /// The budget of `stream`'s frames: one frame period; none while the period is
    /// unknown or deadlines are off.
    pub fn budget_ns(&self, stream: usize) -> Option<u64> {
        if !self.enabled {
            return None;
        }
        self.periods.get(stream)?.period_ns()
    }

    /// The frame of `stream` whose moment was `moment_ns`, started at `now_ns`, with
    /// (`superseded`) or without a newer frame of the stream waiting.
    pub fn verdict(&self, stream: usize, moment_ns: u64, now_ns: u64, superseded: bool) -> Verdict {
        let Some(budget) = self.budget_ns(stream) else {
            return Verdict::OnTime;
        };
        if now_ns <= moment_ns.saturating_add(budget) {
            Verdict::OnTime
        } else if superseded {
            Verdict::Shed
        } else {
            Verdict::Late
        }
    }
}

/// Drains a queue oldest first, handing each item over with whether a newer one was
/// already waiting behind it (`superseded`, for [`Deadlines::verdict`]). One item is
/// held back until the next is received, so at most two are out of the queue at once.
pub fn drain_with_lookahead<T, E>(
    mut receive: impl FnMut() -> Result<Option<T>, E>,
    mut handle: impl FnMut(T, bool) -> Result<(), E>,
) -> Result<(), E> {
    let mut held = receive()?;
    while let Some(item) = held {
        let next = receive()?;
        handle(item, next.is_some())?;
        held = next;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn draining_tells_each_item_whether_a_newer_one_waits() {
        let queue = std::cell::RefCell::new(vec![3, 2, 1]);
        let mut seen = Vec::new();
        drain_with_lookahead(
            || Ok::<_, ()>(queue.borrow_mut().pop()),
            |item, superseded| {
                seen.push((item, superseded));
                if item == 2 {
                    queue.borrow_mut().insert(0, 4); // arrived while the stage worked on 2
                }
                Ok(())
            },
        )
        .unwrap();
        assert_eq!(seen, [(1, true), (2, true), (3, true), (4, false)]);
    }

    const MS: u64 = 1_000_000;

    fn at_30_fps(frames: usize) -> Deadlines<2> {
        let mut d = Deadlines::new(false);
        for k in 0..frames {
            d.see(0, k as f64 / 30.0);
        }
        d
    }

    #[test]
    fn the_budget_is_the_streams_median_frame_period() {
        let d = at_30_fps(10);
        let b = d.budget_ns(0).unwrap();
        assert!((33 * MS..34 * MS).contains(&b), "{b}");
        assert_eq!(d.budget_ns(1), None, "the other stream has no frames yet");
    }

    #[test]
    fn a_dropped_frame_does_not_move_the_period() {
        let mut d = at_30_fps(10);
        d.see(0, 11.0 / 30.0); // frame 10 never came: one interval of two periods
        let b = d.budget_ns(0).unwrap();
        assert!((33 * MS..34 * MS).contains(&b), "{b}");
    }

    #[test]
    fn a_stream_going_back_in_time_starts_over() {
        let mut d = at_30_fps(10);
        d.see(0, 0.0);
        assert_eq!(d.budget_ns(0), None);
        d.see(0, 0.1);
        assert_eq!(d.budget_ns(0), Some(100 * MS));
    }

    #[test]
    fn late_frames_are_shed_only_when_a_newer_one_waits() {
        let d = at_30_fps(10);
        let moment = 1_000 * MS;
        assert_eq!(
            d.verdict(0, moment, moment + 20 * MS, true),
            Verdict::OnTime
        );
        assert_eq!(d.verdict(0, moment, moment + 40 * MS, false), Verdict::Late);
        assert_eq!(d.verdict(0, moment, moment + 40 * MS, true), Verdict::Shed);
        // A clock that runs backwards (moment after now) is on time, never shed.
        assert_eq!(d.verdict(0, moment, 0, true), Verdict::OnTime);
    }

    #[test]
    fn flow_control_has_no_deadlines() {
        let mut d = Deadlines::<2>::new(true);
        for k in 0..10 {
            d.see(0, k as f64 / 30.0);
        }
        assert_eq!(d.budget_ns(0), None);
        assert_eq!(d.verdict(0, 0, u64::MAX, true), Verdict::OnTime);
    }

    #[test]
    fn non_finite_times_are_ignored() {
        let mut d = at_30_fps(10);
        d.see(0, f64::NAN);
        d.see(0, f64::INFINITY);
        assert!(d.budget_ns(0).is_some());
    }
}
