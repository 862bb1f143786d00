//! Left/right pairing by capture time: which left frame goes with which right frame, and
//! which frames have no partner close enough in time and are dropped.
//!
//! Pure logic over timestamps, so it is tested without cameras. Each side's frames arrive in
//! capture order (a GStreamer pipeline delivers its buffers in order); the two sides arrive
//! interleaved in any order.
//!
//! The rule, applied whenever both sides have a frame waiting: the two oldest frames are a
//! pair when their capture times differ by at most the allowed skew, unless the frame right
//! behind one of them is an even closer partner for the other (then the first is dropped and
//! the closer one is paired on the next step). When they differ by more, the older of the
//! two can never be paired (every later frame of the other side is later still) and is
//! dropped. A side that runs ahead while the other side delivers nothing is capped at
//! `max_waiting` frames; beyond that its oldest frame is dropped as stale.

use std::collections::VecDeque;

/// One captured frame waiting for its partner.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Stamped<T> {
    /// Capture time, CLOCK_MONOTONIC ns.
    pub capture_ns: u64,
    pub item: T,
}

/// Why a frame was dropped without a partner.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DropReason {
    /// No frame of the other side within the allowed skew.
    NoPartner,
    /// The other side delivered nothing while this side's queue filled up.
    Stale,
}

/// What the pairer decided about the oldest waiting frames.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Paired<T> {
    Pair { left: Stamped<T>, right: Stamped<T>, skew_ns: u64 },
    DroppedLeft { left: Stamped<T>, reason: DropReason },
    DroppedRight { right: Stamped<T>, reason: DropReason },
}

/// Pairs left and right frames by capture time (see the module docs for the rule).
#[derive(Debug)]
pub struct Pairer<T> {
    left: VecDeque<Stamped<T>>,
    right: VecDeque<Stamped<T>>,
    max_skew_ns: u64,
    max_waiting: usize,
}

impl<T> Pairer<T> {
    /// `max_waiting` >= 2 so that the closer-partner look-ahead can see a second frame.
    pub fn new(max_skew_ns: u64, max_waiting: usize) -> Self {
        Self { left: VecDeque::new(), right: VecDeque::new(), max_skew_ns, max_waiting: max_waiting.max(2) }
    }

    pub fn push_left(&mut self, frame: Stamped<T>) {
        self.left.push_back(frame);
    }

    pub fn push_right(&mut self, frame: Stamped<T>) {
        self.right.push_back(frame);
    }

    pub fn waiting_left(&self) -> usize {
        self.left.len()
    }

    pub fn waiting_right(&self) -> usize {
        self.right.len()
    }

    /// Forgets the frames waiting on one side (its source restarted: they may never get a
    /// partner in order). Returns them so that the caller can count them as dropped.
    pub fn clear_left(&mut self) -> Vec<Stamped<T>> {
        self.left.drain(..).collect()
    }

    pub fn clear_right(&mut self) -> Vec<Stamped<T>> {
        self.right.drain(..).collect()
    }

    /// The next decision, or `None` when the frames waiting do not decide anything yet.
    /// Call until `None` after every push.
    pub fn next(&mut self) -> Option<Paired<T>> {
        let (Some(l), Some(r)) = (self.left.front(), self.right.front()) else {
            return self.drop_stale();
        };
        let skew_ns = l.capture_ns.abs_diff(r.capture_ns);
        if skew_ns <= self.max_skew_ns {
            if self.left.get(1).is_some_and(|l2| l2.capture_ns.abs_diff(r.capture_ns) < skew_ns) {
                let left = self.left.pop_front()?;
                return Some(Paired::DroppedLeft { left, reason: DropReason::NoPartner });
            }
            if self.right.get(1).is_some_and(|r2| r2.capture_ns.abs_diff(l.capture_ns) < skew_ns) {
                let right = self.right.pop_front()?;
                return Some(Paired::DroppedRight { right, reason: DropReason::NoPartner });
            }
            let (left, right) = (self.left.pop_front()?, self.right.pop_front()?);
            return Some(Paired::Pair { left, right, skew_ns });
        }
        if l.capture_ns < r.capture_ns {
            let left = self.left.pop_front()?;
            Some(Paired::DroppedLeft { left, reason: DropReason::NoPartner })
        } else {
            let right = self.right.pop_front()?;
            Some(Paired::DroppedRight { right, reason: DropReason::NoPartner })
        }
    }

    fn drop_stale(&mut self) -> Option<Paired<T>> {
        if self.left.len() > self.max_waiting {
            let left = self.left.pop_front()?;
            return Some(Paired::DroppedLeft { left, reason: DropReason::Stale });
        }
        if self.right.len() > self.max_waiting {
            let right = self.right.pop_front()?;
            return Some(Paired::DroppedRight { right, reason: DropReason::Stale });
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    fn s(t_ms: u64, id: u32) -> Stamped<u32> {
        Stamped { capture_ns: t_ms * MS, item: id }
    }

    /// Feeds both streams in capture order (interleaved by time) and collects every decision.
    fn run(left: &[u64], right: &[u64], skew_ms: u64) -> Vec<Paired<u32>> {
        let mut p = Pairer::new(skew_ms * MS, 8);
        let mut events: Vec<(u64, bool, u32)> = left.iter().enumerate().map(|(i, &t)| (t, true, i as u32)).collect();
        events.extend(right.iter().enumerate().map(|(i, &t)| (t, false, i as u32)));
        events.sort();
        let mut out = Vec::new();
        for (t, is_left, id) in events {
            if is_left { p.push_left(s(t, id)) } else { p.push_right(s(t, id)) }
            while let Some(d) = p.next() {
                out.push(d);
            }
        }
        out
    }

    fn pairs(out: &[Paired<u32>]) -> Vec<(u32, u32)> {
        out.iter().filter_map(|d| if let Paired::Pair { left, right, .. } = d { Some((left.item, right.item)) } else { None }).collect()
    }

    #[test]
    fn synchronised_streams_pair_one_to_one() {
        let t: Vec<u64> = (0..10).map(|i| i * 33).collect();
        let right: Vec<u64> = t.iter().map(|x| x + 2).collect();
        let out = run(&t, &right, 5);
        assert_eq!(pairs(&out), (0..10).map(|i| (i, i)).collect::<Vec<_>>());
        assert!(out.iter().all(|d| matches!(d, Paired::Pair { skew_ns, .. } if *skew_ns == 2 * MS)));
    }

    #[test]
    fn different_rates_pair_only_within_the_skew_and_drop_the_rest() {
        // 30 and 20 frames/s from t = 0: exposures coincide every 100 ms.
        let left: Vec<u64> = (0..30).map(|i| i * 100 / 3).collect();
        let right: Vec<u64> = (0..20).map(|i| i * 50).collect();
        let out = run(&left, &right, 5);
        let p = pairs(&out);
        assert!(!p.is_empty());
        for d in &out {
            if let Paired::Pair { left, right, skew_ns } = d {
                assert!(*skew_ns <= 5 * MS && left.capture_ns.abs_diff(right.capture_ns) == *skew_ns);
            }
        }
        // Every frame is decided exactly once, except those still waiting at the end.
        let dropped_left = out.iter().filter(|d| matches!(d, Paired::DroppedLeft { .. })).count();
        let dropped_right = out.iter().filter(|d| matches!(d, Paired::DroppedRight { .. })).count();
        assert!(p.len() + dropped_left <= 30 && p.len() + dropped_right <= 20);
        assert!(30 - (p.len() + dropped_left) <= 1 && 20 - (p.len() + dropped_right) <= 1, "{out:?}");
        // Left frames 0, 3, 6, ... (t = 0, 100, 200 ms) meet right frames 0, 2, 4, ...
        assert_eq!(&p[..3], &[(0, 0), (3, 2), (6, 4)]);
    }

    #[test]
    fn a_closer_partner_right_behind_wins() {
        // Left at 0 and 10 ms, right at 9 ms: both left frames are within 10 ms, the second is
        // closer, so the first is dropped.
        let mut p = Pairer::new(10 * MS, 8);
        p.push_left(s(0, 0));
        p.push_left(s(10, 1));
        p.push_right(s(9, 0));
        assert_eq!(p.next(), Some(Paired::DroppedLeft { left: s(0, 0), reason: DropReason::NoPartner }));
        assert_eq!(p.next(), Some(Paired::Pair { left: s(10, 1), right: s(9, 0), skew_ns: MS }));
        assert_eq!(p.next(), None);
    }

    #[test]
    fn nothing_is_decided_while_one_side_is_empty_until_it_is_stale() {
        let mut p = Pairer::new(5 * MS, 3);
        for i in 0..3 {
            p.push_left(s(i * 33, i as u32));
            assert_eq!(p.next(), None);
        }
        p.push_left(s(99, 3));
        assert_eq!(p.next(), Some(Paired::DroppedLeft { left: s(0, 0), reason: DropReason::Stale }));
        assert_eq!(p.next(), None);
        assert_eq!(p.waiting_left(), 3);
        assert_eq!(p.clear_left().len(), 3);
        assert_eq!(p.waiting_left(), 0);
    }

    #[test]
    fn right_frames_older_than_every_left_frame_are_dropped() {
        let mut p = Pairer::new(5 * MS, 8);
        p.push_right(s(0, 0));
        p.push_right(s(33, 1));
        p.push_left(s(40, 0));
        assert_eq!(p.next(), Some(Paired::DroppedRight { right: s(0, 0), reason: DropReason::NoPartner }));
        // 7 ms apart: too far, and the right one is older.
        assert_eq!(p.next(), Some(Paired::DroppedRight { right: s(33, 1), reason: DropReason::NoPartner }));
        assert_eq!(p.next(), None);
        assert_eq!(p.waiting_left(), 1);
    }
}
